// Width-explicit helpers of the current loop (firmware_model/fpga/fixed.py): saturation and
// clamping on wide signed intermediates. Rounding shifts are written out where they occur:
// (x + 2^(s-1)) >>> s, round half up.
function automatic signed [15:0] sat16(input signed [47:0] x);
    if (x > 48'sd32767)
        sat16 = 16'sd32767;
    else if (x < -48'sd32768)
        sat16 = -16'sd32768;
    else
        sat16 = x[15:0];
endfunction

function automatic signed [47:0] clamp48(input signed [47:0] x, input signed [47:0] lo,
                                         input signed [47:0] hi);
    if (x < lo)
        clamp48 = lo;
    else if (x > hi)
        clamp48 = hi;
    else
        clamp48 = x;
endfunction
