"""The sensor chips' value level (:func:`plant.sensors.harness.digitise`) over a batch of up
to ``LW`` actuators at once, one actuator per vector lane.

The chips' parameters of a batch are loaded once per kernel call (:func:`load_chips`) into
one flat float64 **lane buffer** (structure of arrays: row ``r`` of lane ``j`` at
``r * LW + j``); per tick :func:`digitise_lanes` copies the plant outputs the chips read
from the plant's lane buffer (:mod:`plant.lanes`, where the tick before left them) into it,
computes every raw word of every lane in one branch-free pass over the lanes (LLVM
vectorises it: ``floor``, float64 <-> int64 conversions, 64-bit multiplies and variable
shifts all have AVX-512 forms), and writes them into the board lanes
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
#: Lane-buffer rows: the chips' parameters (``K_*``), then per lane the SSI and BiSS masks
#: and whether the lane runs the scalar digitise, then the plant outputs read this tick,
#: then the tick's codes.
KO = 0
SSI_MASK = K.N_CHIP
BISS_MASK = SSI_MASK + 1
SCALAR = BISS_MASK + 1
YO = SCALAR + 1                            #: theta_m, x_piston, f_strain, ia, ib, analogs
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
def _mod6(h):
    """``h % 6`` (Python's, in 0..5) for any int64 ``h`` without an integer division: two
    float64 estimates of the quotient (products with 1/6, not divisions: a vector
    division costs ~8x a product; the first leaves a remainder below 2^11, the second is
    off by at most one), then one compare."""
    r = h - np.int64(np.float64(h) * _SIXTH) * 6
    r = r - np.int64(np.float64(r) * _SIXTH) * 6
    r = r + 6 if r < 0 else r
    return r - 6 if r >= 6 else r


@njit(cache=True, inline="always")
def _div_1e9(p):
    """``p // 1_000_000_000`` (floor) for any int64 ``p``: a float64 estimate (a product
    with 1e-9, off by at most one: the quotient is below 2^34) corrected by one compare
    each way."""
    q = np.int64(np.float64(p) * 1e-9)
    r = p - q * 1_000_000_000
    q = q - 1 if r < 0 else q
    r = r + 1_000_000_000 if r < 0 else r
    return q + 1 if r >= 1_000_000_000 else q


@njit(cache=True, inline="always")
def _adc_code(x, code_max):
    """:func:`plant.sensors.chips.adc_code` as selects (float64 result, an integer)."""
    c = np.float64(np.int64(np.floor(x + 0.5)))
    c = np.float64(np.int64(code_max)) if x >= code_max - 0.5 else c
    return 0.0 if x < 0.5 else c


@njit(**LANES)
def load_chips(sb, chips, rows, m):
    """The chips' parameters of the actuators ``rows[:m]`` into lanes 0..m-1 (the last
    one's into the free lanes), the masks of the SSI and BiSS moduli, and whether a lane
    needs the scalar digitise (a modulus that is not a power of two)."""
    for j in range(LW):
        i = rows[min(j, m - 1)]
        for k in range(K.N_CHIP):
            sb[_ix(KO + k, j)] = chips[i, k]
        n = np.int64(chips[i, K.K_SSI_N])
        mod = np.int64(chips[i, K.K_BISS_MOD])
        sb[_ix(SSI_MASK, j)] = n - 1
        sb[_ix(BISS_MASK, j)] = mod - 1
        pow2 = n > 0 and (n & (n - 1)) == 0 and mod > 0 and (mod & (mod - 1)) == 0
        sb[_ix(SCALAR, j)] = 0.0 if pow2 else 1.0


@njit(cache=True, inline="always", error_model="numpy")
def _codes(sb, tick):
    """Every lane's codes of the tick from the outputs in the lane buffer."""
    for j in range(LW):
        theta = sb[_ix(YO + _Y_THETA, j)]
        # motor_encoder.ssi_count, abi_count
        n = sb[_ix(KO + K.K_SSI_N, j)]
        v = np.int64(np.floor(theta * n / _TWO_PI + sb[_ix(KO + K.K_SSI_MOUNT, j)]
                              + EPS_COUNT))
        sb[_ix(RO + _C_SSI, j)] = np.float64(v & np.int64(sb[_ix(SSI_MASK, j)]))
        a = np.int64(np.floor(theta * sb[_ix(KO + K.K_ABI_N, j)] / _TWO_PI + EPS_COUNT))
        sb[_ix(RO + _C_ABI, j)] = np.float64(a & 0xFFFF)
        # piston_encoder.biss_count
        c = (np.int64(np.floor(sb[_ix(YO + _Y_X, j)] / LINEAR_COUNT_M + EPS_COUNT))
             + np.int64(sb[_ix(KO + K.K_BISS_ZERO, j)]))
        sb[_ix(RO + _C_BISS, j)] = np.float64(c & np.int64(sb[_ix(BISS_MASK, j)]))
        # strain_gauge.strain_conversions, strain_clamped, strain_code
        per = np.int64(sb[_ix(KO + K.K_TICK_NS, j)]) * np.int64(sb[_ix(KO + K.K_ODR, j)])
        new = _div_1e9(tick * per) != _div_1e9((tick - 1) * per)
        sb[_ix(RO + _C_NEW, j)] = 1.0 if new else 0.0
        x = sb[_ix(YO + _Y_F, j)] * sb[_ix(KO + K.K_STRAIN_SCALE, j)] + MIDSCALE
        clamped = (x < -0.5) | (x >= CODE_MAX + 0.5)
        sb[_ix(RO + _C_CLAMPED, j)] = 1.0 if clamped else 0.0
        sb[_ix(RO + _C_STRAIN, j)] = np.float64(np.int64(np.floor(x + 0.5)))
        # current_sense.current_code
        lsb = sb[_ix(KO + K.K_I_LSB, j)]
        mid = sb[_ix(KO + K.K_I_MID, j)]
        i_max = sb[_ix(KO + K.K_I_MAX, j)]
        sb[_ix(RO + _C_IA, j)] = _adc_code(sb[_ix(YO + _Y_IA, j)] / lsb + mid, i_max)
        sb[_ix(RO + _C_IB, j)] = _adc_code(sb[_ix(YO + _Y_IB, j)] / lsb + mid, i_max)
        # hall_sensor.hall_code
        h = (sb[_ix(KO + K.K_POLE_PAIRS, j)] * theta - sb[_ix(KO + K.K_HALL_OFFSET, j)]) / (
            _SECTOR)
        s = _mod6(np.int64(np.floor(h)))
        sb[_ix(RO + _C_HALL, j)] = np.float64((HALL_PACKED >> (3 * s)) & 7)
        # chips.analog_code of each analog input (inside the loop over the lanes: as a
        # loop of its own around it, LLVM left it scalar)
        for q in range(N_ANALOG):
            b = KO + K.K_ANALOG + 4 * q
            v = sb[_ix(b, j)] + sb[_ix(YO + _Y_ANALOG + q, j)] * sb[_ix(b + 1, j)] / sb[
                _ix(b + 2, j)]
            code = _adc_code(v / sb[_ix(KO + K.K_ADC_LSB, j)], sb[_ix(KO + K.K_ADC_MAX, j)])
            sb[_ix(RO + _C_ANALOG + q, j)] = 0.0 if sb[_ix(b + 3, j)] < 0.5 else code


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
        ssi = np.int64(sb[_ix(RO + _C_SSI, j)])
        abi = np.int64(sb[_ix(RO + _C_ABI, j)])
        fb[_raw_at(B.R_SSI, j)] = ssi if live else fb[_raw_at(B.R_SSI, j)]
        fb[_raw_at(B.R_ABI, j)] = abi if live else fb[_raw_at(B.R_ABI, j)]
        fb[_raw_at(B.R_SSI_OK, j)] = 1 if live else 0
        live = sb[_ix(KO + K.K_PISTON_DEAD, j)] <= 0.5
        biss = np.int64(sb[_ix(RO + _C_BISS, j)])
        fb[_raw_at(B.R_BISS, j)] = biss if live else fb[_raw_at(B.R_BISS, j)]
        fb[_raw_at(B.R_BISS_OK, j)] = 1 if live else 0
        new = sb[_ix(RO + _C_NEW, j)] != 0.0
        good = new & (sb[_ix(RO + _C_CLAMPED, j)] == 0.0)
        strain = np.int64(sb[_ix(RO + _C_STRAIN, j)])
        fb[_raw_at(B.R_STRAIN_NEW, j)] = 1 if new else 0
        fb[_raw_at(B.R_STRAIN, j)] = strain if good else fb[_raw_at(B.R_STRAIN, j)]
        ok = 1 if good else 0
        fb[_raw_at(B.R_STRAIN_OK, j)] = ok if new else fb[_raw_at(B.R_STRAIN_OK, j)]
        for q in range(N_ANALOG):
            fb[_raw_at(B.ANALOG_RAW[q], j)] = np.int64(sb[_ix(RO + _C_ANALOG + q, j)])
        fb[_raw_at(B.R_IA, j)] = np.int64(sb[_ix(RO + _C_IA, j)])
        fb[_raw_at(B.R_IB, j)] = np.int64(sb[_ix(RO + _C_IB, j)])
        fb[_raw_at(B.R_HALL, j)] = np.int64(sb[_ix(RO + _C_HALL, j)])


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
    _codes(sb, tick)
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
