"""The whole robot in one engine: every actuator's stack below the MCU (plant, sensor chips,
driver board, LVDS link) and its MCU program advanced together, batched over actuators.

The per-actuator path (:class:`~hil.fieldbus.boxes.StackBox`) steps each box's Python MCU
model and calls each actuator's compiled stack every MCU period: 47 actuators cost ~10 Python
calls each per MCU period. Here one fieldbus cycle (20 ticks) is one compiled call
(:func:`advance_robot`) per compute thread. Each thread claims actuators one at a time (an
atomic counter) and runs each claimed actuator's five MCU periods: its MCU program steps
(the MCU law's host build, ``firmware_model/mcu/c/``, ``mcu_law_step_many``, built with
``-ffp-contract=off`` and checked bit for bit against the Python model, docs/mcu.md), its
downstream words go into its LVDS memory, its stack advances one MCU period, its upstream
words go back into the program's input record. Actuators share nothing within a cycle, so
which thread runs which changes no result; claiming one by one balances the threads even
when one core is busy with the master and the PC loop,

and the process data of all boxes is decoded and packed with whole-array operations. The
arrays of every :class:`~hil.sim.actuator.FpgaStack` are rebound to rows of the engine's arrays,
so faults and tools that hold a stack see the same memory. A stack with a sensor fault
(:class:`~hil.fieldbus.stack_faults.FaultyStack` overriding plant outputs tick by tick) is left
out of the compiled call and advanced by its own wrapper between the same two copies.

Same results as the per-actuator path, bit for bit (``tests/hil/test_robot.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Protocol

import llvmlite.binding as llvm
import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.lvds import lanes as link_lanes
from firmware_model.lvds import link as LK
from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    IN_GAINS,
    INPUT,
    OUTPUT,
    config_record,
)
from hil.fieldbus import pdo
from hil.fieldbus.pdo_compiled import counts as _counts
from hil.fieldbus.pdo_compiled import le as _le
from hil.fieldbus.pdo_compiled import put as _put
from hil.sim import compute_threads as ct
from hil.sim.actuator import (
    TRACE_WIDTH,
    TRACE_WORDS,
    advance_stack,
    drive_lanes,
    trace_row_lanes,
)
from hil.sim.robot_tunables import EngineTunables
from hil.sim.stack_rows import (
    SOURCES,
    ImageRows,
    LinkSensorLanes,
    McuRows,
    StackRows,
    TapRows,
)
from plant import lanes as lanes_mod
from plant import layout as L
from plant.config import Config, ConfigError
from plant.lane_outputs import load_outputs, outputs_in_lanes, store_outputs
from plant.sensors import lanes as sensor_lanes

#: Offsets of the input record's fields, in 16-bit words (the kernel writes through a view).
_IN_U16 = INPUT.itemsize // 2
_IN_UP = INPUT.fields["up"][1] // 2
_IN_CRC = INPUT.fields["up_crc_errors"][1] // 4
_IN_TICK = INPUT.fields["tick"][1] // 4
_IN_FLAGS = INPUT.fields["flags"][1] // 4
_OUT_U16 = OUTPUT.itemsize // 2
_OUT_DOWN = OUTPUT.fields["down"][1] // 2
_T_ANALOG = [a.name for a in B.ANALOG_INPUTS].index("temperature")
_IN_MODE = INPUT.fields["mode"][1] // 4
_IN_VALUE = INPUT.fields["value"][1] // 4
_IN_KPOS = INPUT.fields["kp_position"][1] // 4
_IN_KPF = INPUT.fields["kp_force"][1] // 4
_OUT_STATUS = OUTPUT.fields["status"][1] // 4
_OUT_X = OUTPUT.fields["x_piston"][1] // 4
_OUT_F_STRAIN_RAW = OUTPUT.fields["f_strain_raw"][1] // 4
_OUT_F_PRES = OUTPUT.fields["f_pres"][1] // 4
_OUT_F_FIL = OUTPUT.fields["f_fil"][1] // 4
_OUT_IQ = OUTPUT.fields["iq"][1] // 4
_OUT_TEMP = OUTPUT.fields["m_analog"][1] // 4 + _T_ANALOG
#: Byte offsets in an actuator's output record, and the sizes of its input record's fields.
_O_MODE, _O_FLAGS, _O_COMMAND, _O_KPOS, _O_KPF = (
    pdo.ACTUATOR_OUT_DTYPE.fields[f.name][1] for f in pdo.ACTUATOR_OUT)
_IN_SIZES = tuple(np.dtype(f.dtype).itemsize for f in pdo.ACTUATOR_IN)
_FLAG_ENABLE = pdo.FLAG_ENABLE
_FLAG_CLEAR = pdo.FLAG_CLEAR_FAULT
assert [f.name for f in pdo.ACTUATOR_IN] == [
    "x_piston", "v_piston", "f_pressure", "f_strain", "f_filtered", "iq", "temperature",
    "status", "err_link_down", "err_link_up"]
assert [f.name for f in pdo.ACTUATOR_OUT] == ["mode", "flags", "command", "kp_position",
                                              "kp_force"]
assert all(OUTPUT.fields[n][1] % 4 == 0 for n in OUTPUT.names)
assert fpl.LW == lanes_mod.LW, "a batch's boards and plants share the lanes"


#: The MCU law's host build, linked by name (the library is loaded by :class:`RobotEngine`
#: before the first call): ``mcu_law_step_many(states, inputs, n, outputs)``, addresses.
_mcu_law_step_many = types.ExternalFunction(
    "mcu_law_step_many", types.void(types.intp, types.intp, types.uint32, types.intp))
#: The law in lanes (``mcu_law_lanes.c``, same library), for a batch of at most ``LW``
#: actuators, rows ``rows[:m]``: ``mcu_lanes_load(lanes, states, rows, m)`` when the batch is
#: claimed, ``mcu_lanes_step(lanes, inputs, outputs, rows, m)`` once per MCU period,
#: ``mcu_lanes_store(lanes, states, outputs, rows, m)`` at the batch's end; addresses.
_mcu_lanes_load = types.ExternalFunction(
    "mcu_lanes_load", types.void(types.intp, types.intp, types.intp, types.uint32))
_mcu_lanes_step = types.ExternalFunction(
    "mcu_lanes_step", types.void(types.intp, types.intp, types.intp, types.intp, types.uint32))
_mcu_lanes_store = types.ExternalFunction(
    "mcu_lanes_store", types.void(types.intp, types.intp, types.intp, types.intp, types.uint32))


@intrinsic
def _claim(typingctx, counter):
    """``counter[0] += 1`` as one atomic operation; returns the value before it: the index
    the calling thread now owns (the threads of a cycle share the actuators this way)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary,
                                       [context.get_constant(types.intp, 0)])
        return builder.atomic_rmw("add", ptr, ir.Constant(ir.IntType(64), 1), "seq_cst")

    return types.int64(counter), codegen


