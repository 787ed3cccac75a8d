"""The driver board's tick in vector lanes (firmware_model.fpga.lanes) against the scalar
tick (firmware_model.fpga.tick.control_tick): bit for bit per board, over random states,
inputs and parameters, with boards that differ in one batch (modes, states, latched
faults, sensor errors, another calibration's parameters, a speed ring just reset)."""

from __future__ import annotations

import functools
import re

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import cfunc, njit, types

from firmware_model.fpga import foc, rtl_abi
from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.fpga.current_loop import O_COUNT_A
from firmware_model.fpga.driver_board import DriverBoard
from firmware_model.fpga.fixed import isqrt
from firmware_model.fpga.tick import control_tick
from plant.config import load_config

#: Two calibrations (the default actuator's; one built for another clock, current range,
#: watchdog and speed window, as another box's boards may be), and random parameters.
_BASE = [DriverBoard(load_config(None, [])).params,
         DriverBoard(load_config(None, ["fpga.clock_hz=40000000", "fpga.current_full_scale_a=30",
                                        "fpga.watchdog_s=0.001",
                                        "fpga.speed_window_ticks=8"])).params]
_U16 = st.integers(0, 0xFFFF)
_S32 = st.integers(-(1 << 31), (1 << 31) - 1)


@st.composite
def board(draw):
    """(params, state, down) of one board."""
    c = _BASE[draw(st.integers(0, 1))].copy()
    if draw(st.booleans()):  # parameters anywhere in their working ranges
        c[B.C_POLE_PAIRS] = draw(st.integers(1, 8))
        c[B.C_SSI_SHIFT] = draw(st.integers(0, 6))
        c[B.C_ADC_SHIFT] = draw(st.integers(0, 4))
        c[B.C_PWM_TOP] = draw(st.integers(2, 5000))
        c[B.C_V_LIMIT] = draw(st.integers(0, 32767))
        c[B.C_KP_SHIFT] = draw(st.integers(1, 16))
        c[B.C_KI_SHIFT] = draw(st.integers(1, 20))
        for k in (B.C_MA_TO_I, B.C_I_TO_MA, B.C_MV_TO_V, B.C_V_TO_MV):
            c[k] = draw(st.integers(0, 1 << 17))
        c[B.C_WD_TICKS] = draw(st.integers(1, 2000))
        c[B.C_SPEED_WINDOW] = 1 << draw(st.integers(0, 8))
    s = np.zeros(B.N_STATE, dtype=np.int64)
    s[B.F_STATE] = draw(st.sampled_from([0, 1, 2, 1, 1, 3]))
    s[B.F_LATCHED] = draw(st.sampled_from([0, 0, B.ST_OVER_CURRENT, B.ST_LINK_LOST,
                                           B.ST_OVER_CURRENT | B.ST_LINK_LOST]))
    s[B.F_STATUS_EXTRA] = draw(st.integers(0, 255))
    s[B.F_INTEG_D] = draw(_S32)
    s[B.F_INTEG_Q] = draw(_S32)
    for k in (B.F_DUTY_A, B.F_DUTY_B, B.F_DUTY_C, B.F_ID, B.F_IQ, B.F_VD, B.F_VQ):
        s[k] = draw(st.integers(-40000, 40000))
    s[B.F_PWM_ON] = draw(st.integers(0, 1))
    s[B.F_SINCE_VALID] = draw(st.sampled_from([0, 1, (1 << 30) - 1, 1 << 30])
                              | st.integers(0, 3000))
    s[B.F_PREV_CONTROL] = draw(st.integers(0, 3))
    s[B.F_TICK] = draw(st.sampled_from([0, 1]) | st.integers(0, 1 << 40))
    window = int(c[B.C_SPEED_WINDOW])
    s[B.F_RING_POS] = draw(st.integers(0, window - 1))
    s[B.F_STRAIN_SAMPLES] = draw(st.integers(0, 255))
    for k in (B.F_ERR_SSI, B.F_ERR_BISS, B.F_ERR_STRAIN, B.F_ERR_LINK_CRC, B.F_OC_TRIPS,
              B.F_WD_TRIPS):
        s[k] = draw(st.sampled_from([0, 0xFFFE, 0xFFFF]) | _U16)
    s[B.F_THETA_E] = draw(_U16)
    ring = np.random.default_rng(draw(st.integers(0, 1 << 32)))
    s[B.RING_BASE:B.RING_BASE + window] = ring.integers(0, 1 << 16, window)
    d = np.zeros(B.DOWN_WORDS, dtype=np.int64)
    d[B.D_TRIP_CURRENT] = draw(_U16)
    d[B.D_CURRENT_LIMIT] = draw(_U16)
    d[B.D_ANGLE_OFFSET] = draw(_U16)
    d[B.D_KP] = draw(_U16)
    d[B.D_KI] = draw(_U16)
    return c, s, d


