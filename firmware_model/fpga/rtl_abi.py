"""The board's side of a compiled current-loop RTL (a Verilated ``current_loop`` in a shared
library, built by :mod:`hil.sim.verilator`): where its words sit in the exchange
buffer, and the compiled calls that reach it from the per-tick path.

The library owns the model; the board owns a buffer of :data:`IO_WORDS` int64 words whose
address the library was given. Per tick the board writes the input ports
(``current_loop.INPUT_PORTS`` order) and whether the tick ends with a rising clock edge,
calls the library's tick function once (every clock cycle of the tick inside the library),
and reads the output ports (``current_loop.OUTPUT_PORTS`` order, sign-extended). The
addresses travel in the board's parameter array (``layout.C_RTL_*``; 0: the board's own
loop), so every compiled caller of the tick reaches the RTL without a new argument.

The calls are numba intrinsics: an address held as an int64 becomes a pointer in the
generated code, so the compiled tick stays cacheable (no address is baked into it)."""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from firmware_model.fpga import layout as B
from firmware_model.fpga.current_loop import (
    INPUT_PORTS,
    O_COUNT_A,
    O_ID,
    O_INTEG_D,
    O_INTEG_Q,
    O_IQ,
    O_VD,
    O_VQ,
    OUTPUT_PORTS,
    loop_outputs,
)

#: Word offsets in the exchange buffer.
IO_IN = 0                                  # input ports, INPUT_PORTS order
IO_EDGE = len(INPUT_PORTS)                 # 1: the tick ends with a rising clk (0: hold)
IO_OUT = 16                                # output ports, OUTPUT_PORTS order
IO_MISMATCHES = IO_OUT + len(OUTPUT_PORTS)  # ticks on which the RTL differed from the model
IO_FIRST_TICK = IO_MISMATCHES + 1          # the board tick of the first difference
IO_FIRST_SIGNAL = IO_FIRST_TICK + 1        # its output port (OUTPUT_PORTS index)
IO_FIRST_MODEL = IO_FIRST_SIGNAL + 1       # the model's word there
IO_FIRST_RTL = IO_FIRST_MODEL + 1          # the RTL's word there
IO_WORDS = IO_FIRST_RTL + 1
assert IO_EDGE < IO_OUT


@intrinsic
def io_load(typingctx, addr, index):  # noqa: ARG001 (numba passes the typing context)
    """The int64 word ``index`` of the buffer at address ``addr``."""
    sig = types.int64(types.int64, types.int64)

    def codegen(context, builder, signature, args):
        a, i = args
        ptr = builder.inttoptr(a, ir.IntType(64).as_pointer())
        return builder.load(builder.gep(ptr, [i]))

    return sig, codegen


@intrinsic
def io_store(typingctx, addr, index, value):  # noqa: ARG001
    """Store ``value`` as int64 word ``index`` of the buffer at address ``addr``."""
    sig = types.void(types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        a, i, v = args
        ptr = builder.inttoptr(a, ir.IntType(64).as_pointer())
        builder.store(v, builder.gep(ptr, [i]))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def call_tick(typingctx, fn, handle):  # noqa: ARG001
    """Call ``void fn(void *handle)`` at address ``fn``."""
    sig = types.void(types.int64, types.int64)

    def codegen(context, builder, signature, args):
        f, h = args
        i8p = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i8p])
        builder.call(builder.inttoptr(f, fnty.as_pointer()), [builder.inttoptr(h, i8p)])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True)
