"""The driver board's tick over many boards at once, one board per vector lane.

:func:`firmware_model.fpga.tick.control_tick` runs one board; here the same integer
arithmetic runs over a batch of up to :data:`LW` boards whose parameters and state live in
one flat int64 buffer, transposed (structure of arrays: state ``F_TICK`` of lane ``i`` at
``SO + F_TICK * LW + i``), so that each statement is one vector instruction over the lanes.
Per board it is the operations of ``control_tick`` (:mod:`~firmware_model.fpga.fixed`'s
wraps, saturations and rounding shifts, :mod:`~firmware_model.fpga.foc`'s transforms, the
protections and the enable state machine) in int64, so the results are the scalar tick's,
bit for bit (``tests/fpga/test_lanes.py``). Boards may differ in everything: mode, state,
latched faults, parameters (a hip box's calibration), sensor errors.

How it is made to vectorise (the recipe of :mod:`plant.lanes`):

* **one flat buffer at offsets known at compile time**: the compiler sees that the rows
  written never overlap the rows read, so it needs no run-time overlap check;
* **unsigned indices** (:func:`_ix`): no wrap-around select of negative indices per access;
* **branches become selects**: both sides of every ``if`` are computed on every lane and
  one is kept; the square root of the voltage circle (:func:`~firmware_model.fpga.fixed.
  isqrt`, whose first loop has a data-dependent trip count) is its fixed 16 steps
  (:func:`isqrt16`, the same result for every input); the sine table's quadrant is a
  select of the index and of the sign (:func:`sin_cos_lanes`, one table read per value);
* **all LW lanes every time**: a free lane holds a copy of the batch's last board
  (computed, never stored back).

The tick's exchange with the stages around the board lives in the lanes too, from
:func:`load_board` to :func:`store_board` (one kernel call): the raw sensor words (``RO``,
written by :func:`plant.sensors.lanes.digitise_lanes`), the downstream memory (``DO``,
written by the link's downstream sweep, :func:`firmware_model.lvds.lanes.sweep_down_lanes`)
and the LVDS receive endpoint's two state words ``F_SINCE_VALID`` and ``F_ERR_LINK_CRC``
(``SO``, the sweep restarts the watchdog there). A stage that falls back to its scalar code
for one actuator moves that lane's exchange words to the rows and back
(:func:`exchange_out`, :func:`exchange_in`).

What does not vectorise (one board after the other, in :func:`board_tick`'s loops): the
ABI speed ring (each board reads and writes its own ring at its own position: a gather and
scatter the compiler will not emit; the ring stays in each board's state row) and the
upstream memory (``up``): it stays in each board's row, where the link's upstream sweep
copies all 32 words into its delay ring every tick as one contiguous move; from lanes that
copy would be 32 strided moves per board, as many as the scatter of the words the tick
writes.

A batch with a board whose current loop is a compiled RTL (``C_RTL_TICK``: a call into a
library per tick) runs the scalar ``control_tick`` on the boards' rows, board by board; the
lanes then only carry what the tick gave (PWM on, compare counts) to the trace and the
inverter.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.fpga import foc
from firmware_model.fpga import layout as B
from firmware_model.fpga.fixed import clamp, mul_shift, sat_s, wrap_s, wrap_u
from firmware_model.fpga.tick import control_tick

#: Compile options of the lane loops: cached, no runtime, no checks.
LANES = {"cache": True, "_nrt": False, "error_model": "numpy", "nogil": True}

#: Boards per batch (the plant's lane width, :data:`plant.lanes.LW`: one batch of actuators).
LW = 8
#: The named state words (the ABI ring after them stays in each board's row).
N_NAMED = B.RING_BASE
PO = 0                              #: parameters (N_PARAMS rows)
SO = PO + B.N_PARAMS * LW           #: named state (N_NAMED rows)
RO = SO + N_NAMED * LW              #: the tick's raw sensor words (N_RAW rows)
DO = RO + B.N_RAW * LW              #: the tick's downstream memory (DOWN_WORDS rows)
UO = DO + B.DOWN_WORDS * LW         #: upstream words the tick computes (UP_WORDS rows)
XO = UO + B.UP_WORDS * LW           #: per-tick extras (N_EXTRA rows, X_*)
X_SINCE, X_CRC, X_STRAIN = range(3)  # link watchdog and CRC counts as the tick found them;
N_EXTRA = 3                          # 1: the strain words are written this tick
HO = XO + N_EXTRA * LW              #: batch header: H_SCALAR
H_SCALAR = 0                        # 1: a board of the batch runs a compiled RTL loop
SIZE = HO + LW

#: Upstream registers written every tick from the lanes: (register, lane row offset).
_UP_OUT = np.array(
    [(u, UO + u * LW) for u in (B.U_STATUS, B.U_STATE, B.U_THETA_E, B.U_IQ, B.U_ID, B.U_IA,
                                B.U_IB, B.U_VD_OUT, B.U_VQ_OUT, B.U_TICK)]
    + [(u, SO + f * LW) for u, f in ((B.U_ERR_SSI, B.F_ERR_SSI), (B.U_ERR_BISS, B.F_ERR_BISS),
                                     (B.U_ERR_STRAIN, B.F_ERR_STRAIN),
                                     (B.U_OC_TRIPS, B.F_OC_TRIPS),
                                     (B.U_WD_TRIPS, B.F_WD_TRIPS))],
    dtype=np.int64)

# The scalar helpers with no loop and no array, inlined into the lane loop as they are.
_clarke = njit(inline="always")(foc.clarke.py_func)
_park = njit(inline="always")(foc.park.py_func)
_inv_park = njit(inline="always")(foc.inv_park.py_func)
_svpwm = njit(inline="always")(foc.svpwm.py_func)
_pi_step = njit(inline="always")(foc.pi_step.py_func)


@njit(cache=True, inline="always")
def _ix(at, k, i):
    """Where row ``k`` of lane ``i`` of the block at ``at`` is, as an unsigned index."""
    return np.uint64(at + k * LW + i)


@njit(cache=True, inline="always")
def lane(fb, at, k, i):
    """Row ``k`` of lane ``i`` of the block at ``at`` (e.g. ``lane(fb, SO, F_DUTY_A, i)``)."""
    return fb[_ix(at, k, i)]


@njit(cache=True, inline="always")
def _p(fb, k, i):
    return fb[_ix(PO, k, i)]


@njit(cache=True, inline="always")
def _s(fb, k, i):
    return fb[_ix(SO, k, i)]


@njit(cache=True, inline="always")
def _raw(fb, k, i):
    return fb[_ix(RO, k, i)]


@njit(cache=True, inline="always")
def _down(fb, k, i):
    return fb[_ix(DO, k, i)]


@njit(cache=True, inline="always")
def isqrt16(n):
    """:func:`firmware_model.fpga.fixed.isqrt` as its 16 steps from the top bit, always:
    while the bit is above ``n`` the root stays 0, which is what the scalar's first loop
    skips, so the result is the same for every ``n`` (0 for ``n <= 0``)."""
    root = 0
    bit = 1 << 30
    for _ in range(16):
        take = n >= root + bit
        n = n - (root + bit) if take else n
        root = (root >> 1) + bit if take else root >> 1
        bit >>= 2
    return root


@njit(cache=True, inline="always")
def _sine_q15(k):
    """:func:`firmware_model.fpga.foc._quarter_sine`: one read of the quarter-wave table,
    the quadrant a select of the index and of the sign."""
    k &= foc.SINE_STEPS - 1
    quadrant = k >> 8
    r = k & 255
    v = foc.SINE_TABLE[np.uint64(256 - r if (quadrant & 1) != 0 else r)]
    return -v if quadrant >= 2 else v


@njit(cache=True, inline="always")
def sin_cos_lanes(theta_e):
    """:func:`firmware_model.fpga.foc.sin_cos` without branches."""
    k = (theta_e + (1 << (foc.SINE_SHIFT - 1))) >> foc.SINE_SHIFT
    return _sine_q15(k), _sine_q15(k + foc.SINE_STEPS // 4)


@njit(cache=True, inline="always")
def _count(v):
    """:func:`~firmware_model.fpga.protections.count` (``sat_u(v + 1, 16)``) as a min and a
    max: the same value for every int64, and no branch (whose merge made LLVM store the
    counters with scatters)."""
    return max(0, min(v + 1, 0xFFFF))


@njit(**LANES)
def tick_lanes(fb):
    """:func:`control_tick` for every lane of the board buffer ``fb``, once the gather
    (:func:`board_tick`) has put the tick's inputs there and the ABI words (speed, ring)
    are done: the named state is updated in the lanes, the computed upstream words go to
    the rows at :data:`UO`, the strain words (written only with a new good sample) to
    ``UO`` and the flag ``X_STRAIN``."""
    for i in range(LW):
        tick = _s(fb, B.F_TICK, i)
        # motor angle: SSI absolute angle, pole pairs and the calibrated offset
        ssi_ok = _raw(fb, B.R_SSI_OK, i) != 0
        counts = _raw(fb, B.R_SSI, i) * _p(fb, B.C_POLE_PAIRS, i)
        theta_new = wrap_u((counts << _p(fb, B.C_SSI_SHIFT, i))
                           + _down(fb, B.D_ANGLE_OFFSET, i), 16)
        theta_e = theta_new if ssi_ok else _s(fb, B.F_THETA_E, i)
        err_ssi = _s(fb, B.F_ERR_SSI, i)
        err_ssi = err_ssi if ssi_ok else _count(err_ssi)
        extra = 0 if ssi_ok else B.ST_ENCODER_ERROR
        biss_ok = _raw(fb, B.R_BISS_OK, i) != 0
        err_biss = _s(fb, B.F_ERR_BISS, i)
        err_biss = err_biss if biss_ok else _count(err_biss)
        extra = extra if biss_ok else extra | B.ST_ENCODER_ERROR

        # phase currents
        i_a = (_raw(fb, B.R_IA, i) - _p(fb, B.C_ADC_MID, i)) << _p(fb, B.C_ADC_SHIFT, i)
        i_b = (_raw(fb, B.R_IB, i) - _p(fb, B.C_ADC_MID, i)) << _p(fb, B.C_ADC_SHIFT, i)
        i_c = -i_a - i_b
        i_alpha, i_beta = _clarke(i_a, i_b)
        sn, co = sin_cos_lanes(theta_e)
        i_d, i_q = _park(i_alpha, i_beta, sn, co)

        # protections (firmware_model.fpga.protections)
        ma_to_i = _p(fb, B.C_MA_TO_I, i)
        mv_to_v = _p(fb, B.C_MV_TO_V, i)
        state = _s(fb, B.F_STATE, i)
        latched = _s(fb, B.F_LATCHED, i)
        trip = mul_shift(_down(fb, B.D_TRIP_CURRENT, i), ma_to_i, 15)
        over_current = (abs(i_a) >= trip) | (abs(i_b) >= trip) | (abs(i_c) >= trip)
        link_ok = _s(fb, B.F_SINCE_VALID, i) < _p(fb, B.C_WD_TICKS, i)
        oc_new = over_current & ((latched & B.ST_OVER_CURRENT) == 0)
        latched = latched | B.ST_OVER_CURRENT if oc_new else latched
        oc_trips = _s(fb, B.F_OC_TRIPS, i)
        oc_trips = _count(oc_trips) if oc_new else oc_trips
        wd_new = (state == B.STATE_ENABLED) & (not link_ok) & ((latched & B.ST_LINK_LOST) == 0)
        latched = latched | B.ST_LINK_LOST if wd_new else latched
        wd_trips = _s(fb, B.F_WD_TRIPS, i)
        wd_trips = _count(wd_trips) if wd_new else wd_trips
        extra = extra | B.ST_LINK_OK if link_ok else extra

        # the enable state machine (firmware_model.fpga.enable)
        control = _down(fb, B.D_CONTROL, i)
        mode = _down(fb, B.D_MODE, i)
        enable = ((control & B.CTRL_ENABLE) != 0) & ((mode == B.BoardMode.CURRENT)
                                                     | (mode == B.BoardMode.VOLTAGE))
        clear = ((control & B.CTRL_CLEAR_FAULT) != 0) & (
            (_s(fb, B.F_PREV_CONTROL, i) & B.CTRL_CLEAR_FAULT) == 0)
        was_enabled = state == B.STATE_ENABLED
        was_fault = state == B.STATE_FAULT
        was_other = (not was_enabled) & (not was_fault)
        # enabled: a latched fault -> fault, enable low -> disabled
        st_en = B.STATE_FAULT if latched != 0 else (state if enable else B.STATE_DISABLED)
        # fault: clear with enable low, the cause gone -> disabled, latch cleared
        leave = clear & (not enable) & (not over_current) & link_ok
        # disabled (or any other value): clear, then enable if nothing refuses it
        latched_o = 0 if clear & (not over_current) else latched
        refused = (latched_o != 0) | over_current | (not link_ok) | (
            (extra & B.ST_ENCODER_ERROR) != 0)
        start = was_other & enable & (not refused)
        extra = extra | B.ST_ENABLE_REFUSED if was_other & enable & refused else extra
        state = st_en if was_enabled else (
            (B.STATE_DISABLED if leave else state) if was_fault else (
                B.STATE_ENABLED if start else state))
        latched = (0 if leave else latched) if was_fault else (
            latched if was_enabled else latched_o)
        integ_d = 0 if start else _s(fb, B.F_INTEG_D, i)
        integ_q = 0 if start else _s(fb, B.F_INTEG_Q, i)

        # current loop and modulation: both modes' refs computed, one kept
        top = _p(fb, B.C_PWM_TOP, i)
        v_lim = _p(fb, B.C_V_LIMIT, i)
        enabled = state == B.STATE_ENABLED
        current = mode == B.BoardMode.CURRENT
        v_d_v = clamp(mul_shift(wrap_s(_down(fb, B.D_VD_REF, i), 16), mv_to_v, 15), -v_lim, v_lim)
        i_lim = min(mul_shift(_down(fb, B.D_CURRENT_LIMIT, i), ma_to_i, 15), 32767)
        iq_ref = clamp(mul_shift(wrap_s(_down(fb, B.D_IQ_REF, i), 16), ma_to_i, 15),
                       -i_lim, i_lim)
        id_ref = clamp(mul_shift(wrap_s(_down(fb, B.D_ID_REF, i), 16), ma_to_i, 15),
                       -i_lim, i_lim)
        ff = sat_s(mul_shift(wrap_s(_down(fb, B.D_VQ_FF, i), 16), mv_to_v, 15), 16)
        kp = _down(fb, B.D_KP, i)
        ki = _down(fb, B.D_KI, i)
        v_d_c, integ_d_c = _pi_step(id_ref - i_d, integ_d, kp, _p(fb, B.C_KP_SHIFT, i), ki,
                                    _p(fb, B.C_KI_SHIFT, i), 0, v_lim)
        v_d = v_d_c if current else v_d_v
        # q_limit(v_d, v_lim): the voltage mode's clamp and the current mode's PI limit
        r = v_lim * v_lim - v_d * v_d
        q_lim = isqrt16(r) if r > 0 else 0
        v_q_v = clamp(mul_shift(wrap_s(_down(fb, B.D_VQ_REF, i), 16), mv_to_v, 15),
                      -q_lim, q_lim)
        v_q_c, integ_q_c = _pi_step(iq_ref - i_q, integ_q, kp, _p(fb, B.C_KP_SHIFT, i), ki,
                                    _p(fb, B.C_KI_SHIFT, i), ff, q_lim)
        v_q = v_q_c if current else v_q_v
        v_alpha, v_beta = _inv_park(v_d, v_q, sn, co)
        d_a, d_b, d_c = _svpwm(v_alpha, v_beta, top)
        half = top >> 1
        use_c = enabled & current
        integ_d = (integ_d_c if use_c else integ_d) if enabled else 0
        integ_q = (integ_q_c if use_c else integ_q) if enabled else 0
        v_d = v_d if enabled else 0
        v_q = v_q if enabled else 0
        fb[_ix(SO, B.F_DUTY_A, i)] = d_a if enabled else half
        fb[_ix(SO, B.F_DUTY_B, i)] = d_b if enabled else half
        fb[_ix(SO, B.F_DUTY_C, i)] = d_c if enabled else half
        fb[_ix(SO, B.F_PWM_ON, i)] = 1 if enabled else 0

        # strain: a new AD7195 conversion was read this tick
        new = _raw(fb, B.R_STRAIN_NEW, i) != 0
        good = new & (_raw(fb, B.R_STRAIN_OK, i) != 0)
        bad = new & (_raw(fb, B.R_STRAIN_OK, i) == 0)
        samples = _s(fb, B.F_STRAIN_SAMPLES, i)
        n = (samples + 1) & 0xFF
        code = _raw(fb, B.R_STRAIN, i)
        fb[_ix(UO, B.U_STRAIN_LO, i)] = code & 0xFFFF
        fb[_ix(UO, B.U_STRAIN_HI, i)] = ((code >> 16) & 0xFF) | (n << 8)
        fb[_ix(XO, X_STRAIN, i)] = 1 if good else 0
        err_strain = _s(fb, B.F_ERR_STRAIN, i)
        err_strain = _count(err_strain) if bad else err_strain
        extra = extra | B.ST_STRAIN_ERROR if bad else extra
        extra = extra if new else extra | (_s(fb, B.F_STATUS_EXTRA, i) & B.ST_STRAIN_ERROR)

        # upstream words
        status = extra | latched
        status = status | B.ST_FAULT if (latched != 0) | (state == B.STATE_FAULT) else status
        status = status | B.ST_ENABLED if state == B.STATE_ENABLED else status
        i_to_ma = _p(fb, B.C_I_TO_MA, i)
        v_to_mv = _p(fb, B.C_V_TO_MV, i)
        fb[_ix(UO, B.U_STATUS, i)] = status
        fb[_ix(UO, B.U_STATE, i)] = state
        fb[_ix(UO, B.U_THETA_E, i)] = theta_e
        fb[_ix(UO, B.U_IQ, i)] = sat_s(mul_shift(i_q, i_to_ma, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_ID, i)] = sat_s(mul_shift(i_d, i_to_ma, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_IA, i)] = sat_s(mul_shift(i_a, i_to_ma, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_IB, i)] = sat_s(mul_shift(i_b, i_to_ma, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_VD_OUT, i)] = sat_s(mul_shift(v_d, v_to_mv, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_VQ_OUT, i)] = sat_s(mul_shift(v_q, v_to_mv, 15), 16) & 0xFFFF
        fb[_ix(UO, B.U_TICK, i)] = tick & 0xFFFF

        # the state the tick leaves
        fb[_ix(SO, B.F_THETA_E, i)] = theta_e
        fb[_ix(SO, B.F_ERR_SSI, i)] = err_ssi
        fb[_ix(SO, B.F_ERR_BISS, i)] = err_biss
        fb[_ix(SO, B.F_ID, i)] = i_d
        fb[_ix(SO, B.F_IQ, i)] = i_q
        fb[_ix(SO, B.F_OC_TRIPS, i)] = oc_trips
        fb[_ix(SO, B.F_WD_TRIPS, i)] = wd_trips
        fb[_ix(SO, B.F_PREV_CONTROL, i)] = control
        fb[_ix(SO, B.F_STATE, i)] = state
        fb[_ix(SO, B.F_LATCHED, i)] = latched
        fb[_ix(SO, B.F_INTEG_D, i)] = integ_d
        fb[_ix(SO, B.F_INTEG_Q, i)] = integ_q
        fb[_ix(SO, B.F_VD, i)] = v_d
        fb[_ix(SO, B.F_VQ, i)] = v_q
        fb[_ix(SO, B.F_STRAIN_SAMPLES, i)] = n if good else samples
        fb[_ix(SO, B.F_ERR_STRAIN, i)] = err_strain
        fb[_ix(SO, B.F_STATUS_EXTRA, i)] = extra
        fb[_ix(SO, B.F_SINCE_VALID, i)] = min(_s(fb, B.F_SINCE_VALID, i) + 1, 1 << 30)
        fb[_ix(SO, B.F_TICK, i)] = tick + 1


@njit(cache=True, inline="always")
def exchange_out(fb, j, st, raw, down):
    """Lane ``j``'s exchange words (raw sensor words, downstream memory, the link endpoint's
    ``F_SINCE_VALID`` and ``F_ERR_LINK_CRC``) into one board's rows: for a stage's scalar
    code, and at the batch's end."""
    for k in range(B.N_RAW):
        raw[k] = fb[_ix(RO, k, j)]
    for k in range(B.DOWN_WORDS):
        down[k] = fb[_ix(DO, k, j)]
    st[B.F_SINCE_VALID] = fb[_ix(SO, B.F_SINCE_VALID, j)]
    st[B.F_ERR_LINK_CRC] = fb[_ix(SO, B.F_ERR_LINK_CRC, j)]


