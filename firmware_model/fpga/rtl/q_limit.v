// Room for v_q inside the voltage circle: isqrt(v_max^2 - v_d^2), 0 when |v_d| >= v_max.
// The square root is the 16-step digit-by-digit method, unrolled.
module q_limit (
    input  wire signed [15:0] v_d,
    input  wire        [14:0] v_max,
    output reg         [14:0] v_q_max
);
    wire signed [31:0] r = $signed({17'd0, v_max}) * $signed({17'd0, v_max}) - v_d * v_d;
    reg [31:0] n, root, one;
    integer i;
    always @* begin
        n = r[31] ? 32'd0 : r;
        root = 32'd0;
        one = 32'h40000000;
        for (i = 0; i < 16; i = i + 1) begin
            if (n >= root + one) begin
                n = n - (root + one);
                root = (root >> 1) + one;
            end else begin
                root = root >> 1;
            end
            one = one >> 2;
        end
        v_q_max = root[14:0];
    end
endmodule
