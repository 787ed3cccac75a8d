"""The guarded fit stops at the first hold of a parameter whose hold refuses the fit for the
caller (an effect's own parameter not credible: :meth:`_Loop.refit_with` with
``judged_alone``), on a stand-in fitter whose offenders are a script: the holds before it
are made as without the stop, the holds and refits after it are not."""

from __future__ import annotations

import numpy as np

from hil.identify.fit import FitResult, guarded_fit
from hil.identify.model import IDX, N_PARAMS


class _ScriptFitter:
    """Duck-typed :class:`~hil.identify.fit.OutputErrorFit`: each fit names the next
    offender of the script (worst first), until the script is done."""

    def __init__(self, script: list[str]) -> None:
        self.script = list(script)
        self.fits: list[list[str]] = []

    def fit(self, theta: np.ndarray, free: list[str], **_kw) -> FitResult:
        self.fits.append(list(free))
        return FitResult(theta.copy(), list(free), {n: 0.0 for n in free}, {}, {},
                         np.zeros((1, 5)))

    def offenders(self, result: FitResult, names: list[str] | None = None
                  ) -> list[tuple[str, str, float]]:
        left = [n for n in self.script if n in result.free]
        return [(left[0], "ran to its bound", np.inf)] if left else []


def _run(refuse: frozenset[str]) -> tuple[_ScriptFitter, FitResult, dict[str, str]]:
    fitter = _ScriptFitter(["ds", "sf_static_n", "jc"])
    theta = np.ones(N_PARAMS)
    credible = np.full(N_PARAMS, 2.0)
    free = ["ds", "jc", "sf_coulomb_n", "sf_static_n"]
    result, held = guarded_fit(fitter, theta, free, credible, refuse=refuse)  # type: ignore[arg-type]
    return fitter, result, held


def test_the_guard_stops_at_the_first_refusing_hold():
    full, _, held_full = _run(frozenset())
    assert list(held_full) == ["ds", "sf_static_n", "jc"]
    assert len(full.fits) == 4  # the first fit and a refit after each hold
    stopped, result, held = _run(frozenset({"sf_coulomb_n", "sf_static_n"}))
    # the hold before the refusing one is made as before, with its refit; then it stops
    assert list(held) == ["ds", "sf_static_n"]
    assert held["sf_static_n"] == held_full["sf_static_n"]
    assert stopped.fits == full.fits[:2]
    # the fit returned is the one the refusing parameter was found in (not held in it)
    assert "sf_static_n" in result.free and result.theta[IDX["ds"]] == 2.0