@njit(cache=True, inline="always")
def exchange_in(fb, j, st, raw, down):
    """One board's exchange words from its rows into lane ``j`` (:func:`exchange_out`'s
    reverse): at the batch's claim, and after a stage's scalar code."""
    for k in range(B.N_RAW):
        fb[_ix(RO, k, j)] = raw[k]
    for k in range(B.DOWN_WORDS):
        fb[_ix(DO, k, j)] = down[k]
    fb[_ix(SO, B.F_SINCE_VALID, j)] = st[B.F_SINCE_VALID]
    fb[_ix(SO, B.F_ERR_LINK_CRC, j)] = st[B.F_ERR_LINK_CRC]


@njit(**LANES, inline="always")
def board_tick(fb, rows, m, raw, down, state, up, params):
    """One tick of the boards ``rows[:m]``, their state and the tick's inputs (raw sensor
    words, downstream memory, the link's two counts) in the lanes of ``fb``
    (:func:`load_board`): what ``control_tick`` would do to each. The upstream words go into
    the boards' rows of ``up``, the speed ring is each board's row of ``state``; ``raw`` and
    ``down`` (rows) are used only by a batch that runs the scalar tick. Afterwards the lanes
    hold each board's PWM-on flag and compare counts (``lane(fb, SO, F_PWM_ON, j)``...), and
    the link's two counts as the tick found them (``XO``: ``X_SINCE``, ``X_CRC``) for the
    trace."""
    for j in range(LW):
        fb[_ix(XO, X_SINCE, j)] = fb[_ix(SO, B.F_SINCE_VALID, j)]
        fb[_ix(XO, X_CRC, j)] = fb[_ix(SO, B.F_ERR_LINK_CRC, j)]
    if fb[HO + H_SCALAR] != 0:
        for j in range(m):
            r = rows[j]
            st = state[r]
            exchange_out(fb, j, st, raw[r], down[r])
            fb[_ix(SO, B.F_PWM_ON, j)] = control_tick(params[r], st, down[r], up[r], raw[r])
            for f in range(B.F_DUTY_A, B.F_DUTY_C + 1):
                fb[_ix(SO, f, j)] = st[f]
            fb[_ix(SO, B.F_SINCE_VALID, j)] = st[B.F_SINCE_VALID]
        return
    # the words the board only copies, and the ABI speed ring, board by board
    for j in range(m):
        r = rows[j]
        u = up[r]
        # speed: ABI count difference over a window of ticks (M method)
        window = fb[_ix(PO, B.C_SPEED_WINDOW, j)]
        abi = wrap_u(_raw(fb, B.R_ABI, j), 16)
        if fb[_ix(SO, B.F_TICK, j)] == 0:
            for k in range(window):
                state[r, B.RING_BASE + k] = abi
        pos = fb[_ix(SO, B.F_RING_POS, j)]
        u[B.U_SPEED] = wrap_s(abi - state[r, B.RING_BASE + pos], 16) & 0xFFFF
        state[r, B.RING_BASE + pos] = abi
        fb[_ix(SO, B.F_RING_POS, j)] = (pos + 1) & (window - 1)
        u[B.U_ABI] = abi
        if _raw(fb, B.R_SSI_OK, j) != 0:
            u[B.U_SSI] = _raw(fb, B.R_SSI, j)
        if _raw(fb, B.R_BISS_OK, j) != 0:
            biss = _raw(fb, B.R_BISS, j)
            u[B.U_PISTON_LO] = biss & 0xFFFF
            u[B.U_PISTON_HI] = (biss >> 16) & 0xFFFF
        for a in range(B.ANALOG_UP.size):
            u[B.ANALOG_UP[a]] = _raw(fb, B.ANALOG_RAW[a], j)
        u[B.U_HALL] = _raw(fb, B.R_HALL, j)
        u[B.U_ERR_LINK_CRC] = fb[_ix(SO, B.F_ERR_LINK_CRC, j)]
        u[B.U_SEQ_ECHO] = _down(fb, B.D_SEQUENCE, j)
    tick_lanes(fb)
    # scatter: the upstream words into the boards' rows
    for j in range(m):
        u = up[rows[j]]
        for q in range(_UP_OUT.shape[0]):
            u[_UP_OUT[q, 0]] = fb[np.uint64(_UP_OUT[q, 1] + j)]
        if fb[_ix(XO, X_STRAIN, j)] != 0:
            u[B.U_STRAIN_LO] = fb[_ix(UO, B.U_STRAIN_LO, j)]
            u[B.U_STRAIN_HI] = fb[_ix(UO, B.U_STRAIN_HI, j)]


