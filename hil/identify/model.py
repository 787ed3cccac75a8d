"""The fast model the fit simulates: thesis ch. 2 linear EHA, exactly discretised, plus effects.

States ``z = [theta_p, v_p, tau_q, x_c, v_c]`` (piston-equivalent m, m/s, N, m, m/s), inputs
``u = [tau_p, f_pump, q_rate, f_piston]`` (N, N, N/s, N):

    J_p dv_p/dt   = tau_p - d_p v_p - tau_q + f_pump                 (Eq. 2.28)
    d tau_q/dt    = k_s (v_p - tau_q / d_s - v_c) + q_rate           (Eq. 2.29-2.30)
    J_c dv_c/dt   = tau_q - (d_c + c_rod) v_c - k_rod x_c + f_piston (Eq. 2.31 + load)

with ``tau_p = K i_q`` (K the current-to-force gain, N/A). Piston fixed: ``x_c = v_c = 0``;
free: ``k_rod = c_rod = 0``; conrod: the rod to a fixed point. The linear part is discretised
exactly (zero-order hold, matrix exponential) over ``n_sub`` sub-steps per sample, so its
stiff modes (leakage ``k_s/d_s``, the piston on ``k_s`` near 1.4 kHz) cost nothing in
accuracy. The effect terms enter through ``f_pump``, ``q_rate``, ``f_piston``, evaluated
from the state at the start of each sub-step; the Coulomb frictions are solved implicitly
(a scalar root per friction), so a small regularisation velocity does not chatter: the
pump's for the end-of-sub-step velocity, the seal's for the mid-sub-step one (second order:
a piston held by a stiff rod lives in the seal's stuck zone, where the law is a damper whose
time constant is a fraction of the sub-step). Output-side effects (strain drift, sensor
saturation) and the input delay act outside the loop.

Parameters live in one flat vector addressed by :data:`PARAM_NAMES`; all effect parameters
at zero is the linear model.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np
from numba import njit
from scipy.fft import next_fast_len
from scipy.linalg import expm

from hil.identify.experiment import Experiment
from hil.identify.intersample import substep_average
from hil.identify.lag import sensor_lags

N_ORDERS = 8
BASE_NAMES = ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod",
              "strain_offset_n", "skew_s", "lag_pressure_s", "lag_strain_s")
#: Nuisance parameters of the baseline: the input's timing skew and the sensors' first-order
#: lags. They are fitted, reported, bounded, and never held for a wide interval.
NUISANCE = ("skew_s", "lag_pressure_s", "lag_strain_s")
_PULS = tuple(
    f"puls{n}_{part}" for n in range(1, N_ORDERS + 1)
    for part in ("flow_s", "flow_c", "torque_s", "torque_c")
)
SAT_CHANNELS = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "f_strain")
#: Pressure channels clipping together: one clip fraction for every pressure channel with a
#: plateau (the sensors share a range; a clip seen on one channel only in the estimation part
#: and on another only in the validation part is still one effect).
SAT_PRESSURE = "sat_pressure"
EFFECT_NAMES = _PULS + (
    "pc_force_n", "sf_coulomb_n", "sf_static_n", "ks_k1", "ks_k2", "visc_coeff_per_c",
    "drift_n_per_c", "delay_s", "pc_eps_m_per_s", "sf_vs_m_per_s", "pc_shape", "sf_shape",
    "sf_eps_m_per_s",
) + tuple(f"sat_{c}" for c in SAT_CHANNELS) + (SAT_PRESSURE,)
PARAM_NAMES = BASE_NAMES + EFFECT_NAMES
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}
N_PARAMS = len(PARAM_NAMES)
#: The parameters the continuous (A, B) depend on.
_LINEAR_IDX = tuple(IDX[k] for k in ("ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod"))

# Indices into the flat effect array the kernel reads.
_E_PULS = 0  # 8 orders x (flow_s, flow_c, torque_s, torque_c)
_E_PC, _E_PC_EPS = 32, 33
_E_SF_C, _E_SF_S, _E_SF_VS, _E_SF_EPS = 34, 35, 36, 37
_E_K1, _E_K2, _E_HALF = 38, 39, 40
_E_VISC = 41
_E_KC_KP = 42
_E_H_SUB = 43
_E_ALPHA = 44  # per-sample gain of the angle complementary filter
_E_PC_SHAPE, _E_SF_SHAPE = 45, 46
_E_SOLVE_TOL = 47  # scale of the friction solves' tolerance (1; tests tighten it)
_N_EFF = 48
#: Crossover of the complementary filter that ties the simulated rotor angle to the
#: measured one: below it the encoder (no drift), above it the simulation (no quantisation).
ANGLE_CROSSOVER_HZ = 10.0


#: Floating-point freedoms of the compiled model: contraction into fused multiply-adds,
#: reciprocals and reassociation (a tenth of a simulation's time), no assumptions about NaN
#: or infinity (the friction solve's bracket tests rely on them).
_FAST = {"contract", "arcp", "nsz", "reassoc"}

#: Simulations a model keeps for a repeated parameter vector, and the memory they may take
#: (a run of 16 s at 5 kHz is 3.2 MB; of a million samples 40 MB, and only one is kept).
RUNS_KEPT = 6
RUNS_BYTES = 64 << 20

_T = TypeVar("_T")
_R = TypeVar("_R")
_POOL: ThreadPoolExecutor | None = None
#: Threads :func:`map_threads` runs on; None: one per core, at most 8
#: (:func:`set_threads`).
_WORKERS: int | None = None


def set_threads(workers: int | None) -> None:
    """Run :func:`map_threads` on ``workers`` threads (1: in the calling thread), None: one
    per core. The results do not depend on it (each item is computed alone); the CPU
    time may (``eha-hil bench identify --threads``)."""
    global _POOL, _WORKERS
    if workers is not None and workers < 1:
        raise ValueError(f"threads must be at least 1, not {workers}")
    _WORKERS = workers
    if _POOL is not None:
        _POOL.shutdown()
        _POOL = None


def map_threads(fn: Callable[[_T], _R], items: Iterable[_T]) -> list[_R]:
    """``[fn(i) for i in items]`` on a thread per core (the simulation kernel drops the GIL)."""
    global _POOL
    items = list(items)
    workers = _WORKERS or min(os.cpu_count() or 1, 8)
    if workers < 2 or len(items) < 2:
        return [fn(i) for i in items]
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=workers)
    return list(_POOL.map(fn, items))


#: Parameters that act on the outputs only, after the simulation (an offset, a gauge's drift,
#: the sensors' lags, the clips): :meth:`FastModel.states` never reads them, so a fit's
#: Jacobian column for one of them maps the same states to new outputs, no simulation.
OUTPUT_ONLY = frozenset({"strain_offset_n", "drift_n_per_c", "lag_pressure_s", "lag_strain_s",
                         SAT_PRESSURE, *(f"sat_{c}" for c in SAT_CHANNELS)})


def channels_moved_by(name: str) -> frozenset[str]:
    """The channels an :data:`OUTPUT_ONLY` parameter changes, as whole sensor-lag groups
    (the pressures share their lag's transform, and a channel filtered alone or among
    them need not round alike)."""
    if name in ("strain_offset_n", "drift_n_per_c", "lag_strain_s", "sat_f_strain"):
        return frozenset({"f_strain"})
    if name == "lag_pressure_s" or name == SAT_PRESSURE or name.startswith("sat_p_"):
        return frozenset(PRESSURE_CHANNELS)
    raise KeyError(name)


def discretise(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation: (A_d, B_d) for step ``h`` s."""
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n] = a
    big[:n, n:] = b
    e = expm(big * h)
    return e[:n, :n].copy(), e[:n, n:].copy()


