"""A Levenberg-Marquardt pass ends at the first accepted step that lowers the cost by no more
than :data:`~hil.identify.fit.CONVERGED_GAIN` residual variances, and not before (steps from
exact Jacobians: a step from a Broyden update that gains that little is judged by an exact
Jacobian first, tests/identify/test_lm_broyden.py)."""

from __future__ import annotations

import numpy as np

from hil.identify import fit


def test_a_pass_stops_at_the_first_step_below_the_gain_and_not_before():
    rng = np.random.default_rng(5)
    noise = rng.standard_normal(4000)  # the residual's variance: about 1
    weights = rng.uniform(0.5, 1.5, noise.size)
    # a root of multiplicity five: Gauss-Newton steps reach it linearly, each shrinking the
    # excess cost by about e^2, so the gains run from 1e6 variances down through the
    # threshold a few steps apart (a simple root's quadratic steps would jump past it)
    scale = 30.0
    costs: list[float] = []

    def fun(x: np.ndarray) -> np.ndarray:
        r = noise + scale * weights * x[0] ** 5
        costs.append(float(r @ r))
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        return (scale * weights * 5.0 * x[0] ** 4)[:, None]

    x, r, _, converged = fit.levenberg_marquardt(fun, jac, np.array([2.0]), np.array([-10.0]),
                                                 np.array([10.0]), max_jac=40,
                                                 updates=0)
    # the accepted steps: each cost lower than every one before it
    accepted = [costs[0]]
    for c in costs[1:]:
        if c < accepted[-1]:
            accepted.append(c)
    gains = -np.diff(accepted)
    limits = fit.CONVERGED_GAIN * np.array(accepted[1:]) / r.size
    assert converged and len(gains) >= 3  # several steps: the stop is not the first one
    assert np.all(gains[:-1] > limits[:-1])  # no earlier step would have ended the pass
    assert gains[-1] <= limits[-1]  # and the last one did
    assert float(r @ r) == accepted[-1] and abs(x[0]) < 1.0  # the returned point is the last
