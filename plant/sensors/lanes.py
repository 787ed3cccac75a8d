"""The sensor chips' value level (:func:`plant.sensors.harness.digitise`) over a batch of up
to ``LW`` actuators at once, one actuator per vector lane.

The chips' parameters of a batch are loaded once per kernel call (:func:`load_chips`) into
one flat float64 **lane buffer** (structure of arrays: row ``r`` of lane ``j`` at
``r * LW + j``); per tick :func:`digitise_lanes` copies the plant outputs the chips read
from the plant's lane buffer (:mod:`plant.lanes`, where the tick before left them) into it,
computes every raw word of every lane in one branch-free pass over the lanes (LLVM
vectorises it on AVX-512 and on AVX2: ``floor``, 64-bit multiplies and variable shifts
have packed forms on both; the float64 <-> int64 conversions, which have packed forms only
with AVX-512DQ, are :mod:`firmware_model.lane_int`'s, with a general pass as a fallback,
:func:`_all_codes`), and writes them into the board lanes
(:mod:`firmware_model.fpga.lanes`, rows ``RO``: the board's inputs) in a second branch-free
pass, holding what the scalar code holds (a dead encoder's count, a rejected strain read).
No actuator row is read or written per tick, except for a lane on the scalar code below.

Per actuator the operations are :func:`digitise`'s in its order, except three integer
steps that have no vector form for 64-bit lanes and are computed another way with the same
result:

* ``% int(n)`` of the SSI count and ``% int(mod)`` of the BiSS count: ``& (n - 1)``, the
  same value for any int64 when ``n`` is a power of two (``chip_params`` makes both
  ``1 << bits``); a lane whose ``n`` is not one runs the scalar :func:`digitise`
  (decided at :func:`load_chips`);
* ``% 6`` of the hall sector and ``// 10**9`` of the strain ADC's conversion count: a
  float64 estimate of the quotient corrected by compares (:func:`_mod6`,
  :func:`_div_1e9`), exact for every int64.

Bit for bit :func:`digitise` per actuator (``tests/plant/test_sensor_lanes.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.lane_int import (
    INT_EXACT,
    int_to_float,
    integral_to_int,
    pick_int,
    small_int_to_float,
    trunc_to_int,
)
from firmware_model.lane_int import bits as _bits
from firmware_model.lane_int import from_bits as _from_bits
from plant import layout as L
from plant.lanes import LANES, LW
from plant.lanes import YO as PYO
from plant.sensors import chips as K
from plant.sensors.hall_sensor import HALL_SEQUENCE
from plant.sensors.harness import ANALOG_ROWS, digitise
from plant.sensors.motor_encoder import EPS_COUNT
from protocols.ad7195 import CODE_MAX, MIDSCALE
from protocols.biss import LINEAR_COUNT_M

N_ANALOG = ANALOG_ROWS.size
#: Lane-buffer rows: the chips' parameters (``K_*``), then per lane the integer constants
#: the codes take (SSI and BiSS masks, the BiSS zero, the strain ADC's ns per conversion
#: period, the converters' largest codes; each an int64 stored as its bits), whether the
#: lane runs the scalar digitise, whether the tick's values were in the fast conversions'
#: range, then the plant outputs read this tick, then the tick's codes (int64 bits).
KO = 0
SSI_MASK = K.N_CHIP
BISS_MASK = SSI_MASK + 1
BISS_ZERO = BISS_MASK + 1
STRAIN_PER = BISS_ZERO + 1
I_MAX = STRAIN_PER + 1
ADC_MAX = I_MAX + 1
SCALAR = ADC_MAX + 1
IN_RANGE = SCALAR + 1
YO = IN_RANGE + 1                          #: theta_m, x_piston, f_strain, ia, ib, analogs
(_Y_THETA, _Y_X, _Y_F, _Y_IA, _Y_IB) = range(5)
_Y_ANALOG = 5
RO = YO + _Y_ANALOG + N_ANALOG             #: codes
(_C_SSI, _C_ABI, _C_BISS, _C_NEW, _C_CLAMPED, _C_STRAIN, _C_IA, _C_IB, _C_HALL) = range(9)
_C_ANALOG = 9
SIZE = (RO + _C_ANALOG + N_ANALOG) * LW    #: float64 entries of a sensor lane buffer
#: The plant output behind each input row (``_Y_*`` order).
Y_SOURCES = np.array([L.Y_THETA_M, L.Y_X_PISTON, L.Y_F_STRAIN, L.Y_IA, L.Y_IB]
                     + list(ANALOG_ROWS), dtype=np.int64)
#: The hall code of each sector, three bits per sector: ``HALL_SEQUENCE[s]`` is
#: ``(HALL_PACKED >> 3 s) & 7`` (a shift, where the table would be a gather).
HALL_PACKED = sum(int(c) << (3 * s) for s, c in enumerate(HALL_SEQUENCE))
assert all(0 <= int(c) < 8 for c in HALL_SEQUENCE) and len(HALL_SEQUENCE) == 6
_SECTOR = np.pi / 3.0
_SIXTH = 1.0 / 6.0
_TWO_PI = K.TWO_PI


@njit(cache=True, inline="always")
def _ix(row, j):
    return np.uint64(row * LW + j)


@njit(cache=True, inline="always")
def _int_at(sb, row, j):
    """The int64 stored as its bits at ``row`` of lane ``j``."""
    return _bits(sb[_ix(row, j)])


@njit(cache=True, inline="always")
def _to_int(x, fast):
    """``np.int64(x)`` of an integral ``x``: by the 1.5 * 2**52 trick (``fast``: exact for
    ``|x| < 2**51``, which the caller checks) or by the conversion itself (any ``x``; on
    AVX2 a scalar instruction per lane)."""
    return integral_to_int(x) if fast else np.int64(x)


@njit(cache=True, inline="always")
def _in_range(x):
    """Whether ``|x| <`` :data:`~plant.blocks.lanemath.INT_EXACT` (a NaN is not)."""
    return np.abs(x) < INT_EXACT


@njit(cache=True, inline="always")
def _mod6(h, fast):
    """``h % 6`` (Python's, in 0..5) of an int64 ``h`` without an integer division: two
    float64 estimates of the quotient (products with 1/6, not divisions: a vector
    division costs ~8x a product; the first leaves a remainder below 2^11, the second is
    off by at most one), then one compare. ``fast``: ``|h| < 2**51`` (the conversions by
    the 1.5 * 2**52 trick); else any int64."""
    hf = small_int_to_float(h) if fast else np.float64(h)
    q = trunc_to_int(hf * _SIXTH) if fast else np.int64(hf * _SIXTH)
    r = h - q * 6
    r = r - trunc_to_int(small_int_to_float(r) * _SIXTH) * 6
    r = r + 6 if r < 0 else r
    return r - 6 if r >= 6 else r


@njit(cache=True, inline="always")
def _div_1e9(p):
    """``p // 1_000_000_000`` (floor) for any int64 ``p``: a float64 estimate (a product
    with 1e-9, off by at most one: the quotient is below 2^34, so its truncation is exact
    by the 1.5 * 2**52 trick; ``p`` converted exactly by :func:`int_to_float`) corrected
    by one compare each way."""
    q = trunc_to_int(int_to_float(p) * 1e-9)
    r = p - q * 1_000_000_000
    q = q - 1 if r < 0 else q
    r = r + 1_000_000_000 if r < 0 else r
    return q + 1 if r >= 1_000_000_000 else q


@njit(cache=True, inline="always")
def _adc_code(x, code_max, code_max_int, fast):
    """:func:`plant.sensors.chips.adc_code` as selects (an int64; ``code_max_int`` is
    ``np.int64(code_max)``), and whether the fast conversion was in range where its
    result is taken."""
    f = np.floor(x + 0.5)
    c = pick_int(x >= code_max - 0.5, code_max_int, _to_int(f, fast))
    ok = _in_range(f) | (x >= code_max - 0.5) | (x < 0.5)
    return pick_int(x < 0.5, np.int64(0), c), ok


@njit(**LANES)
def load_chips(sb, chips, rows, m):
    """The chips' parameters of the actuators ``rows[:m]`` into lanes 0..m-1 (the last
    one's into the free lanes), the integer constants the codes take, and whether a lane
    needs the scalar digitise (a modulus that is not a power of two)."""
    for j in range(LW):
        i = rows[min(j, m - 1)]
        for k in range(K.N_CHIP):
            sb[_ix(KO + k, j)] = chips[i, k]
        n = np.int64(chips[i, K.K_SSI_N])
        mod = np.int64(chips[i, K.K_BISS_MOD])
        sb[_ix(SSI_MASK, j)] = _from_bits(n - 1)
        sb[_ix(BISS_MASK, j)] = _from_bits(mod - 1)
        sb[_ix(BISS_ZERO, j)] = _from_bits(np.int64(chips[i, K.K_BISS_ZERO]))
        sb[_ix(STRAIN_PER, j)] = _from_bits(np.int64(chips[i, K.K_TICK_NS])
                                            * np.int64(chips[i, K.K_ODR]))
        sb[_ix(I_MAX, j)] = _from_bits(np.int64(chips[i, K.K_I_MAX]))
        sb[_ix(ADC_MAX, j)] = _from_bits(np.int64(chips[i, K.K_ADC_MAX]))
        pow2 = n > 0 and (n & (n - 1)) == 0 and mod > 0 and (mod & (mod - 1)) == 0
        sb[_ix(SCALAR, j)] = 0.0 if pow2 else 1.0


@njit(cache=True, inline="always", error_model="numpy")
def _codes(sb, tick, fast):
    """Every lane's codes of the tick from the outputs in the lane buffer, as int64 bits.
    ``fast``: the float64 -> int64 conversions by the 1.5 * 2**52 trick, and whether each
    lane's values were within its range into :data:`IN_RANGE`; else by the conversion
    itself (any value)."""
    for j in range(LW):
        theta = sb[_ix(YO + _Y_THETA, j)]
        # motor_encoder.ssi_count, abi_count
        n = sb[_ix(KO + K.K_SSI_N, j)]
        fv = np.floor(theta * n / _TWO_PI + sb[_ix(KO + K.K_SSI_MOUNT, j)] + EPS_COUNT)
        sb[_ix(RO + _C_SSI, j)] = _from_bits(_to_int(fv, fast) & _int_at(sb, SSI_MASK, j))
        fa = np.floor(theta * sb[_ix(KO + K.K_ABI_N, j)] / _TWO_PI + EPS_COUNT)
        sb[_ix(RO + _C_ABI, j)] = _from_bits(_to_int(fa, fast) & 0xFFFF)
        ok = _in_range(fv) & _in_range(fa)
        # piston_encoder.biss_count
        fc = np.floor(sb[_ix(YO + _Y_X, j)] / LINEAR_COUNT_M + EPS_COUNT)
        c = _to_int(fc, fast) + _int_at(sb, BISS_ZERO, j)
        sb[_ix(RO + _C_BISS, j)] = _from_bits(c & _int_at(sb, BISS_MASK, j))
        ok &= _in_range(fc)
        # strain_gauge.strain_conversions, strain_clamped, strain_code
        per = _int_at(sb, STRAIN_PER, j)
        new = _div_1e9(tick * per) != _div_1e9((tick - 1) * per)
        sb[_ix(RO + _C_NEW, j)] = 1.0 if new else 0.0
        x = sb[_ix(YO + _Y_F, j)] * sb[_ix(KO + K.K_STRAIN_SCALE, j)] + MIDSCALE
        clamped = (x < -0.5) | (x >= CODE_MAX + 0.5)
        sb[_ix(RO + _C_CLAMPED, j)] = 1.0 if clamped else 0.0
        fs = np.floor(x + 0.5)
        sb[_ix(RO + _C_STRAIN, j)] = _from_bits(_to_int(fs, fast))
        ok &= _in_range(fs)
        # current_sense.current_code
        lsb = sb[_ix(KO + K.K_I_LSB, j)]
        mid = sb[_ix(KO + K.K_I_MID, j)]
        i_max = sb[_ix(KO + K.K_I_MAX, j)]
        i_max_int = _int_at(sb, I_MAX, j)
        code, good = _adc_code(sb[_ix(YO + _Y_IA, j)] / lsb + mid, i_max, i_max_int, fast)
        sb[_ix(RO + _C_IA, j)] = _from_bits(code)
        ok &= good
        code, good = _adc_code(sb[_ix(YO + _Y_IB, j)] / lsb + mid, i_max, i_max_int, fast)
        sb[_ix(RO + _C_IB, j)] = _from_bits(code)
        ok &= good
        # hall_sensor.hall_code
        h = (sb[_ix(KO + K.K_POLE_PAIRS, j)] * theta - sb[_ix(KO + K.K_HALL_OFFSET, j)]) / (
            _SECTOR)
        fh = np.floor(h)
        s = _mod6(_to_int(fh, fast), fast)
        sb[_ix(RO + _C_HALL, j)] = _from_bits((HALL_PACKED >> (3 * s)) & 7)
        ok &= _in_range(fh)
        # chips.analog_code of each analog input (inside the loop over the lanes: as a
        # loop of its own around it, LLVM left it scalar)
        adc_max = sb[_ix(KO + K.K_ADC_MAX, j)]
        adc_max_int = _int_at(sb, ADC_MAX, j)
        for q in range(N_ANALOG):
            b = KO + K.K_ANALOG + 4 * q
            v = sb[_ix(b, j)] + sb[_ix(YO + _Y_ANALOG + q, j)] * sb[_ix(b + 1, j)] / sb[
                _ix(b + 2, j)]
            code, good = _adc_code(v / sb[_ix(KO + K.K_ADC_LSB, j)], adc_max, adc_max_int,
                                   fast)
            unfitted = sb[_ix(b + 3, j)] < 0.5
            sb[_ix(RO + _C_ANALOG + q, j)] = _from_bits(pick_int(unfitted, np.int64(0), code))
            ok &= good | unfitted
        if fast:
            sb[_ix(IN_RANGE, j)] = 1.0 if ok else 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _all_codes(sb, tick):
    """:func:`_codes` with the fast conversions, and again with the general ones when some
    lane's values were out of their range (a motor angle or a force far beyond any real
    one): the same codes either way."""
    _codes(sb, tick, True)
    ok = True
    for j in range(LW):
        ok &= sb[_ix(IN_RANGE, j)] != 0.0
    if not ok:
        _codes(sb, tick, False)


@njit(cache=True, inline="always")
def _raw_at(k, j):
    """Raw word ``k`` of lane ``j`` in the board lanes."""
    return np.uint64(fpl.RO + k * LW + j)


@njit(cache=True, inline="always", error_model="numpy")
def _raw_words(sb, fb):
    """Every lane's codes (:func:`_codes`) into its raw words in the board lanes ``fb``,
    as :func:`digitise` writes them into a row: a dead encoder's OK word 0 and its counts
    held, the strain code and OK word held but on a conversion, the OK word 0 and the
    code held for a rejected read."""
    for j in range(LW):
        live = sb[_ix(KO + K.K_MOTOR_DEAD, j)] <= 0.5
        ssi = _int_at(sb, RO + _C_SSI, j)
        abi = _int_at(sb, RO + _C_ABI, j)
        fb[_raw_at(B.R_SSI, j)] = ssi if live else fb[_raw_at(B.R_SSI, j)]
        fb[_raw_at(B.R_ABI, j)] = abi if live else fb[_raw_at(B.R_ABI, j)]
        fb[_raw_at(B.R_SSI_OK, j)] = 1 if live else 0
        live = sb[_ix(KO + K.K_PISTON_DEAD, j)] <= 0.5
        biss = _int_at(sb, RO + _C_BISS, j)
        fb[_raw_at(B.R_BISS, j)] = biss if live else fb[_raw_at(B.R_BISS, j)]
        fb[_raw_at(B.R_BISS_OK, j)] = 1 if live else 0
        new = sb[_ix(RO + _C_NEW, j)] != 0.0
        good = new & (sb[_ix(RO + _C_CLAMPED, j)] == 0.0)
        strain = _int_at(sb, RO + _C_STRAIN, j)
        fb[_raw_at(B.R_STRAIN_NEW, j)] = 1 if new else 0
        fb[_raw_at(B.R_STRAIN, j)] = strain if good else fb[_raw_at(B.R_STRAIN, j)]
        ok = 1 if good else 0
        fb[_raw_at(B.R_STRAIN_OK, j)] = ok if new else fb[_raw_at(B.R_STRAIN_OK, j)]
        for q in range(N_ANALOG):
            fb[_raw_at(B.ANALOG_RAW[q], j)] = _int_at(sb, RO + _C_ANALOG + q, j)
        fb[_raw_at(B.R_IA, j)] = _int_at(sb, RO + _C_IA, j)
        fb[_raw_at(B.R_IB, j)] = _int_at(sb, RO + _C_IB, j)
        fb[_raw_at(B.R_HALL, j)] = _int_at(sb, RO + _C_HALL, j)


@njit(**LANES, inline="always")
def digitise_lanes(sb, pb, fb, chips, rows, m, tick, y, raw):
    """:func:`digitise` at ``tick`` of the plant outputs in the plant lanes ``pb``
    (:data:`plant.lanes.YO`) into the raw words in the board lanes ``fb``
    (:data:`firmware_model.fpga.lanes.RO`), every lane (chips loaded by
    :func:`load_chips`). A lane on the scalar :func:`digitise` runs it on its actuator's
    rows (``y[rows[j]]``, ``raw[rows[j]]``): its outputs and raw words moved there first,
    its raw words back after. (The outputs' copy runs over ``rows``' length, ``LW``, as
    a count the compiler does not know: see :func:`hil.sim.actuator.drive_lanes`.)"""
    for j in range(rows.shape[0]):
        for q in range(Y_SOURCES.size):
            sb[_ix(YO + q, j)] = pb[np.uint64(PYO + Y_SOURCES[q] * LW + j)]
    _all_codes(sb, tick)
    _raw_words(sb, fb)
    for j in range(m):
        if sb[_ix(SCALAR, j)] != 0.0:
            i = rows[j]
            for q in range(Y_SOURCES.size):
                y[i, Y_SOURCES[q]] = pb[np.uint64(PYO + Y_SOURCES[q] * LW + j)]
            for k in range(B.N_RAW):
                raw[i, k] = fb[_raw_at(k, j)]
            digitise(y[i], chips[i], tick, raw[i])
            for k in range(B.N_RAW):
                fb[_raw_at(k, j)] = raw[i, k]


def sensor_lane_buffer() -> np.ndarray:
    """A zeroed sensor lane buffer (:data:`SIZE` float64)."""
    return np.zeros(SIZE)


__all__ = ["SIZE", "digitise_lanes", "load_chips", "sensor_lane_buffer"]
