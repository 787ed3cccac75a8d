"""The fast model's implicit friction solve: its early return keeps the solve's tolerance.

The solve (``hil.identify.model._solve_friction``) accepts a velocity whose residual
``g(v) = v - v_free + b F(v)`` is below ``tol = 1e-13 + 1e-10 |v_free|``, or returns one
Newton step early, linearised, when a bound on ``F''`` says that step lands below ``tol``.
Checked here against an independent root (scipy's ``brentq``) and an independent evaluation
of the friction law, and the bound's constants against the laws themselves.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from hil.identify import model
from hil.identify.model import NEAR, NEAR_GROWTH, SIGN_CURVATURE, _solve_friction


def _sign(u: float, w: float) -> float:
    return (1.0 - w) * math.tanh(u) + w * (2.0 / math.pi) * math.atan(0.5 * math.pi * u)


def _force(v: float, fc: float, fs: float, vs: float, eps: float, w: float) -> float:
    level = fc + (fs - fc) * math.exp(-(v / vs) ** 2) if vs > 0.0 else fc
    return level * _sign(v / eps, w)


def _slope(u: np.ndarray, w: float) -> np.ndarray:
    q = 0.5 * np.pi * u
    return (1.0 - w) / np.cosh(u) ** 2 + w / (1.0 + q * q)


def _curvature(u: np.ndarray, w: float) -> np.ndarray:
    q = 0.5 * np.pi * u
    return (1.0 - w) * (-2.0 * np.tanh(u) / np.cosh(u) ** 2) - w * np.pi * q / (1.0 + q * q) ** 2


@pytest.mark.parametrize("w", [0.0, 0.3, 0.55, 1.0])
def test_sign_law_curvature_and_growth_bounds(w):
    """|s''| <= SIGN_CURVATURE s' everywhere, and s' grows by at most NEAR_GROWTH within
    NEAR of any point: the early return's bound on the sign law."""
    u = np.linspace(-40.0, 40.0, 160_001)
    s1 = _slope(u, w)
    assert np.all(np.abs(_curvature(u, w)) <= SIGN_CURVATURE * s1 * (1 + 1e-12) + 1e-300)
    for du in np.linspace(-NEAR, NEAR, 11):
        grown = _slope(u + du, w)
        ok = grown <= NEAR_GROWTH * s1 * (1 + 1e-12)
        assert ok.all(), (du, u[~ok][:3])


def test_stribeck_factor_growth_bound():
    """exp(-q'^2) <= NEAR_GROWTH exp(-q^2) for |q' - q| max(1, |q|) <= NEAR."""
    q = np.linspace(-30.0, 30.0, 60_001)
    for f in np.linspace(-1.0, 1.0, 11):
        dq = f * NEAR / np.maximum(1.0, np.abs(q))
        lhs = -((q + dq) ** 2)
        rhs = math.log(NEAR_GROWTH) - q * q
        assert np.all(lhs <= rhs + 1e-9)


def _cases(n: int, seed: int):
    """Random solves over sticking, the Stribeck dip and sliding: (v_free, b, Fc, Fs, vs,
    eps, w, f_start), with starts from the root's own force moved a little or a lot."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        eps = 10.0 ** rng.uniform(-4.0, -2.0)
        vs = 0.0 if rng.random() < 0.3 else 10.0 ** rng.uniform(-4.5, -2.0)
        fc = rng.uniform(5.0, 100.0)
        fs = fc * rng.uniform(0.3, 2.0) if vs > 0.0 else fc
        w = float(rng.choice([0.0, 1.0, rng.uniform()]))
        b = 10.0 ** rng.uniform(-7.0, -4.0)
        v_free = rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-6.0, -1.0)
        yield v_free, b, fc, fs, vs, eps, w


def test_solve_meets_its_tolerance_against_an_independent_root():
    """Every return (evaluated or early) meets |g| <= tol (the old 1e-6 eps linearised step
    within its own 1e-12 of the level), its force agrees with the law at the returned
    velocity, and the velocity is the root's."""
    checked = 0
    rng = np.random.default_rng(5)
    for v_free, b, fc, fs, vs, eps, w in _cases(2500, 3):
        fmax = max(fc, fs)

        def g(v, v_free=v_free, b=b, fc=fc, fs=fs, vs=vs, eps=eps, w=w):
            return v - v_free + b * _force(v, fc, fs, vs, eps, w)

        lo, hi = v_free - b * fmax - 1e-15, v_free + b * fmax + 1e-15
        if g(lo) * g(hi) > 0.0:
            continue
        root = brentq(g, lo, hi, xtol=1e-300, rtol=8.9e-16, maxiter=500)
        f_root = _force(root, fc, fs, vs, eps, w)
        for rel in (0.0, 1e-9, 1e-6, 1e-3, 0.1):
            f_start = f_root * (1.0 + rel * rng.normal())
            v, f = _solve_friction(v_free, b, fc, fs, vs, eps, w, f_start, 1.0)
            tol = 1e-13 + 1e-10 * abs(v_free)
            # the 1e-6 eps linearised step is off by up to b/2 max|F''| (1e-6 eps)^2
            fpp = fmax * 2.0 / eps**2 + (
                abs(fs - fc) * (2.5 / vs**2 + 1.8 / (vs * eps)) if vs > 0.0 else 0.0)
            allow = tol * (1.0 + 1e-6) + 0.5 * b * fpp * (1e-6 * eps) ** 2
            assert abs(g(v)) <= allow, (v_free, b, fc, fs, vs, eps, w, rel, g(v), tol)
            assert abs(b * (f - _force(v, fc, fs, vs, eps, w))) <= allow
            slope = 1.0 + b * (_force(root + 1e-3 * eps, fc, fs, vs, eps, w)
                               - _force(root - 1e-3 * eps, fc, fs, vs, eps, w)) / (2e-3 * eps)
            if slope > 0.5:
                assert abs(v - root) <= 4.0 * allow / slope + 1e-15
            checked += 1
    assert checked > 6_000


def test_simulation_with_both_frictions_stays_near_a_tighter_solve():
    """The whole model with both frictions against itself with the solves' tolerance a
    hundred times tighter: the states agree to 4e-8 of their spread (far below what a fit
    resolves), and the tolerance does act (the two differ). The seal's solve is at the
    sub-step's middle: an error there reaches the force held over the whole sub-step with a
    gain of up to 2 (its end-of-step solve damped it by 1/(1 + h F'/J_c), ~0.26 here), so a
    stuck piston's states move by up to 1.6e-8 of their spread here (within 1e-8 with the
    end-of-step solve)."""
    from hil.identify.experiment import prepare
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    rig = generate_rig("free_piston", ["pump_coulomb_friction", "seal_friction"], seconds=0.6,
                       seed=2)
    fm = model.FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))
    theta = fm.start_vector()
    for k, v in (("pc_force_n", 80.0), ("pc_shape", 0.6), ("sf_coulomb_n", 20.0),
                 ("sf_static_n", 35.0), ("sf_shape", 0.0)):
        theta[model.IDX[k]] = v
    z = fm.states(theta)
    fm.solve_tol = 0.01
    z_ref = fm.states(theta)
    spread = np.ptp(z_ref, axis=0)
    assert np.all(np.isfinite(z)) and np.all(spread[1:] > 0.0)
    assert np.all(np.abs(z - z_ref) <= 4e-8 * spread)
    assert not np.array_equal(z, z_ref)
