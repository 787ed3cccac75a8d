// Testbench top for the cocotb replay (hil/verify/current_loop/testbench.py): the current loop's ports
// packed into one input and one output bus, so each cycle costs the simulator interface one
// write and one read. Connects by port name: any RTL with the current loop's ports fits.
// Generated from hil/verify/current_loop/records.py (field order, least significant first).
module tb_current_loop (
    input  wire              clk,
    input  wire              rst,
    input  wire [136:0]      in_bus,
    output wire [271:0]      out_bus
);
    current_loop dut (
        .clk(clk),
        .rst(rst),
        .enable(in_bus[0:0]),
        .ia_code(in_bus[12:1]),
        .ib_code(in_bus[24:13]),
        .theta_e(in_bus[40:25]),
        .iq_ref(in_bus[56:41]),
        .id_ref(in_bus[72:57]),
        .vq_ff(in_bus[88:73]),
        .current_limit(in_bus[104:89]),
        .kp(in_bus[120:105]),
        .ki(in_bus[136:121]),
        .sin_q15(out_bus[15:0]),
        .cos_q15(out_bus[31:16]),
        .i_alpha(out_bus[47:32]),
        .i_beta(out_bus[63:48]),
        .i_d(out_bus[79:64]),
        .i_q(out_bus[95:80]),
        .v_d(out_bus[111:96]),
        .v_q(out_bus[127:112]),
        .q_lim(out_bus[142:128]),
        .v_alpha(out_bus[158:143]),
        .v_beta(out_bus[174:159]),
        .count_a(out_bus[185:175]),
        .count_b(out_bus[196:186]),
        .count_c(out_bus[207:197]),
        .integ_d_next(out_bus[239:208]),
        .integ_q_next(out_bus[271:240])
    );
endmodule
