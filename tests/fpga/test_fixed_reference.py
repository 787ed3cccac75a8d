"""The fixed-point FOC chain against a float64 reference, within derived quantisation bounds.

Every bound below is computed from the terms of the derivation in ``docs/fpga.md`` ("Error
bounds against float64"), not fitted to the observed error:

* angle rounding to 1024 table steps: |theta - theta_k| <= DELTA_ANGLE = pi/1024 rad;
* table rounding: |(cos, sin)_table / 2^15 - (cos, sin)(theta_k)| <= EPS_TABLE = 2^-15
  (0.5 LSB per component, 1 LSB at the +1 entry saturated to 32767, whose partner is 0);
* output rounding (``shr_round``/``mul_shift``): 0.5 LSB;
* constant rounding: |K - 2^15 c| / 2^15 times the input the constant multiplies.

Units: currents and voltages in s16 LSB (Q1.15 of I_FS = 40 A, V_dc = 48 V), angle in u16
counts (2^16 per electrical turn), duty in PWM compare counts (top = 1250).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.fpga.fixed import (
    clamp,
    isqrt,
    mul_shift,
    sat_s,
    sat_u,
    shr_floor,
    shr_round,
    wrap_s,
    wrap_u,
)
from firmware_model.fpga.foc import (
    INV_SQRT3_Q15,
    SINE_TABLE,
    SQRT3_2_Q15,
    V_LIMIT_Q15,
    clarke,
    inv_park,
    park,
    pi_step,
    q_limit,
    sin_cos,
    svpwm,
)
from firmware_model.fpga.params import gain_registers

Q15 = float(1 << 15)
S16_MIN, S16_MAX = -(1 << 15), (1 << 15) - 1
TOP = 1250
KP_SHIFT, KI_SHIFT = 12, 16
#: Float slack for the reference's own rounding (values are < 2^20 LSB; float64 eps 2^-52).
TINY = 1e-9

# --- terms of the derivation ----------------------------------------------------------------
#: Largest angle rounding: half a table step, 32 of 2^16 counts per turn [rad].
DELTA_ANGLE = math.pi / 1024
#: Norm of the table's error vector at a table angle [1 = full scale].
EPS_TABLE = 2.0 ** -15
#: Norm of the (cos, sin) error vector at any angle: |e^{j theta_k} - e^{j theta}| =
#: 2 sin(|theta - theta_k| / 2) <= DELTA_ANGLE, plus the table term.
EPS_TRIG = DELTA_ANGLE + EPS_TABLE
#: Output rounding of shr_round / mul_shift [LSB].
ROUND = 0.5
#: Constant errors in units of 2^-15: Clarke's 1/sqrt3 (0.386), inverse Clarke's sqrt3/2 (0.080).
DK_CLARKE = abs(INV_SQRT3_Q15 - Q15 / math.sqrt(3.0))
DK_SVPWM = abs(SQRT3_2_Q15 - Q15 * math.sqrt(3.0) / 2.0)

s16 = st.integers(S16_MIN, S16_MAX)
angle = st.integers(0, 0xFFFF)
SETTINGS = settings(max_examples=300, deadline=None)


# --- float64 reference ------------------------------------------------------------------------
def theta_rad(theta_e: int) -> float:
    """Electrical angle in rad of a u16 angle word."""
    return 2.0 * math.pi * theta_e / 65536.0


def theta_table(theta_e: int) -> float:
    """The table angle the model uses: nearest of 1024 steps (half up) [rad]."""
    return 2.0 * math.pi * ((theta_e + 32) >> 6) / 1024.0


def sat16(x: float) -> float:
    """Saturate a float to the s16 range (the reference of ``sat_s(.., 16)``)."""
    return min(max(x, S16_MIN), S16_MAX)


def ref_clarke(i_a: float, i_b: float) -> tuple[float, float]:
    return sat16(i_a), sat16((i_a + 2.0 * i_b) / math.sqrt(3.0))


def ref_park(x: float, y: float, th: float) -> tuple[float, float]:
    c, s = math.cos(th), math.sin(th)
    return sat16(x * c + y * s), sat16(y * c - x * s)


def ref_inv_park(d: float, q: float, th: float) -> tuple[float, float]:
    c, s = math.cos(th), math.sin(th)
    return sat16(d * c - q * s), sat16(d * s + q * c)


def ref_svpwm(v_alpha: float, v_beta: float, top: int, clip: bool = True) -> list[float]:
    """Min-max injection SVPWM in float: counts top/2 + top (v_x + v_off) / 2^15."""
    r = math.sqrt(3.0) / 2.0
    v = [v_alpha, -0.5 * v_alpha + r * v_beta, -0.5 * v_alpha - r * v_beta]
    off = -(max(v) + min(v)) / 2.0
    counts = [top / 2.0 + top * (x + off) / Q15 for x in v]
    return [min(max(c, 0.0), float(top)) for c in counts] if clip else counts


def ref_pi(error: int, integ: int, kp: int, ki: int, ff: int,
           limit: int) -> tuple[float, float, float]:
    """Float PI with the same conditional integration: (output, unsaturated output,
    new integrator in units of 2^-KI_SHIFT output LSB)."""
    i_old = integ / 2.0 ** KI_SHIFT
    i_new = min(max(i_old + ki * error / 2.0 ** KI_SHIFT, -limit), limit)
    u_raw = kp * error / 2.0 ** KP_SHIFT + i_new + ff
    u = u_raw
    if u_raw > limit:
        u = limit
        if error > 0:
            i_new = min(i_old, limit)
    elif u_raw < -limit:
        u = -limit
        if error < 0:
            i_new = max(i_old, -limit)
    return u, u_raw, i_new * 2.0 ** KI_SHIFT


# --- bounds from the derivation ----------------------------------------------------------------
def bound_rotation(x: float, y: float, eps_trig: float) -> float:
    """Park / inverse Park: 0.5 LSB rounding + |vector| * trig error (Cauchy-Schwarz)."""
    return ROUND + math.hypot(x, y) * eps_trig


def bound_i_beta(i_a: int, i_b: int) -> float:
    """Clarke i_beta: 0.5 LSB rounding + |i_a + 2 i_b| * constant error."""
    return ROUND + abs(i_a + 2 * i_b) * DK_CLARKE / Q15


def bound_svpwm(v_beta: int, top: int) -> float:
    """Counts: v_b, v_c err <= E; max/min err <= E; offset err <= E + 0.5 (floor of half);
    leg err <= 2E + 0.5 LSB; times top/2^15, + 0.5 count rounding, + top/2 - (top >> 1)."""
    e_b = ROUND + abs(v_beta) * DK_SVPWM / Q15
    return (top / 2.0 - (top >> 1)) + ROUND + top / Q15 * (2.0 * e_b + ROUND)


# --- sin / cos -----------------------------------------------------------------------------------
def test_table_error_is_eps_table() -> None:
    """The derivation's table term: per component <= 0.5 LSB except the saturated +1 entry
    (1 LSB), and the (cos, sin) error vector's norm <= EPS_TABLE at every table angle."""
    for k in range(257):
        exact = Q15 * math.sin(2.0 * math.pi * k / 1024)
        assert abs(int(SINE_TABLE[k]) - exact) <= (1.0 if exact > S16_MAX else ROUND) + TINY
    worst = 0.0
    for k in range(1024):
        s, c = sin_cos(k << 6)
        th = 2.0 * math.pi * k / 1024
        worst = max(worst, math.hypot(c / Q15 - math.cos(th), s / Q15 - math.sin(th)))
    assert worst <= EPS_TABLE + TINY