@intrinsic
def _copy_bytes(typingctx, dst, src, nbytes):
    """The first ``nbytes`` bytes of array ``src`` into array ``dst`` (both contiguous,
    not overlapping, large enough: unchecked), as one ``memcpy``: with a constant count
    LLVM makes it a few vector moves."""
    if not (isinstance(dst, types.Array) and isinstance(src, types.Array)
            and isinstance(nbytes, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        d = context.make_array(signature.args[0])(context, builder, args[0])
        s = context.make_array(signature.args[1])(context, builder, args[1])
        cgutils.raw_memcpy(builder, d.data, s.data, args[2], 1)
        return context.get_dummy_value()

    return types.void(dst, src, nbytes), codegen


# _log_words copies the records' bytes: the CRC-error count is a whole u32 (its two u16,
# low half first, in the log's row), the downstream words are all in the output record
assert INPUT.fields["up_crc_errors"][1] % 4 == 0
assert OUTPUT.fields["down"][0].shape == (B.DOWN_WORDS,)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _log_words(log, i, r, in16, in32, out16):
    """Row ``r`` of actuator ``i`` in the frame log's copies (a
    :class:`~hil.sim.stack_rows.TapRows`): the upstream words and CRC-error count the MCU
    program read at this step (the count as a u32 in two u16, low half first), the
    downstream words it wrote. Three byte copies: a loop of 16-bit stores per word was
    ~2x slower (the compiler must assume the rows may overlap the records, so it could
    not combine the stores; 235,000 steps per simulated second of the whole robot)."""
    _copy_bytes(log.up[i, r], in16[i, _IN_UP:], 2 * B.UP_WORDS)
    _copy_bytes(log.up[i, r, B.UP_WORDS:], in32[i, _IN_CRC:], 4)
    _copy_bytes(log.down[i, r], out16[i, _OUT_DOWN:], 2 * B.DOWN_WORDS)


# No reference counting (``_nrt=False``, as the parts' tick functions): every row view
# below would otherwise increment and decrement the parent array's count, an atomic on a
# cache line all compute threads share (~200 ns per actuator tick with one thread, more
# with two). Reading a field of a bundle is a static tuple index: no count either.
@njit(cache=True, nogil=True, _nrt=False)
def advance_robot(counter, n_periods, period, tick0, batched, s, mcu, no_rec, tap):
    """``n_periods`` MCU periods of ``period`` ticks from ``tick0`` for the actuators this
    thread claims (``counter``: the next unclaimed index, shared by every thread of the
    cycle), those with ``batched[i]``: its MCU program (state, input and output record at
    the addresses ``mcu.ptrs[i]``) steps, its downstream words go into its LVDS memory, its
    stack (``s``, a :class:`StackRows`) advances one period, its upstream words and the
    link's CRC count go into its input record. ``mcu.err[i]``: the link error counts the
    program read at its last step. ``no_rec``: an empty record array (no plant record
    here). ``tap`` (a :class:`~hil.sim.stack_rows.TapRows`): the MCU words of each step and
    the board traces for a frame log, if it has rows. Returns how many actuators this
    thread advanced."""
    pl, se, bd, lk = s.plant, s.sensors, s.board, s.link
    in16, in32 = mcu.in16, mcu.in32
    done = 0
    while True:
        i = _claim(counter)
        if i >= pl.x.shape[0]:
            return done
        if not batched[i]:
            continue
        done += 1
        for n in range(n_periods):
            t = tick0 + n * period
            in32[i, _IN_TICK] = t
            _mcu_law_step_many(mcu.ptrs[i, 0], mcu.ptrs[i, 1], 1, mcu.ptrs[i, 2])
            in32[i, _IN_FLAGS] = 0
            if n == n_periods - 1:
                mcu.err[i, 0] = in16[i, _IN_UP + B.U_ERR_LINK_CRC]
                mcu.err[i, 1] = in32[i, _IN_CRC]
            for w in range(lk.mcu_down.shape[1]):
                lk.mcu_down[i, w] = mcu.out16[i, _OUT_DOWN + w]
            r = tap.row[0] + n
            if tap.up.shape[1] > 0:  # a frame log: the words the program read and wrote
                _log_words(tap, i, r, in16, in32, mcu.out16)
            advance_stack(period, pl.x[i], pl.params[i], pl.u[i], pl.y[i], no_rec, 0, 1, t,
                          pl.rng[i], pl.work[i], se.chips[i], se.raw[i], bd.params[i],
                          bd.state[i], bd.down[i], bd.up[i], lk.mcu_down[i], lk.mcu_up[i],
                          lk.state[i], tap.trace[i, r * period:(r + 1) * period])
            for w in range(lk.mcu_up.shape[1]):
                in16[i, _IN_UP + w] = lk.mcu_up[i, w] & 0xFFFF
            in32[i, _IN_CRC] = lk.state[i, LK.LK_MASTER_CRC]


@njit(cache=True, nogil=True, _nrt=False, error_model="numpy")
def advance_robot_lanes(counter, n_periods, period, tick0, blocks, sizes, n_sub_max, s, mcu,
                        buf, fb, ls, tap_y, tap_trace, log):
    """:func:`advance_robot` with the plants in lanes: this thread claims whole batches
    (``blocks[b, :sizes[b]]``: up to :data:`plant.lanes.LW` actuator rows, counted by
    ``counter``) and runs their MCU periods together. Per tick the batch's sensor chips
    (:func:`plant.sensors.lanes.digitise_lanes`) and downstream LVDS sweeps
    (:func:`firmware_model.lvds.lanes.sweep_down_lanes`) in lanes, the batch's boards in one
    pass over the lanes (:func:`firmware_model.fpga.lanes.board_tick`), the batch's
    upstream sweeps in lanes, the inverters (:func:`~hil.sim.actuator.drive_lanes`), then
    all their plants take the tick's RK4 step in one pass over the lanes
    (:func:`plant.lanes.rk4_lanes`, in ``buf``, this thread's lane buffer), then their
    outputs and noise (:func:`plant.lane_outputs.outputs_in_lanes`, in the same buffer).
    ``fb``: this thread's board lane buffer. ``ls`` (a
    :class:`~hil.sim.stack_rows.LinkSensorLanes`): this thread's lane buffers of the links'
    counters and word logs and of the chips' parameters and codes.

    What the stages hand each other stays in the lanes for the whole call: loaded from
    the actuators' rows when a batch is claimed, stored back at its end (plant states,
    inputs, outputs and noise streams; the board's state, raw sensor words, downstream
    memory and link counts; the links' counters). A tick moves no actuator row but the
    board's upstream memory (its row: the link copies it whole into its delay ring), the
    MCU's memories (once per MCU period, below) and what a tap or log copies out. Each
    actuator sees the operations of :func:`advance_stack` in its order: the batch only
    interleaves independent actuators.

    ``tap_y`` (actuators, ticks, outputs) and ``tap_trace`` (actuators, ticks,
    ``TRACE_WIDTH``): where given (not empty), every tick's plant outputs and board trace
    row (:func:`advance_stack`'s) of every actuator (:attr:`RobotEngine.tap`). ``log`` (a
    :class:`~hil.sim.stack_rows.TapRows`): the frame log's copies, filled as
    :func:`advance_robot` fills them. Returns how many actuators this thread advanced."""
    pl, se, bd, lk = s.plant, s.sensors, s.board, s.link
    in16, in32 = mcu.in16, mcu.in32
    done = 0
    while True:
        b = _claim(counter)
        if b >= blocks.shape[0]:
            return done
        m = sizes[b]
        rows = blocks[b]
        done += m
        # The batch's stages and the words between them in lanes for the whole call:
        # loaded here, stored back at the batch's end.
        lanes_mod.load_params(buf, pl.params, rows, m)
        lanes_mod.load_states(buf, pl.x, pl.u, rows, m)
        load_outputs(buf, pl.y, pl.rng, rows, m)
        fpl.load_board(fb, bd.params, bd.state, se.raw, bd.down, rows, m)
        sensor_lanes.load_chips(ls.chips, se.chips, rows, m)
        link_lanes.load_link(ls.link, lk.state, rows, m)
        # The batch's MCU programs in lanes (ls.mcu) until the batch's end: the records'
        # bases are row 0's addresses.
        at_rows, n_lanes = rows.ctypes.data, np.uint32(m)
        _mcu_lanes_load(ls.mcu.ctypes.data, mcu.ptrs[0, 0], at_rows, n_lanes)
        for n in range(n_periods):
            t = tick0 + n * period
            r = log.row[0] + n
            # advance_stack traces only into a slice with a row for every tick of the period
            logging_trace = log.trace.shape[1] >= (r + 1) * period
            tracing = logging_trace or tap_trace.shape[0] > 0
            for j in range(m):
                in32[rows[j], _IN_TICK] = t
            _mcu_lanes_step(ls.mcu.ctypes.data, mcu.ptrs[0, 1], mcu.ptrs[0, 2], at_rows, n_lanes)
            for j in range(m):
                i = rows[j]
                in32[i, _IN_FLAGS] = 0
                if n == n_periods - 1:
                    mcu.err[i, 0] = in16[i, _IN_UP + B.U_ERR_LINK_CRC]
                    mcu.err[i, 1] = in32[i, _IN_CRC]
                for w in range(lk.mcu_down.shape[1]):
                    lk.mcu_down[i, w] = mcu.out16[i, _OUT_DOWN + w]
                if log.up.shape[1] > 0:
                    _log_words(log, i, r, in16, in32, mcu.out16)
            for k in range(period):
                at = n * period + k
                lt = r * period + k  # the log trace's row (advance_stack's k-th)
                sensor_lanes.digitise_lanes(ls.chips, buf, fb, se.chips, rows, m, t + k, pl.y,
                                            se.raw)
                link_lanes.sweep_down_lanes(ls.link, lk.state, lk.mcu_down, fb, bd.state,
                                            bd.down, rows, m)
                fpl.board_tick(fb, rows, m, se.raw, bd.down, bd.state, bd.up, bd.params)
                if tracing:
                    for j in range(m):
                        i = rows[j]
                        if tap_trace.shape[0] > 0:
                            trace_row_lanes(tap_trace[i], at, fb, j, bd.up[i])
                        if logging_trace:
                            trace_row_lanes(log.trace[i], lt, fb, j, bd.up[i])
                link_lanes.sweep_up_lanes(ls.link, lk.state, bd.up, lk.mcu_up, rows, m)
                if tracing:
                    for j in range(m):
                        i = rows[j]
                        if tap_trace.shape[0] > 0:
                            link_lanes.word_log(tap_trace[i], at, TRACE_WORDS, ls.link, j)
                        if logging_trace:
                            link_lanes.word_log(log.trace[i], lt, TRACE_WORDS, ls.link, j)
                drive_lanes(fb, buf, rows)
                lanes_mod.rk4_lanes(buf, n_sub_max)
                outputs_in_lanes(buf, pl.rng, rows, m)
                if tap_y.shape[0] > 0:
                    for j in range(m):
                        i = rows[j]
                        for w in range(tap_y.shape[2]):
                            tap_y[i, at, w] = buf[lanes_mod.YO + w * lanes_mod.LW + j]
            for j in range(m):
                i = rows[j]
                for w in range(lk.mcu_up.shape[1]):
                    in16[i, _IN_UP + w] = lk.mcu_up[i, w] & 0xFFFF
                in32[i, _IN_CRC] = lk.state[i, LK.LK_MASTER_CRC]
        lanes_mod.store_states(buf, pl.x, rows, m)
        lanes_mod.store_inputs(buf, pl.u, rows, m)
        store_outputs(buf, pl.y, pl.rng, rows, m)
        fpl.store_board(fb, bd.state, se.raw, bd.down, rows, m)
        link_lanes.store_link(ls.link, lk.state, rows, m)
        _mcu_lanes_store(ls.mcu.ctypes.data, mcu.ptrs[0, 0], mcu.ptrs[0, 2], at_rows, n_lanes)


@njit(cache=True)
def take_outputs(image, at, got, enabled, clear, in32, inf32, cmd_lsb, gain_lsb):
    """What :meth:`McuBoard.apply` does with each actuator's output record (at byte
    ``at[i]`` of ``image``) for the actuators ``got[i]``: the program's input flags (a fresh
    command and gains; enable, disable and clear-fault edges against ``enabled``/``clear``),
    mode, command value (``cmd_lsb[mode]`` per count) and gains (``gain_lsb`` per count)."""
    for i in range(at.shape[0]):
        if not got[i]:
            in32[i, _IN_FLAGS] = 0
            continue
        o = at[i]
        mode = _le(image, o + _O_MODE, 1, False)
        if mode >= cmd_lsb.shape[0]:
            mode = 0  # an unknown code is "off"
        flags = _le(image, o + _O_FLAGS, 1, False)
        on = (flags & _FLAG_ENABLE) != 0
        cl = (flags & _FLAG_CLEAR) != 0
        f = IN_COMMAND | IN_GAINS
        if cl and not clear[i]:
            f |= IN_CLEAR_FAULT
        if on and not enabled[i]:
            f |= IN_ENABLE
        elif enabled[i] and not on:
            f |= IN_DISABLE
        enabled[i], clear[i] = on, cl
        in32[i, _IN_FLAGS] = f
        in32[i, _IN_MODE] = mode
        inf32[i, _IN_VALUE] = np.float32(_le(image, o + _O_COMMAND, 4, True) * cmd_lsb[mode])
        inf32[i, _IN_KPOS] = np.float32(_le(image, o + _O_KPOS, 2, False) * gain_lsb[0])
        inf32[i, _IN_KPF] = np.float32(_le(image, o + _O_KPF, 2, False) * gain_lsb[1])


@njit(cache=True)
def give_inputs(image, at, out32, outf32, x_prev, dt, cos_alpha, err, lsb, bounds, out_image,
                got, tick, ticks, periods, log, tap_row):
    """:meth:`McuBoard.report` packed into each actuator's input record (at byte ``at[i]``
    of ``image``) from its program's last output record: piston position and its change
    over ``dt`` s (0: no speed), the forces, current, temperature, status and link error
    counts (``err``); ``lsb``/``bounds``: the fields' scales and ranges in record order.
    Then, for a frame log (``log``, an :class:`~hil.sim.stack_rows.ImageRows` with rows),
    the cycle's images into its next row: the input image given, the output image
    ``out_image`` and the actuators' ``got`` flags the cycle took ``ticks`` before
    ``tick``; the tap's row ``tap_row[0]`` moves on by the cycle's ``periods`` MCU steps.
    (Here, not in a Python hook per cycle: three row copies from Python cost ~2 us a
    cycle, most of it the interpreter's.)"""
    for i in range(at.shape[0]):
        o = at[i]
        x = np.float64(outf32[i, _OUT_X])
        v = (x - x_prev[i]) / dt if dt > 0 else 0.0
        x_prev[i] = x
        f_strain = np.float64(cos_alpha * outf32[i, _OUT_F_STRAIN_RAW])
        values = (x, v, np.float64(outf32[i, _OUT_F_PRES]), f_strain,
                  np.float64(outf32[i, _OUT_F_FIL]), np.float64(outf32[i, _OUT_IQ]),
                  np.float64(outf32[i, _OUT_TEMP]))
        pos = o
        for f in range(7):
            n_bytes = _IN_SIZES[f]
            _put(image, pos, n_bytes, _counts(values[f], lsb[f], bounds[f, 0], bounds[f, 1]))
            pos += n_bytes
        _put(image, pos, 2, out32[i, _OUT_STATUS] & 0xFFFF)
        _put(image, pos + 2, 2, min(err[i, 0], 0xFFFF))
        _put(image, pos + 4, 2, min(err[i, 1], 0xFFFF))
    c = log.at[0]
    if c < log.inp.shape[0]:
        log.inp[c, :] = image
        log.out[c, :] = out_image
        log.got[c, :] = got
        log.t_out[c] = tick - ticks
        log.t_in[c] = tick
        log.at[0] = c + 1
        tap_row[0] += periods


@njit(nogil=True, cache=True)
def _serve_lanes(ctl, job, seen, spins, counter, period, *rest):
    """A helper thread's life (:mod:`hil.sim.compute_threads`): each posted cycle (its MCU
    periods and first tick in ``job``), its share of :func:`advance_robot_lanes`, with
    ``rest``: that kernel's arguments after ``tick0``."""
    while True:
        seen = ct.await_post(ctl, seen, spins)
        if ct.stopping(ctl):
            return 0
        advance_robot_lanes(counter, job[ct.JOB_A], period, job[ct.JOB_B], *rest)
        ct.finished(ctl)


@njit(nogil=True, cache=True)
def _serve_actuators(ctl, job, seen, spins, counter, period, *rest):
    """:func:`_serve_lanes` for :func:`advance_robot` (one actuator at a time)."""
    while True:
        seen = ct.await_post(ctl, seen, spins)
        if ct.stopping(ctl):
            return 0
        advance_robot(counter, job[ct.JOB_A], period, job[ct.JOB_B], *rest)
        ct.finished(ctl)


def _entry(kernel: Callable, args: tuple) -> Callable:
    """The compiled entry point of ``kernel`` for the types of ``args``: called with
    arguments of those types it skips the dispatcher's typing of every argument (~4 us for
    the engine's nested tuples of arrays, per call)."""
    return kernel.compile(tuple(kernel.typeof_pyval(a) for a in args))


class RobotEngine:
    """All StackBoxes of a chain advanced as one; ``workers`` threads share the actuators
    (``None``: one per core). The calling thread is one of them (with one worker, the
    only one: no hand-off at all); the others are helper threads that wait for each cycle
    in compiled code (:mod:`hil.sim.compute_threads`)."""

    def __init__(self, boxes: list, cfg: Config, workers: int | None = None,
                 overlap: bool = True, cycle_ticks: int = 20, lanes: bool | None = None
                 ) -> None:
        from hil.sim.mcu_builds import BuildError, HostLaw, build_host

        self.all_boxes = boxes
        self.boxes = [b for b in boxes if getattr(b, "board", None) is not None]
        self._stale = True  # the compiled calls' arguments changed (see _calls)
        self.workers = workers
        self.period = cfg.get("mcu.period_ticks")
        self.tick_s = cfg.get("sim.tick_ns") * 1e-9
        #: (box, slot index in the box) of each actuator, in chain order.
        self.slots = [(b, i) for b in self.boxes for i in range(len(b.stacks))]
        n = self.n = len(self.slots)
        try:
            library = build_host()
        except BuildError as exc:
            raise ConfigError(f"the robot engine runs the MCU law's C build: {exc}") from None
        self.law = HostLaw(library)
        llvm.load_library_permanently(str(library))  # for advance_robot's call by name
        self._bind_arrays()
        recipes = self.arrays.plant.params[:, L.P_NUMERICS]
        lane_ok = n > 0 and recipes.min() >= 3.0
        if lanes and not lane_ok:
            raise ConfigError("the robot engine's lanes need the plant's arithmetic recipe 3 "
                              "(sim.plant_numerics >= 3); this configuration has "
                              f"{int(recipes.min()) if n else 'no actuators'}")
        #: The plants in vector lanes (:func:`advance_robot_lanes`); else one actuator at a
        #: time (:func:`advance_robot`). Default: lanes where the recipe allows them.
        self.lanes = lane_ok if lanes is None else lanes
        self._take = self._give = None  # entry points of take_outputs / give_inputs
        config = config_record(cfg)
        size = self.law.state_size
        self.states = np.zeros(n * size, dtype=np.uint8)
        for j in range(n):
            self.law.init_at(self.states.ctypes.data + j * size, config)
        #: The MCU tunables written to the actuators (:meth:`tune`).
        self.tunables = EngineTunables(cfg, self.states, size, n)
        self.inp = np.zeros(n, dtype=INPUT)
        self.out = np.zeros(n, dtype=OUTPUT)
        self.in16 = self.inp.view(np.uint16).reshape(n, _IN_U16)
        self.in32 = self.inp.view(np.uint32).reshape(n, _IN_U16 // 2)
        self.out16 = self.out.view(np.uint16).reshape(n, _OUT_U16)
        self.out["down"] = self.out_down_init = config["down_init"]
        self.inp["angle_offset"] = [b.stacks[i].board.calibrated_offset for b, i in self.slots]
        self.cos_alpha = np.float32(config["cos_alpha"])
        self._refresh_inputs(np.ones(n, dtype=bool))
        # Process data as the boxes last decoded it (edges are taken against these).
        self.enabled = np.zeros(n, dtype=bool)
        self.clear = np.zeros(n, dtype=bool)
        self.x_prev = np.zeros(n)
        self.inf32 = self.inp.view(np.float32).reshape(n, _IN_U16 // 2)
        self.out32 = self.out.view(np.uint32).reshape(n, OUTPUT.itemsize // 4)
        self.outf32 = self.out.view(np.float32).reshape(n, OUTPUT.itemsize // 4)
        self._cmd_lsb = np.zeros(len(pdo.MODE_NAMES))
        for code in pdo.MODE_NAMES:
            self._cmd_lsb[code] = (pdo.POSITION_CMD_LSB if code == pdo.MODE_CODES["position"]
                                   else pdo.FORCE_CMD_LSB)
        self._gain_lsb = np.array([f.lsb for f in pdo.ACTUATOR_OUT[3:5]])
        fields = pdo.ACTUATOR_IN[:7]
        self._in_lsb = np.array([f.lsb for f in fields])
        self._in_bounds = np.array([(np.iinfo(f.dtype).min, np.iinfo(f.dtype).max)
                                    for f in fields], dtype=np.int64)
        self.tick = self.boxes[0].tick if self.boxes else 0
        self._images()
        self._no_rec = np.zeros((0, L.N_OUTPUTS))
        #: Copies of each MCU step's words (and board traces) for a frame log, and who
        #: writes them out (a :class:`hil.replay.robot_record.RobotRecorder` sets both); no
        #: rows and None: no log.
        self.log_rows = no_tap(n)
        #: The process images of each cycle for a frame log (an :class:`ImageRows`, filled
        #: by the compiled :func:`give_inputs`); no rows: none copied.
        self.log_images = no_images(n)
        self.log: EngineLog | None = None
        #: Both kernels fill :attr:`log_rows` (a logged run keeps the lanes).
        self.lanes_log_rows = True
        self.err = np.zeros((n, 2), dtype=np.int64)
        self._batched = np.ones(n, dtype=bool)
        self.ptrs = np.array([[self.states.ctypes.data + j * size,
                               self.inp.ctypes.data + j * INPUT.itemsize,
                               self.out.ctypes.data + j * OUTPUT.itemsize] for j in range(n)],
                             dtype=np.int64).reshape(n, 3)
        self.mcu = McuRows(self.ptrs, self.in16, self.in32, self.out16, self.err)
        for b in self.boxes:
            b.engine = self
        #: Start a cycle's compute in the helper threads as soon as every box has its
        #: outputs (:meth:`applied`), overlapping it with the master and the PC loop (with
        #: one worker there is no helper: the cycle is computed at :meth:`advance`).
        self.overlap = overlap
        self.cycle_ticks = cycle_ticks
        self._counter = np.zeros(1, dtype=np.int64)  # the next actuator nobody has claimed
        #: The helper threads (workers - 1) and this thread's compiled call (its entry
        #: point and its arguments after the first tick), made by :meth:`_calls`.
        self._threads: ct.ComputeThreads | None = None
        self._main_call: tuple[Callable, tuple] | None = None
        self._posted = False  # the helpers compute a cycle posted ahead (overlap)
        self._ready: list[int] | None = None  # prepared, with stacks under sensor faults
        #: Per box: its outputs of this cycle are in :attr:`out_image` (not yet taken).
        self._box_got = np.zeros(len(self.boxes), dtype=bool)
        self._box_number = {id(b): k for k, b in enumerate(self.boxes)}
        #: Made when the boxes' stacks change (faults wrap them): the stacks under a sensor
        #: fault, the wrapped ones, the plants the kernel advances (see _prepare).
        self._stacks_seen: tuple = ()
        self._external: list[int] = []
        self._wrapped: list = []
        self._batched_plants: list = []
        self._blocks = np.zeros((0, lanes_mod.LW), dtype=np.int64)
        self._sizes = np.zeros(0, dtype=np.int64)
        self._blocks_for: bytes = b""
        self._lane_bufs: list[tuple[np.ndarray, np.ndarray]] = []
        #: Each thread's lane buffers of the link's counters and the sensor chips.
        self._link_sensor_bufs: list[LinkSensorLanes] = []
        #: Called with the first tick of each cycle once it is computed (:meth:`tap`).
        self.on_cycle = None
        self.tap(False, False)

    # --- what the compiled calls take: changing one makes them again at the next cycle ----
    @property
    def workers(self) -> int | None:
        """Compute threads (None: one per core), the calling thread included."""
        return self._workers_given

    @workers.setter
    def workers(self, workers: int | None) -> None:
        if workers is not None and not 1 <= workers <= numba.config.NUMBA_NUM_THREADS:
            raise ConfigError(f"workers = {workers}: expected 1..{numba.config.NUMBA_NUM_THREADS}")
        self._workers_given = workers
        self._stale = True

    @property
    def lanes(self) -> bool:
        """The plants in vector lanes (:func:`advance_robot_lanes`); else one actuator at
        a time (:func:`advance_robot`)."""
        return self._lanes

    @lanes.setter
    def lanes(self, lanes: bool) -> None:
        self._lanes = lanes
        self._stale = True

    @property
    def log_rows(self) -> TapRows:
        """Copies of each MCU step's words (and board traces) for a frame log."""
        return self._log_rows

    @log_rows.setter
    def log_rows(self, rows: TapRows) -> None:
        self._log_rows = rows
        self._stale = True

    # --- set-up --------------------------------------------------------------------------
    def _images(self) -> None:
        """One byte image of every box's outputs and one of its inputs (each box's input
        buffer becomes its slice), and each actuator's record offset in them."""
        out_at, in_at, out_lo, in_lo = [], [], [0], [0]
        for b in self.boxes:
            out_at += [out_lo[-1] + b._out_off[b.act[i]] for i in range(len(b.stacks))]
            in_at += [in_lo[-1] + b._in_off[b.act[i]] for i in range(len(b.stacks))]
            out_lo.append(out_lo[-1] + b.out_dtype.itemsize)
            in_lo.append(in_lo[-1] + b.in_dtype.itemsize)
        self.out_image = np.zeros(out_lo[-1], dtype=np.uint8)
        self.in_image = np.zeros(in_lo[-1], dtype=np.uint8)
        self._out_span = list(zip(out_lo[:-1], out_lo[1:], strict=True))
        self._in_span = list(zip(in_lo[:-1], in_lo[1:], strict=True))
        for b, (lo, hi) in zip(self.boxes, self._in_span, strict=True):
            self.in_image[lo:hi] = np.frombuffer(bytes(b._in_buf), dtype=np.uint8)
            b._in_buf = self.in_image[lo:hi]
        self._out_at = np.array(out_at, dtype=np.int64)
        self._in_at = np.array(in_at, dtype=np.int64)
        self._got = np.zeros(self.n, dtype=bool)
        self._first = np.cumsum([0] + [len(b.stacks) for b in self.boxes])
        #: The box (engine's number) of each actuator.
        self._box_of = np.repeat(np.arange(len(self.boxes)), np.diff(self._first))

    def _bind_arrays(self) -> None:
        """Stack the stacks' arrays into :attr:`arrays` (a :class:`StackRows`) and rebind
        every stack to its row."""
        stacks = [self._inner(b.stacks[i]) for b, i in self.slots]

        def rows(owner: str, name: str) -> np.ndarray:
            parts = [getattr(s, owner) if owner else s for s in stacks]
            whole = np.ascontiguousarray(np.stack([getattr(o, name) for o in parts]))
            for j, o in enumerate(parts):
                setattr(o, name, whole[j])
            return whole

        self.arrays = StackRows(*(kind(*(rows(*at) for at in fields))
                                  for kind, fields in SOURCES))

    @staticmethod
    def _inner(stack: object) -> object:
        return getattr(stack, "stack", stack)  # a FaultyStack holds the FpgaStack

    def _refresh_inputs(self, which: np.ndarray) -> None:
        """Upstream words and CRC counts of the stacks ``which`` into the input records."""
        link = self.arrays.link
        self.inp["up"][which] = link.mcu_up[which] & 0xFFFF
        self.inp["up_crc_errors"][which] = link.state[which, LK.LK_MASTER_CRC]

    def tune(self, box: object, slot: int, key: str, value: float) -> None:
        """MCU tunable ``key`` (:mod:`firmware_model.mcu.tunables`) of actuator ``slot`` of
        ``box`` becomes ``value`` at its program's next step: put into the program state
        when the next cycle's outputs are taken, before its compute starts (never while a
        compiled call runs)."""
        n_box = next((k for k, b in enumerate(self.boxes) if b is box), None)
        if n_box is None:
            raise ValueError("the box is not one this engine advances")
        if not 0 <= slot < len(box.stacks):
            raise IndexError(f"slot {slot}: the box has {len(box.stacks)} actuators")
        self.tunables.tune(int(self._first[n_box]) + slot, key, value)

    # --- one fieldbus cycle ----------------------------------------------------------------
    def spans(self, box: object) -> tuple[int, tuple[int, int], tuple[int, int]] | None:
        """The engine's number of ``box`` and its records' spans [lo, hi) in
        :attr:`out_image` and :attr:`in_image` (its input buffer is that slice); None if
        the engine does not advance it."""
        n_box = self._box_number.get(id(box))
        if n_box is None or self.boxes[n_box] is not box:
            return None
        return n_box, self._out_span[n_box], self._in_span[n_box]

    def applied(self, box: object, data: bytes) -> None:
        """``box`` has taken this cycle's outputs ``data`` (its output record). Once every
        box has, the next cycle's compute starts in the background (``overlap``): it needs
        nothing that arrives later, since the chain applies a cycle's outputs before the
        frame of the next cycle triggers :meth:`advance`, which then only waits for it."""
        n_box = self._box_number[id(box)]
        lo, hi = self._out_span[n_box]
        self.applied_image(np.frombuffer(data, dtype=np.uint8),
                           np.arange(len(data)), np.arange(lo, hi), n_box)

    def applied_image(self, data: np.ndarray, at: np.ndarray, to: np.ndarray,
                      boxes: object) -> None:
        """:meth:`applied` for several boxes at once (their records in one frame's data):
        the bytes ``data[at]`` are the outputs of the boxes ``boxes`` (engine numbers: an
        int or an index array), at ``out_image[to]``."""
        if self._posted or self._ready is not None:
            # A duplicate of a frame already applied: the reference path would apply the
            # same bytes again, which changes nothing; anything else cannot be undone.
            if not np.array_equal(self.out_image[to], data[at]):
                raise RuntimeError("box outputs changed after the cycle's compute started")
            return
        self.out_image[to] = data[at]
        got = self._box_got
        got[boxes] = True
        if self.overlap and got.all():
            self._take_outputs()
            external = self._prepare()
            if external or self._workers() == 1:
                # Python per tick (sensor faults) or no helper thread: run it at advance
                self._ready = external
                return
            self._start(self.cycle_ticks)

    def advance(self, ticks: int) -> None:
        """``ticks`` ticks (whole MCU periods) of every actuator; then every box's inputs."""
        if ticks % self.period:
            raise ValueError(f"the robot engine advances whole MCU periods ({self.period} "
                             f"ticks), not {ticks}")
        posted, self._posted = self._posted, False
        ready, self._ready = self._ready, None
        if posted:
            threads = self._threads  # (made again if its arguments changed since: joined)
            try:  # this thread joins the helpers (nothing is left if wait() joined them)
                self._compute(self.cycle_ticks)
            finally:
                threads.join()
        elif ready is not None:
            self._run_cycle(self.cycle_ticks)
            if ready:
                self._advance_external(ready, self.cycle_ticks)
        if (posted or ready is not None) and ticks == self.cycle_ticks:
            self._finish(ticks)
            return
        if posted or ready is not None:
            self._finish(self.cycle_ticks)
        self._take_outputs()
        external = self._prepare()
        self._run_cycle(ticks)
        if external:
            self._advance_external(external, ticks)
        self._finish(ticks)

    @property
    def taken_ahead(self) -> bool:
        """The outputs of a cycle not yet advanced are taken (:attr:`out_image` and
        :attr:`_got` hold them; its compute was started or prepared ahead, :meth:`applied`):
        a frame log's last cycle's outputs, which no cycle's end copied."""
        return self._posted or self._ready is not None

    def wait(self) -> None:
        """Let a compute started ahead finish (its results are kept for the next
        :meth:`advance`)."""
        if self._threads is not None:
            self._threads.join()

    def close(self) -> None:
        """Let a compute started ahead finish and end the helper threads (they end too
        when the engine is garbage collected; a later cycle starts them again)."""
        if self._threads is not None:
            self._threads.close()
            self._threads = None
        self._stale = True

    def _prepare(self) -> list[int]:
        """Which stacks the kernel advances (not those under a sensor fault, returned) and
        the LVDS faults of this cycle switched."""
        stacks = tuple(itertools.chain.from_iterable(b.stacks for b in self.boxes))
        if stacks != self._stacks_seen:  # faults wrapped some (by identity, per cycle)
            wrapped = [(j, s) for j, s in enumerate(stacks) if hasattr(s, "sensors")]
            self._external = [j for j, s in wrapped if s.sensors]
            self._wrapped = [s for _, s in wrapped if not s.sensors]
            batched = self._batched
            batched[:] = True
            batched[self._external] = False
            self._batched_plants = [self._inner(s).plant for j, s in enumerate(stacks)
                                    if batched[j]]
            self._stacks_seen = stacks
        for s in self._wrapped:  # LVDS faults switch at cycle boundaries (FaultyStack)
            s._switch_lvds(self.tick // self.cycle_ticks)
        if self.lanes and self._batched.tobytes() != self._blocks_for:
            self._make_blocks()
        return list(self._external)

    def _make_blocks(self) -> None:
        """The batches of :func:`advance_robot_lanes`: the batched actuators in chain
        order, cut into as few batches of at most ``LW`` as they need, of equal sizes (so
        that the threads claiming them get equal shares)."""
        rows = np.flatnonzero(self._batched)
        n_blocks = -(-len(rows) // lanes_mod.LW)
        self._blocks = np.zeros((n_blocks, lanes_mod.LW), dtype=np.int64)
        self._sizes = np.zeros(n_blocks, dtype=np.int64)
        for b, part in enumerate(np.array_split(rows, n_blocks) if n_blocks else []):
            self._blocks[b, :len(part)] = part
            self._sizes[b] = len(part)
        self._n_sub_max = int(self.arrays.plant.params[:, L.P_N_SUB].max())
        self._blocks_for = self._batched.tobytes()
        self._stale = True

    def _workers(self) -> int:
        return self.workers or numba.config.NUMBA_NUM_THREADS

    def _start(self, ticks: int) -> None:
        """Open the cycle's actuators for claiming and post the cycle to the helper
        threads (at least one); :meth:`advance` joins them."""
        self._calls(ticks)
        self._counter[0] = 0
        self._threads.post(ticks // self.period, self.tick)
        self._posted = True

    def _run_cycle(self, ticks: int) -> None:
        """A cycle's compute now: this thread and ``workers - 1`` helpers."""
        threads = self._calls(ticks)
        self._counter[0] = 0
        if threads is None:
            self._compute(ticks)
            return
        threads.post(ticks // self.period, self.tick)
        try:
            self._compute(ticks)
        finally:
            threads.join()

    def _compute(self, ticks: int) -> int:
        """This thread's share of a cycle: claim and advance actuators until none is left
        (nothing here but the compiled call, which releases the GIL)."""
        call, rest = self._main_call if not self._stale else self._main_call_for(ticks)
        return call(self._counter, ticks // self.period, self.period, self.tick, *rest)

    def _calls(self, ticks: int) -> ct.ComputeThreads | None:
        """The helper threads for this cycle's compiled calls (None: no helper), made
        again after anything they take changed (workers, lanes, batches, taps, log rows):
        each thread keeps its arguments, and its own lane buffers, from call to call."""
        if ticks > self.cycle_ticks:
            self._taps(ticks)  # (the taps hold one cycle: this refuses more)
        if not self._stale:
            return self._threads
        if self._threads is not None:
            self._threads.close()
            self._threads = None
        helpers = self._workers() - 1
        args = [self._kernel_args(slot) for slot in range(helpers + 1)]
        kernel = advance_robot_lanes if self.lanes else advance_robot
        self._main_call = (_entry(kernel, (self._counter, 1, self.period, self.tick,
                                           *args[0])), args[0])
        if helpers:
            serve = _serve_lanes if self.lanes else _serve_actuators
            self._threads = ct.ComputeThreads(
                serve, [(self._counter, self.period, *a) for a in args[1:]],
                name="robot-engine")
        self._stale = False
        return self._threads

    def _main_call_for(self, ticks: int) -> tuple[Callable, tuple]:
        self._calls(ticks)
        return self._main_call

    def _kernel_args(self, slot: int) -> tuple:
        """The compiled call's arguments after its first tick, for thread ``slot`` (0: the
        calling thread): the engine's arrays and that thread's lane buffers."""
        if not self.lanes:
            return (self._batched, self.arrays, self.mcu, self._no_rec, self.log_rows)
        while len(self._lane_bufs) <= slot:
            self._lane_bufs.append((lanes_mod.lane_buffer(), fpl.board_buffer()))
            self._link_sensor_bufs.append(LinkSensorLanes(
                link_lanes.link_lane_buffer(), sensor_lanes.sensor_lane_buffer(),
                self.law.lane_buffer()))
        buf, fb = self._lane_bufs[slot]
        return (self._blocks, self._sizes, self._n_sub_max, self.arrays, self.mcu, buf, fb,
                self._link_sensor_bufs[slot], self.tap_y, self.tap_trace, self.log_rows)

    def tap(self, plant: bool = True, trace: bool = False) -> None:
        """Keep every tick of the next cycles (lanes only): :attr:`tap_y` (actuators,
        cycle ticks, plant outputs) and :attr:`tap_trace` (actuators, cycle ticks,
        ``TRACE_WIDTH``: the board's inputs and outputs, as :func:`advance_stack` traces
        them), chain order, overwritten each cycle: read them after :meth:`advance`
        returns (or from :attr:`on_cycle`, called there with the cycle's first tick).
        ``tap(False, False)`` stops. A stack under a sensor fault (advanced by its own
        wrapper) leaves its rows as they were."""
        ticks = self.cycle_ticks
        self.tap_y = np.zeros((self.n if plant else 0, ticks, L.N_OUTPUTS))
        self.tap_trace = np.zeros((self.n if trace else 0, ticks, TRACE_WIDTH), dtype=np.int64)
        self._stale = True

    def _taps(self, ticks: int) -> tuple[np.ndarray, np.ndarray]:
        if (self.tap_y.shape[0] and ticks > self.tap_y.shape[1]) or (
                self.tap_trace.shape[0] and ticks > self.tap_trace.shape[1]):
            raise ValueError(f"the tap holds {self.cycle_ticks} ticks, not {ticks}")
        return self.tap_y, self.tap_trace

    def _finish(self, ticks: int) -> None:
        for plant in self._batched_plants:
            plant.tick += ticks
        if self.on_cycle is not None:
            self.on_cycle(self.tick)
        self.tick += ticks
        for b in self.all_boxes:
            b.tick = self.tick
        self._give_inputs(ticks)
        if self.log is not None:
            self.log.finished(self.tick, ticks // self.period)

    def _advance_external(self, external: list[int], ticks: int) -> None:
        """The stacks under a sensor fault: their own wrapper advances them tick by tick,
        between the same steps of their programs as :func:`advance_robot` makes."""
        size = self.law.state_size
        tap, p = self.log_rows, self.period
        for n, t in enumerate(range(self.tick, self.tick + ticks, p)):
            r = int(tap.row[0]) + n
            for j in external:
                b, i = self.slots[j]
                self.inp["tick"][j] = t
                self.law.step_many(self.states[j * size:(j + 1) * size], self.inp[j:j + 1],
                                   self.out[j:j + 1])
                self.inp["flags"][j] = 0
                if t + p >= self.tick + ticks:
                    self.err[j] = (self.in16[j, _IN_UP + B.U_ERR_LINK_CRC],
                                   self.in32[j, _IN_CRC])
                self.arrays.link.mcu_down[j] = self.out["down"][j]
                if tap.up.shape[1]:  # as advance_robot copies them
                    tap.up[j, r, :B.UP_WORDS] = self.in16[j, _IN_UP:_IN_UP + B.UP_WORDS]
                    crc = int(self.in32[j, _IN_CRC])
                    tap.up[j, r, B.UP_WORDS:] = (crc & 0xFFFF, crc >> 16)
                    tap.down[j, r] = self.out16[j, _OUT_DOWN:_OUT_DOWN + tap.down.shape[2]]
                if tap.trace.shape[1]:
                    b.stacks[i].advance(p, trace=tap.trace[j, r * p:(r + 1) * p])
                else:
                    b.stacks[i].advance(p)
            which = np.zeros(self.n, dtype=bool)
            which[external] = True
            self._refresh_inputs(which)

    def _take_outputs(self) -> None:
        """The process data the boxes received since the last cycle, as program inputs."""
        self.tunables.apply()  # (no compute runs now: see applied and advance)
        got = self._got
        np.take(self._box_got, self._box_of, out=got)  # (out_image holds them already)
        self._box_got[:] = False
        args = (self.out_image, self._out_at, got, self.enabled, self.clear, self.in32,
                self.inf32, self._cmd_lsb, self._gain_lsb)
        if self._take is None:
            self._take = _entry(take_outputs, args)
        self._take(*args)

    def _give_inputs(self, ticks: int) -> None:
        """Every box's input record from the programs' last outputs (as McuBoard.report)."""
        args = (self.in_image, self._in_at, self.out32, self.outf32, self.x_prev,
                ticks * self.tick_s, self.cos_alpha, self.err, self._in_lsb, self._in_bounds,
                self.out_image, self._got, self.tick, ticks, ticks // self.period,
                self.log_images, self._log_rows.row)
        if self._give is None:
            self._give = _entry(give_inputs, args)
        self._give(*args)


class EngineLog(Protocol):
    """Who writes a frame log of the engine's run (:mod:`hil.replay.robot_record`): told
    when a cycle has ended (``periods`` MCU steps after its outputs were taken, at
    ``tick``; :func:`give_inputs` has given the ``in_image`` and, with
    :attr:`RobotEngine.log_images`, copied the cycle's images and moved ``tap.row`` on),
    it writes the rows out before they run out. Outputs taken for a cycle that has not
    ended (the run's last) are :attr:`RobotEngine.taken_ahead`. (Nothing is called when
    outputs are taken: a call per cycle less.)"""

    def finished(self, tick: int, periods: int) -> None: ...


def no_images(n: int) -> ImageRows:
    """An :class:`ImageRows` with no rows: :func:`give_inputs` copies nothing out."""
    return ImageRows(np.zeros((0, 0), np.uint8), np.zeros((0, n), bool),
                     np.zeros((0, 0), np.uint8), np.zeros(0, np.int64), np.zeros(0, np.int64),
                     np.zeros(1, np.int64))


def no_tap(n: int) -> TapRows:
    """A :class:`TapRows` with no rows: the kernel copies nothing out."""
    return TapRows(np.zeros((n, 0, B.UP_WORDS + 2), np.uint16),
                   np.zeros((n, 0, B.DOWN_WORDS), np.uint16),
                   np.zeros((n, 0, TRACE_WIDTH), np.int64), np.zeros(1, np.int64))


def plant_records(engine: RobotEngine) -> np.ndarray:
    """The plant outputs of every actuator now, (actuators, outputs), chain order."""
    return engine.arrays.plant.y.copy()


__all__ = ["RobotEngine", "advance_robot", "plant_records", "L"]
