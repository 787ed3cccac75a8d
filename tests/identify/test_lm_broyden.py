"""Broyden updates in the Levenberg-Marquardt: the same minimum with fewer Jacobians, the
Jacobian returned exact at the returned point, and an exact Jacobian deciding what an
update's step cannot (a refused step, a gain small enough to end the pass)."""

from __future__ import annotations

import numpy as np

from hil.identify import fit

T = np.linspace(0.0, 4.0, 4000)
SIGMA = 0.01
START = np.array([1.0, 0.5, 1.5, 0.22])
LO, HI = np.full(4, -10.0), np.full(4, 10.0)


def _curve(p: np.ndarray) -> np.ndarray:
    return p[0] * np.exp(-p[1] * T) + p[2] * np.sin(2.0 * np.pi * p[3] * T)


def _problem(seed: int = 3):
    """A decay plus a sine of unknown frequency, white noise of variance 1 once weighted:
    the residual, its Jacobian and the points each was called at."""
    rng = np.random.default_rng(seed)
    y = _curve(np.array([2.0, 1.3, 0.7, 0.25])) + SIGMA * rng.standard_normal(T.size)
    calls: dict[str, list[np.ndarray]] = {"fun": [], "jac": []}

    def fun(x: np.ndarray) -> np.ndarray:
        calls["fun"].append(x.copy())
        return (y - _curve(x)) / SIGMA

    def jac(x: np.ndarray) -> np.ndarray:
        calls["jac"].append(x.copy())
        e = np.exp(-x[1] * T)
        w = 2.0 * np.pi * T
        return -np.column_stack([e, -x[0] * T * e, np.sin(w * x[3]),
                                 x[2] * w * np.cos(w * x[3])]) / SIGMA

    return fun, jac, calls


def _fit(updates: int):
    fun, jac, calls = _problem()
    x, r, j, converged = fit.levenberg_marquardt(fun, jac, START, LO, HI, max_jac=40,
                                                 updates=updates)
    return x, float(r @ r), j, converged, calls, jac


def test_updates_reach_the_same_minimum_with_fewer_jacobians():
    x0, cost0, _, conv0, calls0, _ = _fit(0)
    x2, cost2, j2, conv2, calls2, jac = _fit(2)
    assert conv0 and conv2
    # the same minimum: within one residual variance (the stop's own tolerance) in cost,
    # and within a tenth of a standard error in every parameter
    assert abs(cost2 - cost0) <= cost0 / T.size
    se = np.sqrt(np.diag(np.linalg.inv(j2.T @ j2)))
    assert np.all(np.abs(x2 - x0) < 0.1 * se)
    assert len(calls2["jac"]) < len(calls0["jac"])
    # the Jacobian returned is the exact one at the returned point (the covariance's)
    np.testing.assert_array_equal(calls2["jac"][-1], x2)
    np.testing.assert_array_equal(j2, jac(x2))


def test_a_refused_step_from_a_bad_update_is_retried_from_an_exact_jacobian(monkeypatch):
    # every update points uphill: each step from one is refused
    monkeypatch.setattr(fit, "_broyden", lambda j, dx, dr, d: -j)
    _, cost0, _, _, _, _ = _fit(0)
    x, cost, j, converged, calls, jac = _fit(2)
    assert converged
    assert abs(cost - cost0) <= cost0 / T.size  # it still reaches the minimum
    np.testing.assert_array_equal(j, jac(x))


def test_a_small_gain_from_an_update_does_not_end_the_pass(monkeypatch):
    # every update a thousand times too steep: its steps a thousandth of the right ones,
    # each gaining too little to count; only an exact Jacobian may end the pass there
    monkeypatch.setattr(fit, "_broyden", lambda j, dx, dr, d: 1e3 * j)
    _, cost0, _, _, _, _ = _fit(0)
    x, cost, j, converged, calls, jac = _fit(2)
    assert converged
    assert abs(cost - cost0) <= cost0 / T.size
    np.testing.assert_array_equal(j, jac(x))
