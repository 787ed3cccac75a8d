// Space-vector PWM by min-max zero-sequence injection: phase voltages by inverse Clarke
// (v_b = (28378 v_beta - 2^14 v_alpha) / 2^15, rounded half up; v_c = -v_a - v_b), minus the
// mean of the largest and smallest (floor), then count = top/2 + v_x top / 2^15 (rounded half
// up), clamped to 0..top.
module svpwm #(
    parameter TOP = 1250
) (
    input  wire signed [15:0] v_alpha,
    input  wire signed [15:0] v_beta,
    output wire        [10:0] count_a,
    output wire        [10:0] count_b,
    output wire        [10:0] count_c
);
    `include "fixed.vh"
    localparam signed [15:0] SQRT3_2 = 16'sd28378;
    localparam signed [47:0] TOP_S = TOP;
    localparam signed [47:0] HALF = TOP / 2;
    wire signed [32:0] vb_num = v_beta * SQRT3_2 - (v_alpha <<< 14);
    wire signed [16:0] v_a = v_alpha;
    wire signed [17:0] v_b = (vb_num + 33'sd16384) >>> 15;
    wire signed [17:0] v_c = -v_a - v_b;
    wire signed [17:0] hi = (v_a > v_b) ? ((v_a > v_c) ? v_a : v_c) : ((v_b > v_c) ? v_b : v_c);
    wire signed [17:0] lo = (v_a < v_b) ? ((v_a < v_c) ? v_a : v_c) : ((v_b < v_c) ? v_b : v_c);
    wire signed [18:0] hl = hi + lo;
    wire signed [18:0] v_off = -(hl >>> 1);
    function automatic [10:0] leg(input signed [18:0] v);
        reg signed [47:0] scaled;
        begin
            scaled = (v * TOP_S + 48'sd16384) >>> 15;
            leg = clamp48(HALF + scaled, 48'sd0, TOP_S);
        end
    endfunction
    assign count_a = leg(v_a + v_off);
    assign count_b = leg(v_b + v_off);
    assign count_c = leg(v_c + v_off);
endmodule