def rtl_loop_tick(c, st, down, ia_code, ib_code, theta_e, enable, edge):
    """One tick of the current loop on the RTL: the input words out, one call, the output
    ports back as ``(i_d, i_q, v_d, v_q, count_a, count_b, count_c)``. With ``edge`` the
    tick ends with a rising clock (the integrators the RTL computed are stored, and kept in
    the board's state); without it the RTL holds them (enabled in voltage mode, where the
    board's own loop does not run either).

    The board model's loop runs beside it on the same words and the RTL's stored
    integrators; the first tick on which any output port differs is kept in the buffer
    (tick, port, both words), and the number of such ticks."""
    io = c[B.C_RTL_IO]
    kp = down[B.D_KP]
    ki = down[B.D_KI]
    words = (enable, ia_code, ib_code, theta_e, down[B.D_IQ_REF], down[B.D_ID_REF],
             down[B.D_VQ_FF], down[B.D_CURRENT_LIMIT], kp, ki)
    for j in range(len(words)):
        io_store(io, IO_IN + j, words[j])
    io_store(io, IO_EDGE, edge)
    call_tick(c[B.C_RTL_TICK], c[B.C_RTL_HANDLE])
    model = loop_outputs(c, words[0], words[1], words[2], words[3], words[4], words[5],
                         words[6], words[7], kp, ki, st[B.F_INTEG_D], st[B.F_INTEG_Q])
    for j in range(len(model)):
        got = io_load(io, IO_OUT + j)
        if got != model[j]:
            n = io_load(io, IO_MISMATCHES)
            if n == 0:
                io_store(io, IO_FIRST_TICK, st[B.F_TICK])
                io_store(io, IO_FIRST_SIGNAL, j)
                io_store(io, IO_FIRST_MODEL, model[j])
                io_store(io, IO_FIRST_RTL, got)
            io_store(io, IO_MISMATCHES, n + 1)
            break
    if edge != 0:
        st[B.F_INTEG_D] = io_load(io, IO_OUT + O_INTEG_D)
        st[B.F_INTEG_Q] = io_load(io, IO_OUT + O_INTEG_Q)
    return (io_load(io, IO_OUT + O_ID), io_load(io, IO_OUT + O_IQ),
            io_load(io, IO_OUT + O_VD), io_load(io, IO_OUT + O_VQ),
            io_load(io, IO_OUT + O_COUNT_A), io_load(io, IO_OUT + O_COUNT_A + 1),
            io_load(io, IO_OUT + O_COUNT_A + 2))


# --- loops of ticks for timing the call (``bench fpga --set fpga.impl=rtl``) ----------------
#: Input words of the timing ticks: board gains, an 18 A limit, a 5 A reference.
_WORDS = (1, 2048, 2040, 0, 5000, 0, 0, 18000, 1287, 6433)
_N_OUT = len(OUTPUT_PORTS)


@njit(cache=True)
def timing_ticks_rtl(c, n):
    """``n`` ticks of the RTL through its address on the timing words (a turning angle,
    a wandering current code); a sum of the outputs, so that nothing is optimised away."""
    io = c[B.C_RTL_IO]
    acc = 0
    for k in range(n):
        for j in range(len(_WORDS)):
            io_store(io, IO_IN + j, _WORDS[j])
        io_store(io, IO_IN + 1, 2048 + (k & 63))
        io_store(io, IO_IN + 3, (k * 700) & 0xFFFF)
        io_store(io, IO_EDGE, 1)
        call_tick(c[B.C_RTL_TICK], c[B.C_RTL_HANDLE])
        for j in range(_N_OUT):
            acc += io_load(io, IO_OUT + j)
    return acc


@njit(cache=True)
def timing_ticks_model(c, n):
    """The same ticks through the board model's loop."""
    acc = 0
    integ_d = 0
    integ_q = 0
    w = _WORDS
    for k in range(n):
        r = loop_outputs(c, w[0], 2048 + (k & 63), w[2], (k * 700) & 0xFFFF, w[4], w[5], w[6],
                         w[7], w[8], w[9], integ_d, integ_q)
        integ_d = r[O_INTEG_D]
        integ_q = r[O_INTEG_Q]
        for j in range(len(r)):
            acc += r[j]
    return acc


__all__ = ["IO_EDGE", "IO_FIRST_MODEL", "IO_FIRST_RTL", "IO_FIRST_SIGNAL", "IO_FIRST_TICK",
           "IO_IN", "IO_MISMATCHES", "IO_OUT", "IO_WORDS", "call_tick", "io_load", "io_store",
           "rtl_loop_tick", "timing_ticks_model", "timing_ticks_rtl"]