def test_sin_cos_all_angles() -> None:
    """Exhaustive: every u16 angle within DELTA_ANGLE + EPS_TABLE of sin/cos (per component
    and as a vector), and exactly the table value of the rounded index."""
    worst = 0.0
    for t in range(1 << 16):
        s, c = sin_cos(t)
        th = theta_rad(t)
        err = math.hypot(c / Q15 - math.cos(th), s / Q15 - math.sin(th))
        worst = max(worst, err)
        k = ((t + 32) >> 6) & 1023
        th_k = 2.0 * math.pi * k / 1024
        assert abs(s - Q15 * math.sin(th_k)) <= 1.0 + TINY, t
        assert abs(c - Q15 * math.cos(th_k)) <= 1.0 + TINY, t
    assert worst <= EPS_TRIG + TINY


@SETTINGS
@given(angle)
def test_sin_cos_bound(theta_e: int) -> None:
    s, c = sin_cos(theta_e)
    th = theta_rad(theta_e)
    assert abs(s / Q15 - math.sin(th)) <= EPS_TRIG + TINY
    assert abs(c / Q15 - math.cos(th)) <= EPS_TRIG + TINY
    assert -S16_MAX <= s <= S16_MAX and -S16_MAX <= c <= S16_MAX


def test_angle_wraps() -> None:
    """65535 and 65504 round up to index 1024, which wraps to index 0; 65503 is index 1023."""
    assert sin_cos(65535) == sin_cos(0) == (0, S16_MAX)
    assert sin_cos(65504) == sin_cos(0)
    s, c = sin_cos(65503)
    assert s == -int(SINE_TABLE[1]) and c == S16_MAX
    assert sin_cos(31) == sin_cos(0) and sin_cos(32) == (int(SINE_TABLE[1]), S16_MAX)
    for t in (16384, 32768, 49152):  # quadrant starts: +1/-1 entries, exact zeros
        s, c = sin_cos(t)
        th = theta_rad(t)
        assert (s, c) == (round(S16_MAX * math.sin(th)), round(S16_MAX * math.cos(th)))


