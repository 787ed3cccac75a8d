// sin and cos of the electrical angle (u16, 2^16 per turn) in Q1.15 from the quarter-wave
// table: index k = (theta_e + 32) >> 6 mod 1024 (1024 steps per turn), cos at k + 256.
module quarter_sine (
    input  wire [9:0]         k,
    output wire signed [15:0] y
);
    wire [7:0] r = k[7:0];
    wire [8:0] addr = k[8] ? (9'd256 - {1'b0, r}) : {1'b0, r};
    wire [15:0] mag;
    sine_rom rom (.addr(addr), .data(mag));
    assign y = k[9] ? -$signed(mag) : $signed(mag);
endmodule

module sin_cos (
    input  wire [15:0]        theta_e,
    output wire signed [15:0] sin_q15,
    output wire signed [15:0] cos_q15
);
    wire [16:0] rounded = {1'b0, theta_e} + 17'd32;
    wire [9:0]  k = rounded[15:6];
    wire [9:0]  k_cos = k + 10'd256;
    quarter_sine s (.k(k), .y(sin_q15));
    quarter_sine c (.k(k_cos), .y(cos_q15));
endmodule
