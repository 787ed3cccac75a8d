"""The guard's refit after a hold: three Jacobians, or with ``run_on`` the first fit's budget
where that fit stopped at it (not converged).

Conrod, pump and seal friction, 16 s, rig seed 1: the seal's held-first search stopped at its
budget with ``c_rod`` walked to its bound; the guard held it back and its three-Jacobian
refit left the search's end off its valley floor, from where the polish with ``J_c`` freed
went to the far basin. No model is simulated: the guard on a stub fitter.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify.fit import FitResult, guarded_fit
from hil.identify.model import N_PARAMS


class _Fitter:
    """Holds ``c_rod`` once (it ran to its bound), then nothing; records each fit's budget."""

    def __init__(self, first_converged: bool) -> None:
        self.first_converged = first_converged
        self.budgets: list[tuple[int, int]] = []

    def fit(self, theta0, free, sigma=None, passes=2, max_nfev=40):  # noqa: ANN001, ANN201
        self.budgets.append((passes, max_nfev))
        converged = self.first_converged if len(self.budgets) == 1 else True
        return FitResult(np.array(theta0, dtype=float), list(free), {}, {"p": 1.0}, {},
                         np.zeros((1, 5)), converged=converged)

    def offenders(self, result, names=None):  # noqa: ANN001, ANN201
        return [("c_rod", "ran to its bound", np.inf)] if "c_rod" in result.free else []


@pytest.mark.parametrize(("run_on", "first_converged", "budget"),
                         [(True, False, 120), (True, True, 9), (False, False, 9)])
def test_the_refit_after_a_hold_runs_on_only_after_a_fit_stopped_at_its_budget(
        run_on, first_converged, budget):
    fitter = _Fitter(first_converged)
    theta = np.ones(N_PARAMS)
    _, held = guarded_fit(fitter, theta, ["dc", "c_rod"], theta, max_nfev=120, run_on=run_on)
    assert list(held) == ["c_rod"]
    assert fitter.budgets == [(2, 120), (1, budget)]
