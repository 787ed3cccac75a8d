// Amplitude-invariant Clarke transform: i_alpha = i_a, i_beta = (i_a + 2 i_b) / sqrt 3
// (constant 18919 = round(2^15 / sqrt 3)), rounded half up and saturated to s16.
module clarke (
    input  wire signed [15:0] i_a,
    input  wire signed [15:0] i_b,
    output wire signed [15:0] i_alpha,
    output wire signed [15:0] i_beta
);
    `include "fixed.vh"
    localparam signed [17:0] INV_SQRT3 = 18'sd18919;
    wire signed [17:0] sum = i_a + (i_b <<< 1);       // 18 bit
    wire signed [35:0] prod = sum * INV_SQRT3;        // 33 bit used
    assign i_alpha = i_a;
    assign i_beta = sat16((prod + 36'sd16384) >>> 15);
endmodule