def tick_inputs(g: np.random.Generator):
    """What the sensor chips and the link give one board for one tick (``g``: a generator
    hypothesis seeded): raw words, downstream writes, and the link's watchdog and CRC
    counts (None: as they were)."""
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    raw[B.R_SSI] = g.integers(0, 2048)
    raw[B.R_SSI_OK] = g.random() < 0.8
    raw[B.R_ABI] = g.integers(0, 0x20000)
    raw[B.R_BISS] = g.integers(0, 1 << 32)
    raw[B.R_BISS_OK] = g.random() < 0.8
    raw[B.R_STRAIN] = g.integers(0, 1 << 24)
    raw[B.R_STRAIN_NEW] = g.random() < 0.5
    raw[B.R_STRAIN_OK] = g.random() < 0.7
    for k in [*B.ANALOG_RAW, B.R_IA, B.R_IB]:
        raw[k] = g.integers(0, 4096)
    raw[B.R_HALL] = g.integers(0, 8)
    down = {k: int(g.integers(0, 1 << 16)) for k in (
        B.D_IQ_REF, B.D_ID_REF, B.D_VQ_FF, B.D_VD_REF, B.D_VQ_REF, B.D_SEQUENCE)
        if g.random() < 0.5}
    if g.random() < 0.6:
        down[B.D_CONTROL] = int(g.choice([1, 1, 0, 2, 3]))
    if g.random() < 0.3:
        down[B.D_MODE] = int(g.choice([1, 1, 2, 0, 3]))
    since = 0 if g.random() < 0.3 else None
    crc = int(g.integers(0, 1 << 16)) if g.random() < 0.2 else None
    return raw, down, since, crc


def _apply(d, s, inputs):
    """The link's part of a tick (what its downstream sweep writes) on a board's rows."""
    _, down, since, crc = inputs
    for k, v in down.items():
        d[k] = v
    if since is not None:
        s[B.F_SINCE_VALID] = since
    if crc is not None:
        s[B.F_ERR_LINK_CRC] = crc


def _put(fb, j, inputs):
    """The same tick's inputs where the batch's stages write them, into lane ``j`` of the
    board lanes: the sensor chips' raw words, the link's downstream words and counts."""
    raw, down, since, crc = inputs
    for k, v in enumerate(raw):
        fb[fpl.RO + k * fpl.LW + j] = v
    for k, v in down.items():
        fb[fpl.DO + k * fpl.LW + j] = v
    if since is not None:
        fb[fpl.SO + B.F_SINCE_VALID * fpl.LW + j] = since
    if crc is not None:
        fb[fpl.SO + B.F_ERR_LINK_CRC * fpl.LW + j] = crc


@settings(max_examples=60, deadline=None)
@given(boards=st.lists(board(), min_size=1, max_size=fpl.LW), seed=st.integers(0, 1 << 32),
       ticks=st.integers(1, 8))