@njit(**LANES)
def load_board(fb, params, state, raw, down, rows, m):
    """Parameters, named state and exchange words (raw sensor words, downstream memory) of
    the boards ``rows[:m]`` into lanes 0..m-1 (the last one's again into the free lanes,
    computed and never stored); whether the batch runs the scalar tick (a compiled RTL
    loop on one of its boards)."""
    scalar = 0
    for j in range(LW):
        r = rows[min(j, m - 1)]
        for k in range(B.N_PARAMS):
            fb[_ix(PO, k, j)] = params[r, k]
        for k in range(N_NAMED):
            fb[_ix(SO, k, j)] = state[r, k]
        exchange_in(fb, j, state[r], raw[r], down[r])
        if params[r, B.C_RTL_TICK] != 0:
            scalar = 1
    fb[HO + H_SCALAR] = scalar


@njit(**LANES)
def store_board(fb, state, raw, down, rows, m):
    """The named state and the exchange words of lanes 0..m-1 back into the boards' rows
    ``rows[:m]`` (a batch on the scalar tick has its named state in the rows already)."""
    for j in range(m):
        r = rows[j]
        exchange_out(fb, j, state[r], raw[r], down[r])
        if fb[HO + H_SCALAR] == 0:
            for k in range(N_NAMED):
                state[r, k] = fb[_ix(SO, k, j)]


def board_buffer() -> np.ndarray:
    """A zeroed board lane buffer (:data:`SIZE` int64 words)."""
    return np.zeros(SIZE, dtype=np.int64)


__all__ = ["LANES", "LW", "board_buffer", "board_tick", "exchange_in", "exchange_out",
           "isqrt16", "lane", "load_board", "sin_cos_lanes", "store_board", "tick_lanes"]
