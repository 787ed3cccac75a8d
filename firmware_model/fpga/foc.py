"""Field-oriented control in fixed point: sin/cos table, Clarke, Park, inverse Park, SVPWM, PI.

Formats (``docs/fpga.md`` has the full table and the error bounds):

* currents: signed 16 bit, Q1.15 of the current-sense full scale I_FS (40 A: 1.22 mA/LSB);
* voltages: signed 16 bit, Q1.15 of the nominal bus voltage V_dc (48 V: 1.46 mV/LSB);
* electrical angle: unsigned 16 bit, one electrical turn = 2**16;
* sin/cos: signed 16 bit Q1.15 from a 257-entry quarter-wave table (1024 steps per turn);
* duty: PWM compare counts 0..``top`` of a centre-aligned (up/down) carrier.

Products are formed at full width and rounded half up back to 16 bit (:func:`shr_round`),
then saturated. Everything is integer; no float enters these functions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.fpga.fixed import clamp, isqrt, mul_shift, sat_s, shr_round

#: Fractional bits of the Q1.15 formats.
Q = 15
#: round(2**15 / sqrt(3)): Clarke's 1/sqrt(3).
INV_SQRT3_Q15 = round((1 << Q) / math.sqrt(3.0))
#: round(2**15 * sqrt(3) / 2): inverse Clarke's sqrt(3)/2.
SQRT3_2_Q15 = round((1 << Q) * math.sqrt(3.0) / 2.0)
#: Steps of the sine table per electrical turn (the angle's top 10 bits, rounded).
SINE_STEPS = 1024
#: Angle bits dropped when indexing the table (16 - 10).
SINE_SHIFT = 6
#: Quarter-wave table: round(2**15 sin(2 pi k / 1024)) for k = 0..256, saturated to 32767.
SINE_TABLE = np.array(
    [min(32767, round((1 << Q) * math.sin(2.0 * math.pi * k / SINE_STEPS)))
     for k in range(SINE_STEPS // 4 + 1)],
    dtype=np.int64,
)
#: Largest voltage vector SVPWM can make without clipping: floor(2**15 / sqrt(3)).
V_LIMIT_Q15 = int((1 << Q) / math.sqrt(3.0))


@njit(cache=True, inline="always")
def _quarter_sine(k: int) -> int:
    """sin(2 pi k / 1024) in Q1.15 from the quarter-wave table, any integer k."""
    k &= SINE_STEPS - 1
    quadrant = k >> 8
    r = k & 255
    if quadrant == 0:
        return SINE_TABLE[r]
    if quadrant == 1:
        return SINE_TABLE[256 - r]
    if quadrant == 2:
        return -SINE_TABLE[r]
    return -SINE_TABLE[256 - r]


@njit(cache=True)
def sin_cos(theta_e: int) -> tuple[int, int]:
    """(sin, cos) of an electrical angle (u16, 2**16 per turn) in Q1.15.

    The angle is rounded to the nearest of 1024 table steps (error <= pi/1024 rad), so
    |sin - sin_true| <= pi/1024 + 2**-15 (table rounding; the +/-1 entries saturate to
    32767, which costs 2**-15 where the sine is flat).
    """
    k = (theta_e + (1 << (SINE_SHIFT - 1))) >> SINE_SHIFT
    return _quarter_sine(k), _quarter_sine(k + SINE_STEPS // 4)


@njit(cache=True)
def clarke(i_a: int, i_b: int) -> tuple[int, int]:
    """Amplitude-invariant Clarke transform of two phase currents (i_c = -i_a - i_b).

    i_alpha = i_a, i_beta = (i_a + 2 i_b) / sqrt(3); both s16 Q1.15, i_beta saturated
    (it exceeds 16 bit only beyond 0.87 I_FS per phase, far above the trip level).
    """
    i_beta = mul_shift(i_a + 2 * i_b, INV_SQRT3_Q15, Q)
    return sat_s(i_a, 16), sat_s(i_beta, 16)


@njit(cache=True)
def park(i_alpha: int, i_beta: int, s: int, c: int) -> tuple[int, int]:
    """Park transform: (i_d, i_q) = rotate (i_alpha, i_beta) by -theta; s16, saturated."""
    i_d = shr_round(i_alpha * c + i_beta * s, Q)
    i_q = shr_round(i_beta * c - i_alpha * s, Q)
    return sat_s(i_d, 16), sat_s(i_q, 16)


@njit(cache=True)
def inv_park(v_d: int, v_q: int, s: int, c: int) -> tuple[int, int]:
    """Inverse Park: (v_alpha, v_beta) = rotate (v_d, v_q) by +theta; s16, saturated."""
    v_alpha = shr_round(v_d * c - v_q * s, Q)
    v_beta = shr_round(v_d * s + v_q * c, Q)
    return sat_s(v_alpha, 16), sat_s(v_beta, 16)


@njit(cache=True)
def svpwm(v_alpha: int, v_beta: int, top: int) -> tuple[int, int, int]:
    """Space-vector PWM by min-max zero-sequence injection -> compare counts 0..top.

    Phase voltages from the inverse Clarke transform, then the mean of the largest and
    smallest is subtracted from all three (the common mode a star winding does not see),
    which reaches |v| = V_dc/sqrt(3) like the seven-segment SVPWM. Duty of leg x is
    1/2 + v_x / V_dc, i.e. count = top/2 + v_x * top / 2**15, saturated to 0..top.
    """
    v_a = v_alpha
    v_b = shr_round(SQRT3_2_Q15 * v_beta - (v_alpha << (Q - 1)), Q)
    v_c = -v_a - v_b
    hi = max(v_a, max(v_b, v_c))
    lo = min(v_a, min(v_b, v_c))
    v_off = -((hi + lo) >> 1)
    half = top >> 1
    c_a = clamp(half + mul_shift(v_a + v_off, top, Q), 0, top)
    c_b = clamp(half + mul_shift(v_b + v_off, top, Q), 0, top)
    c_c = clamp(half + mul_shift(v_c + v_off, top, Q), 0, top)
    return c_a, c_b, c_c


@njit(cache=True)
def pi_step(
    error: int, integ: int, kp: int, kp_shift: int, ki: int, ki_shift: int, ff: int,
    limit: int,
) -> tuple[int, int]:
    """One PI update; returns (output, new integrator). Integer gains as multiply + shift.

    output = kp * e / 2**kp_shift + integ / 2**ki_shift + ff, saturated to +/-limit.
    The integrator (s32, units of output * 2**ki_shift) adds ki * e each tick and is
    clamped to +/-limit * 2**ki_shift; when the output saturates, integration in the
    direction of the saturation is skipped (conditional integration: no wind-up).
    ``error`` is s17 (difference of two s16 values).
    """
    p = shr_round(kp * error, kp_shift)
    i_lim = limit << ki_shift
    i_new = clamp(integ + ki * error, -i_lim, i_lim)
    u = p + shr_round(i_new, ki_shift) + ff
    if u > limit:
        u = limit
        if error > 0:
            # Hold the integrator, but inside the clamp: the limit may have shrunk since.
            i_new = clamp(integ, -i_lim, i_lim)
    elif u < -limit:
        u = -limit
        if error < 0:
            i_new = clamp(integ, -i_lim, i_lim)
    return u, i_new


@njit(cache=True)
def q_limit(v_d: int, v_max: int) -> int:
    """Room left for v_q inside the voltage circle once v_d is set: isqrt(v_max^2 - v_d^2)."""
    r = v_max * v_max - v_d * v_d
    return isqrt(r) if r > 0 else 0


__all__ = [
    "INV_SQRT3_Q15", "Q", "SINE_TABLE", "SQRT3_2_Q15", "V_LIMIT_Q15", "clarke", "inv_park",
    "park", "pi_step", "q_limit", "sin_cos", "svpwm",
]
