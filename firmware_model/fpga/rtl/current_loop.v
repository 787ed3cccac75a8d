// The driver board's 20 kHz current loop (firmware_model/fpga/tick.py, current mode):
// phase-current codes -> Clarke -> Park -> d and q PI (the q limit from the voltage circle)
// -> inverse Park -> SVPWM compare counts. Formats per docs/fpga.md's Q-format table.
//
// The datapath is combinational from the inputs and the two integrator registers; a rising
// clk stores the integrators this cycle computed (integ_d_next, integ_q_next). With enable
// low the loop is off: integrators cleared, v_d = v_q = 0, all legs at top/2.
module current_loop #(
    parameter TOP = 1250,            // PWM compare counts per half period
    parameter V_LIMIT = 18918,       // floor(2^15 / sqrt 3): the voltage circle
    parameter MA_TO_I = 26844,       // mA -> Q1.15 of I_FS, shift 15
    parameter MV_TO_V = 22370,       // mV -> Q1.15 of V_dc, shift 15
    parameter KP_SHIFT = 12,
    parameter KI_SHIFT = 16
) (
    input  wire               clk,
    input  wire               rst,            // synchronous: integrators to 0
    input  wire               enable,
    input  wire        [11:0] ia_code,        // phase current ADC codes, 2048 = 0 A
    input  wire        [11:0] ib_code,
    input  wire        [15:0] theta_e,        // electrical angle, 2^16 per turn
    input  wire        [15:0] iq_ref,         // s16 mA
    input  wire        [15:0] id_ref,         // s16 mA
    input  wire        [15:0] vq_ff,          // s16 mV
    input  wire        [15:0] current_limit,  // u16 mA
    input  wire        [15:0] kp,             // x 2^-KP_SHIFT
    input  wire        [15:0] ki,             // x 2^-KI_SHIFT per tick
    output wire signed [15:0] sin_q15,
    output wire signed [15:0] cos_q15,
    output wire signed [15:0] i_alpha,
    output wire signed [15:0] i_beta,
    output wire signed [15:0] i_d,
    output wire signed [15:0] i_q,
    output wire signed [15:0] v_d,
    output wire signed [15:0] v_q,
    output wire        [14:0] q_lim,
    output wire signed [15:0] v_alpha,
    output wire signed [15:0] v_beta,
    output wire        [10:0] count_a,
    output wire        [10:0] count_b,
    output wire        [10:0] count_c,
    output wire signed [31:0] integ_d_next,
    output wire signed [31:0] integ_q_next
);
    `include "fixed.vh"
    localparam [14:0] VLIM = V_LIMIT;

    reg signed [31:0] integ_d, integ_q;

    // phase currents: (code - 2048) << 4, s16 Q1.15 of I_FS
    wire signed [15:0] i_a = ($signed({1'b0, ia_code}) - 13'sd2048) <<< 4;
    wire signed [15:0] i_b = ($signed({1'b0, ib_code}) - 13'sd2048) <<< 4;

    sin_cos trig (.theta_e(theta_e), .sin_q15(sin_q15), .cos_q15(cos_q15));
    clarke cl (.i_a(i_a), .i_b(i_b), .i_alpha(i_alpha), .i_beta(i_beta));
    park pk (.x_alpha(i_alpha), .x_beta(i_beta), .s(sin_q15), .c(cos_q15), .x_d(i_d),
             .x_q(i_q));

    // references from the register words (rounded half up, clamped to the current limit)
    wire signed [47:0] i_lim_full = ({32'd0, current_limit} * MA_TO_I + 48'sd16384) >>> 15;
    wire signed [47:0] i_lim = (i_lim_full > 48'sd32767) ? 48'sd32767 : i_lim_full;
    wire signed [47:0] iq_scaled = ($signed(iq_ref) * MA_TO_I + 48'sd16384) >>> 15;
    wire signed [47:0] id_scaled = ($signed(id_ref) * MA_TO_I + 48'sd16384) >>> 15;
    wire signed [15:0] iq_ref_q15 = clamp48(iq_scaled, -i_lim, i_lim);
    wire signed [15:0] id_ref_q15 = clamp48(id_scaled, -i_lim, i_lim);
    wire signed [15:0] ff = sat16(($signed(vq_ff) * MV_TO_V + 48'sd16384) >>> 15);

    wire signed [16:0] e_d = id_ref_q15 - i_d;
    wire signed [16:0] e_q = iq_ref_q15 - i_q;
    wire signed [15:0] pi_d_u, pi_q_u;
    wire signed [31:0] pi_d_i, pi_q_i;
    wire        [14:0] q_room;
    pi_step #(.KP_SHIFT(KP_SHIFT), .KI_SHIFT(KI_SHIFT)) pi_d (
        .error(e_d), .integ(integ_d), .kp(kp), .ki(ki), .ff(16'sd0), .limit(VLIM),
        .u(pi_d_u), .integ_new(pi_d_i));
    q_limit ql (.v_d(pi_d_u), .v_max(VLIM), .v_q_max(q_room));
    pi_step #(.KP_SHIFT(KP_SHIFT), .KI_SHIFT(KI_SHIFT)) pi_q (
        .error(e_q), .integ(integ_q), .kp(kp), .ki(ki), .ff(ff), .limit(q_room),
        .u(pi_q_u), .integ_new(pi_q_i));

    assign v_d = enable ? pi_d_u : 16'sd0;
    assign v_q = enable ? pi_q_u : 16'sd0;
    assign q_lim = enable ? q_room : 15'd0;
    assign integ_d_next = enable ? pi_d_i : 32'sd0;
    assign integ_q_next = enable ? pi_q_i : 32'sd0;

    wire signed [15:0] va, vb;
    wire [10:0] ca, cb, cc;
    inv_park ip (.v_d(v_d), .v_q(v_q), .s(sin_q15), .c(cos_q15), .v_alpha(va), .v_beta(vb));
    svpwm #(.TOP(TOP)) pwm (.v_alpha(va), .v_beta(vb), .count_a(ca), .count_b(cb),
                            .count_c(cc));
    localparam [10:0] HALF = TOP / 2;
    assign v_alpha = enable ? va : 16'sd0;
    assign v_beta = enable ? vb : 16'sd0;
    assign count_a = enable ? ca : HALF;
    assign count_b = enable ? cb : HALF;
    assign count_c = enable ? cc : HALF;

    always @(posedge clk) begin
        if (rst) begin
            integ_d <= 32'sd0;
            integ_q <= 32'sd0;
        end else begin
            integ_d <= integ_d_next;
            integ_q <= integ_q_next;
        end
    end
endmodule