def test_board_in_lanes_is_the_scalar_tick_bit_for_bit(boards, seed, ticks):
    """Up to LW different boards in one batch, ``ticks`` ticks with random inputs written
    into the lanes: each board's upstream memory, PWM-on flag, compare counts and the link
    counts a trace reads after every tick, and its state (the ring too) and exchange words
    stored back after the batch, are the scalar tick's."""
    m = len(boards)
    C = np.array([b[0] for b in boards])
    S = np.array([b[1] for b in boards])
    D = np.array([b[2] for b in boards])
    U = np.zeros((m, B.UP_WORDS), dtype=np.int64)
    raw = np.zeros((m, B.N_RAW), dtype=np.int64)
    rs, rd, ru, rraw = S.copy(), D.copy(), U.copy(), raw.copy()
    fb = fpl.board_buffer()
    rows = np.arange(m)
    fpl.load_board(fb, C, S, raw, D, rows, m)
    g = np.random.default_rng(seed)
    for _ in range(ticks):
        inputs = [tick_inputs(g) for _ in range(m)]
        want = []
        for j in range(m):
            rraw[j] = inputs[j][0]
            _apply(rd[j], rs[j], inputs[j])
            _put(fb, j, inputs[j])
            since, crc = rs[j, B.F_SINCE_VALID], rs[j, B.F_ERR_LINK_CRC]
            on = control_tick(C[j], rs[j], rd[j], ru[j], rraw[j])
            want.append((on, *rs[j, B.F_DUTY_A:B.F_DUTY_C + 1], since, crc))
        fpl.board_tick(fb, rows, m, raw, D, S, U, C)
        got = [(fpl.lane(fb, fpl.SO, B.F_PWM_ON, j),
                *(fpl.lane(fb, fpl.SO, f, j) for f in (B.F_DUTY_A, B.F_DUTY_B, B.F_DUTY_C)),
                fpl.lane(fb, fpl.XO, fpl.X_SINCE, j), fpl.lane(fb, fpl.XO, fpl.X_CRC, j))
               for j in range(m)]
        assert got == want
        np.testing.assert_array_equal(U, ru)
    fpl.store_board(fb, S, raw, D, rows, m)
    np.testing.assert_array_equal(S, rs)
    np.testing.assert_array_equal(D, rd)
    np.testing.assert_array_equal(raw, rraw)


@functools.cache
def _rtl_stand_in() -> int:
    """The address of a compiled call that leaves the exchange buffer's outputs as they are
    (compiled on first use, not at import: numba cannot cache a ``cfunc``, and every test
    worker collects this file)."""

    @cfunc(types.void(types.voidptr))
    def stand_in(handle):  # noqa: ARG001 - the outputs stay what the buffer holds
        pass

    _KEEP.append(stand_in)
    return stand_in.address


_KEEP: list[object] = []  # (the compiled stand-in lives as long as the tests)


def _rtl_rows():
    """Two boards enabled in current mode, the second on a stand-in for a compiled RTL
    loop (a call that leaves the exchange buffer's outputs as set here)."""
    c = np.array([_BASE[0], _BASE[0]])
    io = np.zeros(rtl_abi.IO_WORDS, dtype=np.int64)
    io[rtl_abi.IO_OUT + O_COUNT_A:rtl_abi.IO_OUT + O_COUNT_A + 3] = (100, 600, 1100)
    c[1, B.C_RTL_TICK] = _rtl_stand_in()
    c[1, B.C_RTL_IO] = io.ctypes.data
    s = np.zeros((2, B.N_STATE), dtype=np.int64)
    s[:, B.F_TICK] = 5
    d = np.zeros((2, B.DOWN_WORDS), dtype=np.int64)
    d[:, B.D_CONTROL] = B.CTRL_ENABLE
    d[:, B.D_MODE] = B.BoardMode.CURRENT
    d[:, B.D_TRIP_CURRENT] = 30000
    d[:, B.D_IQ_REF] = 5000
    raw = np.zeros((2, B.N_RAW), dtype=np.int64)
    raw[:, (B.R_SSI_OK, B.R_BISS_OK)] = 1
    raw[:, (B.R_IA, B.R_IB)] = 2048
    return c, s, d, raw, io