def continuous(theta: np.ndarray, exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time (A, B) of the linear model for the parameter vector ``theta``."""
    ds, dp, dc, ks, jp, jc = (theta[IDX[k]] for k in ("ds", "dp", "dc", "ks", "jp", "jc"))
    a = np.zeros((5, 5))
    b = np.zeros((5, 4))
    a[0, 1] = 1.0
    a[1, 1] = -dp / jp
    a[1, 2] = -1.0 / jp
    b[1, 0] = 1.0 / jp
    b[1, 1] = 1.0 / jp
    a[2, 1] = ks
    a[2, 2] = -ks / ds
    b[2, 2] = 1.0
    if exp.load != "fixed":
        k_rod = theta[IDX["k_rod"]] if exp.load == "conrod" else 0.0
        c_rod = theta[IDX["c_rod"]] if exp.load == "conrod" else 0.0
        a[2, 4] = -ks
        a[3, 4] = 1.0
        a[4, 2] = 1.0 / jc
        a[4, 3] = -k_rod / jc
        a[4, 4] = -(dc + c_rod) / jc
        b[4, 3] = 1.0 / jc
    return a, b


def _initial_state(a: np.ndarray, b: np.ndarray, u0: np.ndarray, load: str) -> np.ndarray:
    """Equilibrium for the first input (integrators excluded), as the start state."""
    keep = [1, 2] if load == "fixed" else ([1, 2, 4] if load == "free" else [1, 2, 3, 4])
    sub = a[np.ix_(keep, keep)]
    rhs = -(b @ u0)[keep]
    z = np.zeros(5)
    sol, *_ = np.linalg.lstsq(sub, rhs, rcond=None)
    z[keep] = sol
    return z


@njit(cache=True, nogil=True, fastmath=_FAST)
def _friction_sign(u, w):
    """The friction's sign law and its slope: ``(1 - w) tanh(u) + w (2/pi) atan(pi u/2)``.

    Both laws have slope 1 at zero (so ``eps`` keeps its meaning) and reach +-1; tanh does so
    exponentially, atan algebraically (1 - 2/(pi u)): ``w`` in 0..1 is the shape."""
    s = 0.0
    ds = 0.0
    if w != 1.0:  # (a pure atan law is common: its tanh would be a third of the solve)
        # tanh from one exponential (a third of the libm tanh's time; as exact: the
        # exponential of -2|u| has no cancellation, the quotient two roundings)
        t = math.exp(-2.0 * abs(u))
        th = (1.0 - t) / (1.0 + t)
        if u < 0.0:
            th = -th
        s = (1.0 - w) * th
        ds = (1.0 - w) * (1.0 - th * th)
    if w != 0.0:
        q = 0.5 * math.pi * u
        s += w * (2.0 / math.pi) * math.atan(q)
        ds += w / (1.0 + q * q)
    return s, ds


#: Bounds of the sign law's curvature behind the solve's early return (:func:`_solve_friction`,
#: checked in tests/identify/test_friction_solve.py): ``|s''(u')| <= SIGN_CURVATURE s'(u')``
#: for every shape (tanh: 2 |tanh| sech^2 <= 2 sech^2; atan: pi |q| / (1 + q^2) <= pi/2), and
#: within ``NEAR`` of ``u`` the slope ``s'`` and the Stribeck factor ``exp(-q^2)`` grow by at
#: most ``NEAR_GROWTH`` (sech^2 by exp(2 NEAR) = 1.105, 1/(1 + q^2) by 1.082, exp(-q^2) by
#: exp(2 |q| NEAR + NEAR^2) <= 1.108 where |q| NEAR <= NEAR).
SIGN_CURVATURE = 2.0
NEAR = 0.05
NEAR_GROWTH = 1.11


@njit(cache=True, nogil=True, fastmath=_FAST)
def _solve_friction(v_free, b, level_c, level_s, vs, eps, w, f_start, tol_scale):
    """Root v of v = v_free - b * F(v), F(v) = (Fc + (Fs - Fc) exp(-(v/vs)^2)) s(v/eps, w)
    with the sign law ``s`` of :func:`_friction_sign`.

    Newton steps from the velocity the force ``f_start`` gives (the caller extrapolates the
    last two sub-steps' forces: the force changes smoothly over 50 us), kept inside the
    bracket [v_free - b Fmax, v_free + b Fmax] by bisection. It accepts a ``v`` whose
    residual ``g(v) = v - v_free + b F(v)`` is below ``tol = 1e-13 + 1e-10 |v_free|``
    (times ``tol_scale``, 1 but in tests), and
    returns early with the force linearised along a Newton step ``d = g/g'`` when that step
    lands below ``tol`` for sure: ``|g(v - d)| <= b/2 max|F''| d^2``, with ``F''``
    bounded near ``v`` from the slope and the Stribeck factor just computed
    (:data:`SIGN_CURVATURE`, :data:`NEAR_GROWTH`), so an early return meets the same
    ``|g| <= tol`` as an evaluated one (and saves that evaluation). A step below 1e-6 eps
    is taken linearised as well (1e-12 of the level off). Returns (v, F(v)).
    """
    fmax = max(abs(level_c), abs(level_s))
    lo = v_free - b * fmax - 1e-15
    hi = v_free + b * fmax + 1e-15
    v = min(max(v_free - b * f_start, lo), hi)
    tol = tol_scale * (1e-13 + 1e-10 * abs(v_free))
    dl = abs(level_s - level_c)
    half_b = 0.5 * abs(b)
    for _ in range(60):
        e = 0.0
        q = 0.0
        if vs > 0.0:
            q = v / vs
            e = math.exp(-q * q)
            lev = level_c + (level_s - level_c) * e
        else:
            lev = level_c
        th, dth = _friction_sign(v / eps, w)
        g = v - v_free + b * lev * th
        if abs(g) < tol:
            return v, lev * th
        if g > 0.0:
            hi = v
        else:
            lo = v
        df = lev * dth / eps
        if vs > 0.0:
            df += th * (level_s - level_c) * e * (-2.0 * q / vs)
        dg = 1.0 + b * df
        if dg > 0.0:
            step = abs(g / dg)
            if step <= 1e-6 * eps:
                return v - g / dg, lev * th - df * g / dg
            if step <= NEAR * eps:
                # |F''| within the step: the sign law's part, then the Stribeck level's
                # (|L| <= Fmax, |L'| <= dl 2|q'|e'/vs, |L''| <= dl (4q'^2 + 2) e'/vs^2)
                fpp = fmax * (SIGN_CURVATURE * NEAR_GROWTH) * dth / (eps * eps)
                if vs > 0.0 and dl > 0.0:
                    qa = abs(q) + NEAR
                    if step * max(1.0, abs(q)) <= NEAR * vs:
                        fpp += dl * NEAR_GROWTH * e * ((4.0 * qa * qa + 2.0) / (vs * vs)
                                                       + 4.0 * qa / (vs * eps))
                    else:
                        fpp = math.inf
                if half_b * fpp * step * step <= tol:
                    return v - g / dg, lev * th - df * g / dg
        vn = v - g / dg if dg > 0.0 else 0.5 * (lo + hi)
        if not (lo < vn < hi):
            vn = 0.5 * (lo + hi)
        v = vn
    if vs > 0.0:
        q = v / vs
        lev = level_c + (level_s - level_c) * math.exp(-q * q)
    else:
        lev = level_c
    return v, lev * _friction_sign(v / eps, w)[0]


@njit(cache=True, nogil=True, fastmath=_FAST)
def _simulate(ad, bd, z0, tau_p, ks, ds, dp, dc, eff, angle, has_angle, xs, has_x, temp,
              has_temp, t_ref, n_sub, fixed, out, adh, bdh):
    """Run the model over ``out.shape[0]`` samples; ``out[k]`` gets the state at sample ``k``.

    ``tau_p`` holds one value per sub-step; ``angle``, ``xs``, ``temp`` one per sample. The
    pulsation terms use the simulated rotor angle plus an offset that tracks the measured
    angle with the first-order gain ``alpha`` per sample. With the piston fixed only the
    first three states move, and only they are propagated. The harmonics n = 1..8 of the
    rotor angle come from one sine and cosine by the angle-addition recurrence.

    ``adh, bdh``: the linear part over half a sub-step, where the seal friction is solved
    (implicit midpoint; the pump friction is solved at the sub-step's end).
    """
    n = out.shape[0]
    ns = 3 if fixed else 5
    z = z0.copy()
    zn = np.zeros(5)
    u = np.zeros(4)
    n_ord = 0
    for m in range(8):
        for i in range(4):
            if eff[_E_PULS + 4 * m + i] != 0.0:
                n_ord = m + 1
    pc = eff[_E_PC]
    sf_c = eff[_E_SF_C]
    sf_s = eff[_E_SF_S]
    sf_on = (sf_c != 0.0 or sf_s != 0.0) and not fixed
    k1 = eff[_E_K1]
    k2 = eff[_E_K2]
    ksx_on = k1 != 0.0 or k2 != 0.0
    visc = eff[_E_VISC]
    kc_kp = eff[_E_KC_KP]
    half = eff[_E_HALF]
    h_sub = eff[_E_H_SUB]
    alpha = eff[_E_ALPHA]
    solve_tol = eff[_E_SOLVE_TOL]
    # the pump's, the series compliance's and the piston's effect inputs (u[1:]) stay zero
    # without a pulsation, a position-dependent k_s or a viscosity law: their columns of
    # the input product are skipped (adding their zero products changes no bit; a linear
    # model's sub-step is a fifth cheaper, a friction model's a tenth)
    inputs_on = n_ord > 0 or ksx_on or (visc != 0.0 and has_temp)
    offset = angle[0] - z[0] * kc_kp if has_angle else 0.0
    # the frictions' forces of the last two sub-steps: their next solves start from the
    # straight line through them (1.7 -> 1.0 and 1.9 -> 1.4 evaluations per sub-step of the
    # pump's and the seal's law, with the solve's early return, than from the last force)
    fp = 0.0
    fs = 0.0
    fp_prev = 0.0
    fs_prev = 0.0
    for k in range(n):
        for i in range(5):
            out[k, i] = z[i]
        if k == n - 1:
            break
        r = 1.0
        if visc != 0.0 and has_temp:
            r = math.exp(-visc * (temp[k] - t_ref))
        for j in range(n_sub):
            vp = z[1]
            tq = z[2]
            vc = z[4]
            f_pump = 0.0
            f_pist = 0.0
            g = 1.0
            if n_ord > 0:
                # rotor angle at the sub-step's midpoint: simulated, plus the slowly
                # tracked offset to the measured angle (complementary filter)
                th = (z[0] + 0.5 * h_sub * vp) * kc_kp + offset
                s1 = math.sin(th)
                c1 = math.cos(th)
                s = s1
                c = c1
                ripple = 0.0
                torque = 0.0
                for m in range(n_ord):
                    base = _E_PULS + 4 * m
                    ripple += eff[base] * s + eff[base + 1] * c
                    torque += eff[base + 2] * s + eff[base + 3] * c
                    s, c = s * c1 + c * s1, c * c1 - s * s1
                g = 1.0 + ripple
                f_pump -= ripple * tq + torque
            if r != 1.0:
                f_pump -= dp * (r - 1.0) * vp
                f_pist -= dc * (r - 1.0) * vc
            ks_eff = ks
            if ksx_on or g != 1.0 or r != 1.0:
                if ksx_on:
                    # Eq. 2.25-2.27: the series compliance is exactly quadratic in x
                    xpos = xs[k] if has_x else z[3]
                    xn = xpos / half
                    ks_eff = ks / max(1.0 + k1 * xn + k2 * xn * xn, 0.05)
                q_rate = ks_eff * (g * vp - tq / (ds * r) - vc) - ks * (vp - tq / ds - vc)
            else:
                q_rate = 0.0
            u[0] = tau_p[k * n_sub + j]
            u[1] = f_pump
            u[2] = q_rate
            u[3] = f_pist
            for i in range(ns):
                acc = 0.0
                for m in range(ns):
                    acc += ad[i, m] * z[m]
                acc += bd[i, 0] * u[0]
                if inputs_on:
                    for m in range(1, 4):
                        acc += bd[i, m] * u[m]
                zn[i] = acc
            dq = 0.0
            if ksx_on:
                # the stiffness term is a sizeable part of k_s acting at the piston's
                # resonance: held from the sub-step's start it is a first-order step that
                # detunes the resonance (6 % of its response at 50 us); the trapezoid of its
                # values at both ends (Heun's predictor-corrector) makes it second order
                q_end = (ks_eff * (g * zn[1] - zn[2] / (ds * r) - zn[4])
                         - ks * (zn[1] - zn[2] / ds - zn[4]))
                dq = 0.5 * (q_end - q_rate)
                for i in range(ns):
                    zn[i] += bd[i, 2] * dq
            if pc != 0.0:
                f_start = 2.0 * fp - fp_prev
                fp_prev = fp
                vnew, fp = _solve_friction(zn[1], bd[1, 1], pc, pc, 0.0, eff[_E_PC_EPS],
                                           eff[_E_PC_SHAPE], f_start, solve_tol)
                for i in range(ns):
                    zn[i] -= bd[i, 1] * fp
            if sf_on:
                # The seal's force held over the sub-step is its law's value at the
                # sub-step's middle (implicit midpoint, second order), not at its end
                # (implicit Euler, first order). With the piston held by a stiff rod its
                # speed stays in the seal's stuck zone and Stribeck dip, where the law is a
                # damper of F_s/eps (~2e4 N s/m on J_c ~0.3 kg: a time constant of a third
                # of the sub-step), and the end value's lag there moved the piston's speed by
                # a third of its rms against a fine-step solve of the same law.
                vmid = -bdh[4, 1] * fp
                for m in range(ns):
                    vmid += adh[4, m] * z[m]
                vmid += bdh[4, 0] * u[0]
                if inputs_on:
                    for m in range(1, 4):
                        vmid += bdh[4, m] * u[m]
                if ksx_on:  # the Heun correction's rate grows linearly over the sub-step
                    vmid += bdh[4, 2] * 0.5 * dq
                f_start = 2.0 * fs - fs_prev
                fs_prev = fs
                vnew, fs = _solve_friction(vmid, bdh[4, 3], sf_c, sf_s, eff[_E_SF_VS],
                                           eff[_E_SF_EPS], eff[_E_SF_SHAPE], f_start,
                                           solve_tol)
                for i in range(ns):
                    zn[i] -= bd[i, 3] * fs
            for i in range(ns):
                z[i] = zn[i]
        if has_angle:
            offset += alpha * (angle[k + 1] - z[0] * kc_kp - offset)


PRESSURE_CHANNELS = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b")


def fast_stop(n_stop: int, size: int) -> int:
    """The first sample count ``>= n_stop`` (at most ``size``) whose even extension the FFT
    transforms fast: ``2 n`` with small prime factors only. The sensor lags transform
    ``2 n_stop`` samples, and a count with a large prime factor (a fit's iterations stop
    at 30,501 samples: 61,002 = 2 x 3^2 x 3389) takes the FFT's slow general-length path,
    25x the time of a nearby smooth one and more than the simulation itself. Simulating
    the few samples more costs under 1 %; the samples before ``n_stop`` move by the
    filter's reach from the record's reflected end, far below the sensors' noise."""
    m = next_fast_len(2 * n_stop, real=True)
    while m % 2:
        m = next_fast_len(m + 1, real=True)
    return min(m // 2, size)


class FastModel:
    """Simulates an :class:`Experiment` for a parameter vector and maps states to channels."""

    #: Scale of the friction solves' tolerance (:func:`_solve_friction`); tests tighten it.
    solve_tol = 1.0

    def __init__(self, exp: Experiment, n_sub: int | None = None) -> None:
        self.exp = exp
        if n_sub is None:
            n_sub = max(1, int(math.ceil(exp.dt / 50e-6 - 1e-9)))
        self.n_sub = n_sub
        self._iq_sub0 = np.repeat(exp.iq, n_sub)
        self._input_cache: dict[tuple[str, float], np.ndarray] = {}
        # the applied force per sub-step, by gain and delay: a Jacobian's columns but the
        # gain's and the timing's share it (a product of n * n_sub values each simulation
        # made afresh was a tenth of a linear run's CPU)
        self._force_cache: dict[tuple[float, float, float], np.ndarray] = {}
        self._disc_cache: dict[tuple[float, ...], tuple[np.ndarray, ...]] = {}
        self._start_cache: dict[tuple[float, ...], np.ndarray] = {}
        self._empty = np.zeros(1)
        # the last few simulations, by parameter vector: a fit simulates the same vector
        # again (the weights' residual after a pass, then the step on all samples starting
        # there; the fit's states at the end), and a head of a longer run is that run's head
        self._runs: dict[tuple[bytes, float], tuple[int, np.ndarray]] = {}
        self._runs_lock = threading.Lock()

    def start_vector(self) -> np.ndarray:
        """Parameter vector at the preset's values, every effect off."""
        theta = np.zeros(N_PARAMS)
        for k, v in self.exp.start.items():
            theta[IDX[k]] = v
        return theta

    def applied_current(self, delay_s: float) -> np.ndarray:
        """The logged current as applied ``delay_s`` later (negative: a timing skew the other
        way), averaged over each sub-step, interpolated between samples as the experiment's
        intersample behaviour says (:mod:`hil.identify.intersample`), A."""
        mode = self.exp.intersample
        if delay_s == 0.0 and mode == "zoh":
            return self._iq_sub0
        key = (mode, float(delay_s))
        hit = self._input_cache.get(key)
        if hit is None:
            if len(self._input_cache) > 64:  # a fit visits many delays; keep memory bounded
                self._input_cache.clear()
            hit = substep_average(self.exp.iq, self.exp.dt, self.n_sub, delay_s, mode)
            self._input_cache[key] = hit
        return hit

    def _applied_force(self, gain: float, delay_s: float) -> np.ndarray:
        """``gain`` times :meth:`applied_current` ``(delay_s)``, N per sub-step, the last
        few kept (the same product, so the same bits; the sign of a zero gain kept apart)."""
        key = (float(gain), math.copysign(1.0, gain), float(delay_s))
        hit = self._force_cache.get(key)
        if hit is None:
            if len(self._force_cache) >= 4:  # 2.6 MB each on a 16 s, 5 kHz record
                self._force_cache.clear()
            hit = gain * self.applied_current(delay_s)
            self._force_cache[key] = hit
        return hit

    def states(self, theta: np.ndarray, n_stop: int | None = None, keep: bool = True
               ) -> np.ndarray:
        """State trajectory (n x 5) for the parameter vector ``theta``, read-only; with
        ``n_stop`` only the first ``n_stop`` samples are simulated (the rest is zero, or the
        rest of a longer run of the same vector that is still kept: the simulation is
        causal, so a run's head is the shorter run, bit for bit). ``keep=False``: a vector
        no one asks for again (a Jacobian column's) is not kept, so it evicts no run that
        may be asked for (a fit's point, its cost compared later)."""
        n_run = self.exp.n if n_stop is None else max(2, min(n_stop, self.exp.n))
        key = (theta.tobytes(), self.solve_tol)
        hit = self._runs.get(key)
        if hit is not None and hit[0] >= n_run:
            return hit[1]
        out = self._simulate_states(theta, n_stop)
        out.setflags(write=False)
        if not keep:
            return out
        with self._runs_lock:
            self._runs[key] = (n_run, out)
            while len(self._runs) > 1 and (
                    len(self._runs) > RUNS_KEPT
                    or sum(r[1].nbytes for r in self._runs.values()) > RUNS_BYTES):
                del self._runs[next(iter(self._runs))]
        return out

    def kernel_inputs(self, theta: np.ndarray) -> tuple[np.ndarray, ...]:
        """What the simulation kernel takes for ``theta`` besides the record: the linear
        part discretised over a sub-step and over half of one ``(ad, bd, adh, bdh)``, the
        start state, the applied force per sub-step and the flat effect array."""
        exp = self.exp
        h = exp.dt / self.n_sub
        # Jacobian columns of effect parameters share the linear part: discretise it once
        key = tuple(float(theta[i]) for i in _LINEAR_IDX)
        hit = self._disc_cache.get(key)
        if hit is None:
            if len(self._disc_cache) > 64:
                self._disc_cache.clear()
            a, b = continuous(theta, exp)
            # the full sub-step, and its first half (where the seal's friction is solved)
            hit = self._disc_cache[key] = discretise(a, b, h) + discretise(a, b, 0.5 * h)
        ad, bd, adh, bdh = hit
        tau_p = self._applied_force(theta[IDX["gain_n_per_a"]],
                                    theta[IDX["delay_s"]] + theta[IDX["skew_s"]])
        # and the start state, for the same linear part and first input (a least-squares
        # solve, a tenth of a linear run's CPU; the sign of a zero input kept apart)
        z0_key = (*key, float(tau_p[0]), math.copysign(1.0, tau_p[0]))
        z0 = self._start_cache.get(z0_key)
        if z0 is None:
            if len(self._start_cache) > 64:
                self._start_cache.clear()
            a, b = continuous(theta, exp)
            u0 = np.array([tau_p[0], 0.0, 0.0, 0.0])
            z0 = self._start_cache[z0_key] = _initial_state(a, b, u0, exp.load)
        return ad, bd, adh, bdh, z0, tau_p, self.effect_array(theta)

    def effect_array(self, theta: np.ndarray) -> np.ndarray:
        """The flat effect array the simulation kernel reads, for ``theta``."""
        exp = self.exp
        h = exp.dt / self.n_sub
        eff = np.zeros(_N_EFF)
        eff[:32] = theta[IDX["puls1_flow_s"]: IDX["puls1_flow_s"] + 32]
        eff[_E_PC] = theta[IDX["pc_force_n"]]
        # the friction laws' shape velocities: fitted once the friction is in, else the preset's
        eff[_E_PC_EPS] = theta[IDX["pc_eps_m_per_s"]] or exp.const.eps_pump
        eff[_E_SF_C] = theta[IDX["sf_coulomb_n"]]
        eff[_E_SF_S] = theta[IDX["sf_static_n"]]
        eff[_E_SF_VS] = theta[IDX["sf_vs_m_per_s"]] or exp.const.vs_seal
        eff[_E_SF_EPS] = theta[IDX["sf_eps_m_per_s"]] or exp.const.eps_seal
        eff[_E_PC_SHAPE] = theta[IDX["pc_shape"]]
        eff[_E_SF_SHAPE] = theta[IDX["sf_shape"]]
        eff[_E_K1] = theta[IDX["ks_k1"]]
        eff[_E_K2] = theta[IDX["ks_k2"]]
        eff[_E_HALF] = exp.const.half_stroke
        eff[_E_VISC] = theta[IDX["visc_coeff_per_c"]]
        eff[_E_KC_KP] = exp.const.rotor_per_m
        eff[_E_H_SUB] = h
        eff[_E_ALPHA] = 1.0 - math.exp(-2.0 * math.pi * ANGLE_CROSSOVER_HZ * exp.dt)
        eff[_E_SOLVE_TOL] = self.solve_tol
        return eff

    def _simulate_states(self, theta: np.ndarray, n_stop: int | None) -> np.ndarray:
        exp = self.exp
        ad, bd, adh, bdh, z0, tau_p, eff = self.kernel_inputs(theta)
        out = np.zeros((exp.n, 5))
        e = self._empty
        sim = out if n_stop is None else out[: max(2, min(n_stop, exp.n))]
        _simulate(ad, bd, z0, tau_p, theta[IDX["ks"]], theta[IDX["ds"]], theta[IDX["dp"]],
                  theta[IDX["dc"]], eff,
                  exp.angle if exp.angle is not None else e, exp.angle is not None,
                  exp.position if exp.position is not None else e, exp.position is not None,
                  exp.temperature if exp.temperature is not None else e,
                  exp.temperature is not None, exp.t_ref, self.n_sub, exp.load == "fixed", sim,
                  adh, bdh)
        return out

    def outputs(self, theta: np.ndarray, z: np.ndarray | None = None,
                n_stop: int | None = None, channels: frozenset[str] | None = None
                ) -> dict[str, np.ndarray]:
        """Model channels (same names and units as :attr:`Experiment.measured`); with
        ``n_stop``, only the first :func:`fast_stop` ``(n_stop)`` samples (the arrays have
        that length: a fit's iterations compare a head of the record, and every output is
        causal in the states, so the head's values are those of the whole record's); with
        ``channels``, only those (each with the same bits as among all channels, given as
        whole :func:`channels_moved_by` groups, whose sensors are filtered together)."""
        exp = self.exp
        n = exp.n
        if n_stop is not None:
            n_stop = fast_stop(n_stop, exp.n)
            n = max(2, min(n_stop, exp.n))
        if z is None:
            z = self.states(theta, n_stop)
        z = z[:n]
        temperature = exp.temperature[:n] if exp.temperature is not None else None
        c = exp.const
        tq = z[:, 2]
        vc = z[:, 4]
        dc = theta[IDX["dc"]]
        if temperature is not None and theta[IDX["visc_coeff_per_c"]] != 0.0:
            dc = dc * np.exp(-theta[IDX["visc_coeff_per_c"]] * (temperature - exp.t_ref))
        # with the piston held the cylinder sees the pump's pressures: the same arrays, which
        # the sensor lag below then filters once
        f_cyl = tq if exp.load == "fixed" else tq - dc * vc
        if exp.load == "fixed":
            f_rod = f_cyl
        elif exp.load == "conrod":
            f_rod = theta[IDX["k_rod"]] * z[:, 3] + theta[IDX["c_rod"]] * vc
        else:
            f_rod = np.zeros_like(tq)
        out: dict[str, np.ndarray] = {}
        pre = exp.precharge
        sides: dict[tuple[int, float], np.ndarray] = {}

        def side(force: np.ndarray, sign: float) -> np.ndarray:
            key = (id(force), sign)
            if key not in sides:
                # pre + max(sign force, 0) / k_c, in one array (a simulation's outputs are a
                # fifth of its time)
                y = np.maximum(force, 0.0) if sign > 0 else np.negative(force)
                if sign < 0:
                    np.maximum(y, 0.0, out=y)
                y /= c.kc
                y += pre
                sides[key] = y
            return sides[key]

        for ch in exp.channels:
            if channels is not None and ch not in channels:
                continue
            if ch == "p_pump_a":
                y = side(tq, 1.0)
            elif ch == "p_pump_b":
                y = side(tq, -1.0)
            elif ch == "p_cyl_a":
                y = side(f_cyl, 1.0)
            elif ch == "p_cyl_b":
                y = side(f_cyl, -1.0)
            elif ch == "f_strain":
                y = f_rod + theta[IDX["strain_offset_n"]]
                drift = theta[IDX["drift_n_per_c"]]
                if drift != 0.0 and temperature is not None:
                    # the gauge drifts with temperature: against the logged covariate,
                    # whatever its shape over time
                    y = y + drift * (temperature - exp.t_ref)
            elif ch == "omega_m":
                y = exp.window_diff(z[:, 0] * c.rotor_per_m)
            elif ch == "v_piston":
                y = exp.window_diff(z[:, 3])
            else:  # pragma: no cover - channels come from prepare()
                raise KeyError(ch)
            out[ch] = y
        # the sensors' lags, channels sharing one filtered together
        for names, lag in ((PRESSURE_CHANNELS, theta[IDX["lag_pressure_s"]]),
                           (("f_strain",), theta[IDX["lag_strain_s"]])):
            lagged = [ch for ch in names if ch in out]
            if lag > 0.0 and lagged:
                distinct = list({id(out[ch]): out[ch] for ch in lagged}.values())
                done = dict(zip((id(y) for y in distinct),
                                sensor_lags(distinct, lag, exp.dt, n_stop), strict=True))
                for ch in lagged:
                    out[ch] = done[id(out[ch])]
        for ch in out:
            if ch in SAT_CHANNELS:
                beta = theta[IDX[f"sat_{ch}"]]
                if ch in PRESSURE_CHANNELS:
                    beta += theta[IDX[SAT_PRESSURE]]
                level = exp.plateaus.get(ch)
                if beta != 0.0 and level is not None:
                    out[ch] = out[ch] + beta * (np.minimum(out[ch], level) - out[ch])
        return out


__all__ = ["BASE_NAMES", "EFFECT_NAMES", "OUTPUT_ONLY", "FastModel", "IDX", "N_PARAMS",
           "PARAM_NAMES", "continuous", "discretise", "fast_stop", "map_threads", "set_threads"]
