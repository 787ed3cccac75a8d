// One PI update (firmware_model/fpga/foc.py pi_step): u = round(kp e / 2^KP_SHIFT) +
// round(integ / 2^KI_SHIFT) + ff, saturated to +/-limit. The integrator adds ki e, clamped to
// +/-limit 2^KI_SHIFT; while the output saturates, integration towards the rail is skipped
// (the held value is clamped again: the limit may have shrunk).
module pi_step #(
    parameter KP_SHIFT = 12,
    parameter KI_SHIFT = 16
) (
    input  wire signed [16:0] error,      // ref - measured, s17
    input  wire signed [31:0] integ,
    input  wire        [15:0] kp,
    input  wire        [15:0] ki,
    input  wire signed [15:0] ff,
    input  wire        [14:0] limit,
    output reg  signed [15:0] u,
    output reg  signed [31:0] integ_new
);
    `include "fixed.vh"
    wire signed [33:0] kp_e = $signed({1'b0, kp}) * error;                 // 34 bit
    wire signed [33:0] ki_e = $signed({1'b0, ki}) * error;
    wire signed [21:0] p = (kp_e + (34'sd1 <<< (KP_SHIFT - 1))) >>> KP_SHIFT;
    wire signed [31:0] i_lim = $signed({17'd0, limit}) <<< KI_SHIFT;
    wire signed [34:0] advanced = integ + ki_e;                             // 34 bit + carry
    wire signed [31:0] i_adv = clamp48(advanced, -i_lim, i_lim);
    wire signed [31:0] i_held = clamp48(integ, -i_lim, i_lim);
    wire signed [16:0] i_out = (i_adv + (32'sd1 <<< (KI_SHIFT - 1))) >>> KI_SHIFT;
    wire signed [23:0] sum = p + i_out + ff;
    wire signed [15:0] lim = $signed({1'b0, limit});
    always @* begin
        if (sum > lim) begin
            u = lim;
            integ_new = (error > 0) ? i_held : i_adv;
        end else if (sum < -lim) begin
            u = -lim;
            integ_new = (error < 0) ? i_held : i_adv;
        end else begin
            u = sum[15:0];
            integ_new = i_adv;
        end
    end
endmodule