# --- Clarke --------------------------------------------------------------------------------------
@SETTINGS
@given(s16, s16)
def test_clarke_bound(i_a: int, i_b: int) -> None:
    i_alpha, i_beta = clarke(i_a, i_b)
    r_alpha, r_beta = ref_clarke(i_a, i_b)
    assert i_alpha == r_alpha
    assert abs(i_beta - r_beta) <= bound_i_beta(i_a, i_b) + TINY


def test_clarke_i_beta_saturates_at_16_bits() -> None:
    """i_beta = round(2 i_b K / 2^15) reaches 2^15 at i_b >= ceil((2^30 - 2^14) / 2K):
    0.866 I_FS with i_a = 0. Below, it is the unsaturated value; at/above, 32767."""
    thr = -(-((1 << 30) - (1 << 14)) // (2 * INV_SQRT3_Q15))
    assert abs(thr / Q15 - math.sqrt(3.0) / 2.0) < 1e-3
    unclipped = (2 * (thr - 1) * INV_SQRT3_Q15 + (1 << 14)) >> 15
    assert S16_MAX - 1 <= unclipped <= S16_MAX
    assert clarke(0, thr - 1) == (0, unclipped)
    assert (2 * thr * INV_SQRT3_Q15 + (1 << 14)) >> 15 == S16_MAX + 1  # first to clip
    for i_b in (thr, thr + 1, S16_MAX):
        assert clarke(0, i_b) == (0, S16_MAX)
        assert clarke(0, -i_b - 1)[1] == S16_MIN
    assert clarke(S16_MAX, S16_MAX) == (S16_MAX, S16_MAX)
    assert clarke(S16_MIN, S16_MIN) == (S16_MIN, S16_MIN)
    assert clarke(S16_MAX, S16_MIN) == (S16_MAX, mul_shift(S16_MAX + 2 * S16_MIN,
                                                           INV_SQRT3_Q15, 15))


# --- Park / inverse Park ------------------------------------------------------------------------
@SETTINGS
@given(s16, s16, angle)
def test_park_bound(x: int, y: int, theta_e: int) -> None:
    s, c = sin_cos(theta_e)
    got = park(x, y, s, c)
    for ref, eps in ((ref_park(x, y, theta_rad(theta_e)), EPS_TRIG),
                     (ref_park(x, y, theta_table(theta_e)), EPS_TABLE)):
        b = bound_rotation(x, y, eps)
        assert abs(got[0] - ref[0]) <= b + TINY and abs(got[1] - ref[1]) <= b + TINY


@SETTINGS
@given(s16, s16, angle)
def test_inv_park_bound(d: int, q: int, theta_e: int) -> None:
    s, c = sin_cos(theta_e)
    got = inv_park(d, q, s, c)
    for ref, eps in ((ref_inv_park(d, q, theta_rad(theta_e)), EPS_TRIG),
                     (ref_inv_park(d, q, theta_table(theta_e)), EPS_TABLE)):
        b = bound_rotation(d, q, eps)
        assert abs(got[0] - ref[0]) <= b + TINY and abs(got[1] - ref[1]) <= b + TINY


def test_park_and_inv_park_saturate() -> None:
    """A full-scale vector at 45 deg has |(x, y)| = sqrt2 FS: the rotated d component clips."""
    s, c = sin_cos(8192)  # 45 deg
    assert park(S16_MAX, S16_MAX, s, c) == (S16_MAX, 0)
    assert park(S16_MIN, S16_MIN, s, c) == (S16_MIN, 0)
    assert inv_park(S16_MAX, 0, s, c) == (23169, 23169)  # 32767 * 23170 / 2^15 = 23169.3
    assert inv_park(S16_MAX, S16_MAX, s, c) == (0, S16_MAX)
    assert inv_park(S16_MIN, S16_MIN, s, c) == (0, S16_MIN)
    # raw words off the unit circle: products 2^30, still clipped rather than wrapped
    assert park(S16_MIN, S16_MIN, S16_MIN, S16_MIN) == (S16_MAX, 0)
    assert inv_park(S16_MIN, S16_MIN, S16_MIN, S16_MIN) == (0, S16_MAX)


# --- SVPWM ------------------------------------------------------------------------------------
@SETTINGS
@given(s16, s16, st.sampled_from([TOP, TOP, TOP, 1000, 1251, 4095]))
def test_svpwm_bound(v_alpha: int, v_beta: int, top: int) -> None:
    got = svpwm(v_alpha, v_beta, top)
    ref = ref_svpwm(v_alpha, v_beta, top)
    b = bound_svpwm(v_beta, top)
    for x, r in zip(got, ref, strict=True):
        assert 0 <= x <= top
        assert abs(x - r) <= b + TINY, (got, ref, b)


def test_svpwm_linear_up_to_vdc_over_sqrt3() -> None:
    """On the circle |v| = V_LIMIT (floor(2^15/sqrt3)) the unclipped float counts reach 0 and
    top to within a count, and the model matches them: no clamping in the linear range."""
    worst = -float(TOP)
    for k in range(1024):
        v_alpha, v_beta = inv_park(V_LIMIT_Q15, 0, *sin_cos(k << 6))
        # error vector of the rotation: two 0.5-LSB roundings plus |v| eps_tab
        assert math.hypot(v_alpha, v_beta) <= V_LIMIT_Q15 * (1 + EPS_TABLE) + math.sqrt(2) * ROUND
        ref = ref_svpwm(v_alpha, v_beta, TOP, clip=False)
        got = svpwm(v_alpha, v_beta, TOP)
        b = bound_svpwm(v_beta, TOP)
        for x, r in zip(got, ref, strict=True):
            assert abs(x - r) <= b + TINY
        worst = max(worst, max(ref) - TOP, -min(ref))
    # the hexagon's inscribed circle touches the rails: the unclipped float counts reach
    # 0 and top to within a count (so the linear range really extends to V_dc/sqrt3)
    assert -1.0 < worst <= bound_svpwm(S16_MAX, TOP)


def test_svpwm_clamps_to_0_top() -> None:
    assert svpwm(S16_MAX, 0, TOP) == (TOP, 0, 0)
    assert svpwm(S16_MIN, 0, TOP) == (0, TOP, TOP)
    assert svpwm(0, S16_MAX, TOP) == (TOP // 2, TOP, 0)
    assert svpwm(0, 0, TOP) == (TOP // 2,) * 3
    for va in (S16_MIN, -1, 0, S16_MAX):
        for vb in (S16_MIN, -1, 0, S16_MAX):
            assert all(0 <= x <= TOP for x in svpwm(va, vb, TOP))


# --- PI --------------------------------------------------------------------------------------
@st.composite
def pi_inputs(draw: st.DrawFn) -> tuple[int, int, int, int, int, int]:
    """(error s17, integ within its clamp, kp u16, ki u16, ff s16, limit 0..32767)."""
    limit = draw(st.integers(0, S16_MAX))
    i_lim = limit << KI_SHIFT
    return (draw(st.integers(-(1 << 16), (1 << 16) - 1)), draw(st.integers(-i_lim, i_lim)),
            draw(st.integers(0, 0xFFFF)), draw(st.integers(0, 0xFFFF)), draw(s16), limit)


@SETTINGS
@given(pi_inputs())
def test_pi_step_bound(case: tuple[int, int, int, int, int, int]) -> None:
    """Output within 0.5 (proportional rounding) + 0.5 (integrator rounding) LSB of float;
    integrator exact when both take the same saturation branch (|u_raw -+ limit| > 1)."""
    error, integ, kp, ki, ff, limit = case
    u, i_new = pi_step(error, integ, kp, KP_SHIFT, ki, KI_SHIFT, ff, limit)
    r_u, r_raw, r_i = ref_pi(error, integ, kp, ki, ff, limit)
    assert abs(u - r_u) <= 2 * ROUND
    assert -limit <= u <= limit
    assert abs(i_new) <= limit << KI_SHIFT
    if abs(r_raw - limit) > 2 * ROUND and abs(r_raw + limit) > 2 * ROUND:
        assert i_new == r_i
    else:  # near the rail: either integrated or held, nothing else
        held = max(-(limit << KI_SHIFT), min(limit << KI_SHIFT, integ))
        step = clamp(integ + ki * error, -(limit << KI_SHIFT), limit << KI_SHIFT)
        assert i_new in (held, step)


@SETTINGS
@given(st.lists(st.integers(-2000, 2000), min_size=1, max_size=60))
def test_pi_integrator_sums_exactly(errors: list[int]) -> None:
    """Far from saturation the integrator is the exact sum of ki e (integer accumulator) and
    the output is within 1 LSB of the float PI after any number of ticks."""
    kp, ki = 1287, 6433
    limit, integ, total = S16_MAX, 0, 0
    for e in errors:
        u, integ = pi_step(e, integ, kp, KP_SHIFT, ki, KI_SHIFT, 0, limit)
        total += e
        assert integ == ki * total
        ref = kp * e / 2.0 ** KP_SHIFT + ki * total / 2.0 ** KI_SHIFT
        assert abs(u - ref) <= 2 * ROUND + TINY


def test_pi_output_and_integrator_clamped() -> None:
    lim = V_LIMIT_Q15
    assert pi_step(65535, 0, 0xFFFF, KP_SHIFT, 0, KI_SHIFT, 0, lim) == (lim, 0)
    assert pi_step(-65536, 0, 0xFFFF, KP_SHIFT, 0, KI_SHIFT, 0, lim) == (-lim, 0)
    # saturated low by feed-forward with a positive error: integrating is allowed (it leads
    # out of saturation) and stops exactly at the clamp limit * 2^16
    integ = 0
    for _ in range(500):
        u, integ = pi_step(5000, integ, 0, KP_SHIFT, 0xFFFF, KI_SHIFT, -3 * lim, lim)
        assert u == -lim and 0 <= integ <= lim << KI_SHIFT
    assert integ == lim << KI_SHIFT
    # integrator above a shrunk limit (q_limit moved) is pulled back to the clamp
    assert pi_step(10, (lim << KI_SHIFT) + 999, 0, KP_SHIFT, 1, KI_SHIFT, 0, lim) == (
        lim, lim << KI_SHIFT)


@pytest.mark.parametrize("sign", [1, -1])
def test_pi_no_windup(default_cfg, sign: int) -> None:
    """Board gains, 2000 ticks of a large error: the output sits on the rail while the
    integrator stays where p + I <= limit. When the error reverses, the output leaves the
    rail on the first tick, by at least the change of the proportional term."""
    kp, ki = gain_registers(default_cfg)
    lim = V_LIMIT_Q15
    e_hi, e_lo = sign * 4000, -sign * 100
    p_hi = shr_round(kp * e_hi, KP_SHIFT)
    integ = 0
    for _ in range(2000):
        u, integ = pi_step(e_hi, integ, kp, KP_SHIFT, ki, KI_SHIFT, 0, lim)
    assert u == sign * lim
    assert sign * (p_hi + shr_round(integ, KI_SHIFT)) <= lim  # conditional integration
    assert abs(integ) < lim << KI_SHIFT  # a clamp-only integrator would sit at the clamp
    u, integ = pi_step(e_lo, integ, kp, KP_SHIFT, ki, KI_SHIFT, 0, lim)
    p_lo = shr_round(kp * e_lo, KP_SHIFT)
    assert sign * u < lim
    assert sign * u <= lim - sign * (p_hi - p_lo)


# --- chain: phase currents -> (i_d, i_q) ------------------------------------------------------
@SETTINGS
@given(s16, s16, angle)
def test_currents_to_dq(i_a: int, i_b: int, theta_e: int) -> None:
    """Clarke then Park: 0.5 + (|i| + e_beta) eps_trig + e_beta, i the float (alpha, beta)."""
    s, c = sin_cos(theta_e)
    got = park(*clarke(i_a, i_b), s, c)
    r_alpha, r_beta = ref_clarke(i_a, i_b)
    e_beta = bound_i_beta(i_a, i_b)
    mag = math.hypot(r_alpha, r_beta)
    for th, eps in ((theta_rad(theta_e), EPS_TRIG), (theta_table(theta_e), EPS_TABLE)):
        ref = ref_park(r_alpha, r_beta, th)
        b = ROUND + (mag + e_beta) * eps + e_beta
        assert abs(got[0] - ref[0]) <= b + TINY and abs(got[1] - ref[1]) <= b + TINY


# --- helpers at their edges -----------------------------------------------------------------
HELPERS = [wrap_s, wrap_u, sat_s, sat_u, shr_floor, shr_round, mul_shift, clamp, isqrt]


@pytest.mark.parametrize("python", [False, True], ids=["compiled", "py_func"])
def test_helper_edges(python: bool) -> None:
    ws, wu, ss, su, sf, sr, ms, cl, sq = (f.py_func if python else f for f in HELPERS)
    assert [ws(x, 16) for x in (32767, 32768, 65535, 65536, -32768, -32769, -65536)] == [
        32767, -32768, -1, 0, -32768, 32767, 0]
    assert ws(1 << 40, 16) == 0 and ws((1 << 40) - 1, 32) == -1
    assert [wu(x, 16) for x in (-1, 0, 65535, 65536, -65536, 70000)] == [
        65535, 0, 65535, 0, 0, 70000 - 65536]
    assert [ss(x, 16) for x in (32767, 32768, 10**9, -32768, -32769, -10**9)] == [
        32767, 32767, 32767, -32768, -32768, -32768]
    assert ss(1 << 40, 32) == (1 << 31) - 1 and ss(-(1 << 40), 17) == -(1 << 16)
    assert [su(x, 16) for x in (-1, -10**9, 0, 65535, 65536)] == [0, 0, 0, 65535, 65535]
    # floor: -0.5 -> -1, -1.5 -> -2; round half up: -0.5 -> 0, -1.5 -> -1, 0.5 -> 1
    assert [sf(x, 1) for x in (-1, -3, 1, 3)] == [-1, -2, 0, 1]
    assert [sr(x, 1) for x in (-1, -3, 1, 3, -2)] == [0, -1, 1, 2, -1]
    assert [sr(x, 4) for x in (-8, -9, 7, 8, -24, -25)] == [0, -1, 0, 1, -1, -2]
    assert [ms(x, 1, 1) for x in (-1, -3, 1)] == [0, -1, 1]
    assert ms(-32768, 40000, 15) == -40000 and ms(32767, 40000, 15) == 39999
    assert ms(S16_MIN, 0xFFFF, 16) == -32767  # -32767.5 rounds up
    assert cl(5, -3, 3) == 3 and cl(-5, -3, 3) == -3 and cl(0, -3, 3) == 0
    edges = {0: 0, 1: 1, 2: 1, 3: 1, 4: 2, 8: 2, 9: 3, 15: 3, 16: 4, (1 << 30) - 1: 32767,
             1 << 30: 32768, (1 << 31) - 1: 46340, (1 << 32) - 1: 65535, 65535**2: 65535,
             65535**2 - 1: 65534, 18918**2: 18918, -5: 0}
    assert {n: sq(n) for n in edges} == edges


@settings(max_examples=300, deadline=None)
@given(st.integers(-(1 << 40), 1 << 40), st.integers(1, 20), st.integers(0, 0xFFFF))
def test_helpers_against_exact_integer_formulas(x: int, s: int, k: int) -> None:
    """floor(x / 2^s), floor(x / 2^s + 1/2) = floor((2x + 2^s) / 2^(s+1)), modulo, min/max."""
    fns = (shr_floor, shr_round, mul_shift, wrap_u, wrap_s, sat_s, sat_u)
    for python in (False, True):
        fl, rd, ms, wu, ws, ss, su = (f.py_func if python else f for f in fns)
        assert fl(x, s) == x // 2**s
        assert rd(x, s) == (2 * x + 2**s) // 2 ** (s + 1)
        assert ms(x >> 8, k, s) == (2 * (x >> 8) * k + 2**s) // 2 ** (s + 1)
        for bits in (16, 17, 32):
            assert wu(x, bits) == x % 2**bits
            assert ws(x, bits) == (x + 2 ** (bits - 1)) % 2**bits - 2 ** (bits - 1)
            assert ss(x, bits) == min(max(x, -(2 ** (bits - 1))), 2 ** (bits - 1) - 1)
            assert su(x, bits) == min(max(x, 0), 2**bits - 1)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, (1 << 32) - 1))
def test_isqrt_matches_math(n: int) -> None:
    r = math.isqrt(n)
    assert isqrt(n) == r and isqrt.py_func(n) == r
    assert isqrt(r * r) == r and isqrt(r * r - 1 if r else 0) == max(r - 1, 0)


@SETTINGS
@given(st.integers(S16_MIN, S16_MAX), st.integers(0, S16_MAX))
def test_q_limit_is_floor_sqrt(v_d: int, v_max: int) -> None:
    """Room for v_q: floor(sqrt(v_max^2 - v_d^2)), within 1 LSB below the float, 0 outside."""
    q = q_limit(v_d, v_max)
    r = v_max * v_max - v_d * v_d
    assert q == (math.isqrt(r) if r > 0 else 0)
    assert 0 <= math.sqrt(max(r, 0)) - q < 1.0
    if r >= 0:
        assert q * q + v_d * v_d <= v_max * v_max < (q + 1) ** 2 + v_d * v_d