def test_a_batch_with_an_rtl_loop_runs_the_scalar_tick_on_its_rows():
    """A board whose current loop is a compiled RTL cannot be a lane: its batch runs
    ``control_tick`` row by row, with the same results as the board alone, and the lanes
    carry its compare counts (the RTL's) to the trace and the inverter."""
    c, s, d, raw, io = _rtl_rows()
    c2, s2, d2, raw2, io2 = _rtl_rows()
    u = np.zeros((2, B.UP_WORDS), dtype=np.int64)
    u2 = u.copy()
    fb = fpl.board_buffer()
    fpl.load_board(fb, c, s, raw, d, np.arange(2), 2)
    assert fb[fpl.HO + fpl.H_SCALAR] == 1
    for _ in range(3):
        fpl.board_tick(fb, np.arange(2), 2, raw, d, s, u, c)
        for j in range(2):
            control_tick(c2[j], s2[j], d2[j], u2[j], raw2[j])
    fpl.store_board(fb, s, raw, d, np.arange(2), 2)
    np.testing.assert_array_equal(s, s2)
    np.testing.assert_array_equal(u, u2)
    assert s[1, B.F_PWM_ON] == 1 and s[1, B.F_DUTY_A:B.F_DUTY_C + 1].tolist() == [100, 600, 1100]
    assert [fpl.lane(fb, fpl.SO, f, 1) for f in (B.F_DUTY_A, B.F_DUTY_B, B.F_DUTY_C)] == [
        100, 600, 1100]


@njit(cache=True)
def _sin_cos_loop(theta, out):
    for i in range(theta.shape[0]):
        out[0, i], out[1, i] = fpl.sin_cos_lanes(theta[i])


def test_the_branch_free_sine_is_the_tables_for_every_angle():
    theta = np.arange(1 << 16, dtype=np.int64)
    out = np.empty((2, theta.size), dtype=np.int64)
    _sin_cos_loop(theta, out)
    want = np.array([foc.sin_cos(int(t)) for t in theta[::7]]).T
    np.testing.assert_array_equal(out[:, ::7], want)


@njit(cache=True)
def _isqrt16(n):
    return fpl.isqrt16(n)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(-(1 << 40), 1 << 40) | st.integers(0, 1 << 32)
       | st.sampled_from([0, 1, 2, 3, 4, (1 << 32) - 1, 1 << 30, (1 << 30) - 1]))
def test_the_fixed_16_step_root_is_the_hardware_root(n):
    assert _isqrt16(n) == isqrt(n)


@pytest.mark.slow
def test_the_board_tick_in_lanes_compiles_to_vector_instructions():
    """The generated machine code of the lane loop: its integer arithmetic is on full
    vector registers (ymm with AVX2, zmm with AVX-512) and it calls nothing (every helper
    inlined, no branch left that would stop the vectoriser: then the count drops to the
    handful of scalar moves)."""
    import llvmlite.binding as llvm

    if "+avx2" not in llvm.get_host_cpu_features().flatten():
        pytest.skip("no AVX2 on this CPU: nothing to check the lanes against")
    opts = {k: v for k, v in fpl.LANES.items() if k != "cache"}
    f = numba.njit(**opts)(fpl.tick_lanes.py_func)
    f(fpl.board_buffer())
    asm = next(iter(f.inspect_asm().values()))
    body = asm[:asm.index(".Lfunc_end0")]
    assert len(re.findall(r"\bvp\w+\s[^\n]*%[yz]mm", body)) > 200
    assert "call" not in body
