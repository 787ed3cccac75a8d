// Park (rotate by -theta) and inverse Park (rotate by +theta), Q1.15, products rounded half
// up, saturated to s16.
module park (
    input  wire signed [15:0] x_alpha,
    input  wire signed [15:0] x_beta,
    input  wire signed [15:0] s,
    input  wire signed [15:0] c,
    output wire signed [15:0] x_d,
    output wire signed [15:0] x_q
);
    `include "fixed.vh"
    wire signed [32:0] d = x_alpha * c + x_beta * s;   // products 32 bit, sum 33
    wire signed [32:0] q = x_beta * c - x_alpha * s;
    assign x_d = sat16((d + 33'sd16384) >>> 15);
    assign x_q = sat16((q + 33'sd16384) >>> 15);
endmodule

module inv_park (
    input  wire signed [15:0] v_d,
    input  wire signed [15:0] v_q,
    input  wire signed [15:0] s,
    input  wire signed [15:0] c,
    output wire signed [15:0] v_alpha,
    output wire signed [15:0] v_beta
);
    `include "fixed.vh"
    wire signed [32:0] a = v_d * c - v_q * s;
    wire signed [32:0] b = v_d * s + v_q * c;
    assign v_alpha = sat16((a + 33'sd16384) >>> 15);
    assign v_beta = sat16((b + 33'sd16384) >>> 15);
endmodule
