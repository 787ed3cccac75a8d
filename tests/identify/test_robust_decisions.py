"""Decisions that must not hang on where a fit's stop fell.

A fit stopped at a looser gain ends a little earlier on its valley; a decision that compares
two costs from fixed, unconverged budgets, or reads a verdict after a fixed count of refits,
then flips with the stop. The rules here: a Levenberg-Marquardt pass does not end at the
looser stop on its first steps (a slow start is no end); the basin choice runs the robust
start's refit on where its trial is still descending near the plain refit's cost; the
restart from the piston's resonance runs at the tight stop, and on while it takes structure
off. No model is simulated: the rules alone, on stubs.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hil.identify import fit, pipeline
from hil.identify.fit import FitResult
from hil.identify.model import IDX, N_PARAMS
from hil.identify.pipeline import (
    JUDGED_GAIN,
    PLAIN_NFEV,
    RESONANCE_REFITS,
    RUN_ON_BAND,
    START_MARGIN,
    _Loop,
)


def _multiple_root_pass(x0: float, gain: float) -> list[float]:
    """One pass on a root of multiplicity five (each Gauss-Newton step shrinks the excess
    cost about ninefold) from ``x0``; the accepted costs, the start's first."""
    rng = np.random.default_rng(5)
    noise = rng.standard_normal(4000)  # the residual's variance: about 1
    scale = 30.0
    costs: list[float] = []

    def fun(x: np.ndarray) -> np.ndarray:
        r = noise + scale * x[0] ** 5
        costs.append(float(r @ r))
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        return np.full((noise.size, 1), scale * 5.0 * x[0] ** 4)

    fit.levenberg_marquardt(fun, jac, np.array([x0]), np.array([-10.0]), np.array([10.0]),
                            max_jac=40, converged_gain=gain)
    accepted = [costs[0]]
    for c in costs[1:]:
        if c < accepted[-1]:
            accepted.append(c)
    return accepted


def test_a_pass_does_not_end_at_the_loose_stop_on_its_first_steps():
    # a start whose first step gains a few tens of variances, its next a few
    x0 = 0.28
    accepted = _multiple_root_pass(x0, 50.0)
    variance = accepted[-1] / 4000
    gains = -np.diff(accepted)
    assert variance < gains[0] < 50.0 * variance  # the loose stop alone would end it there
    # it goes on past the first LOOSE_AFTER_JACOBIANS steps (none of them within one
    # variance), and the first step after them within 50 variances ends it
    assert len(gains) > 1
    assert np.all(gains[:-1] > variance)
    assert len(gains) == fit.LOOSE_AFTER_JACOBIANS + 1
    # the tight stop from the same start ends no earlier
    assert len(_multiple_root_pass(x0, 1.0)) >= len(accepted)


def test_the_loose_stop_still_ends_a_long_descent_early():
    # from far, gains run from 1e6 variances down: past the first steps, the loose stop ends
    # the pass at its first step within 50 variances, before the tight one
    loose, tight = _multiple_root_pass(2.0, 50.0), _multiple_root_pass(2.0, 1.0)
    assert len(loose) < len(tight)
    gains = -np.diff(loose)
    assert gains[-1] <= 50.0 * loose[-1] / 4000 < gains[-2]


# --- the basin choice -------------------------------------------------------------------

def _result(cost: float, converged: bool = True) -> FitResult:
    # the estimation cost the stub loop reads back (weighted_ss below)
    return FitResult(np.zeros(N_PARAMS), [], {}, {}, {"cost": np.array([cost])},
                     np.zeros((1, 5)), converged=converged)


def _chooser(plain_cost: float, trial: FitResult, full: FitResult):
    loop = SimpleNamespace(est_mask=None, said=[], current=None)
    loop.say = loop.said.append
    loop.robust_start = lambda _fit: ["dc"]
    loop.weighted_ss = lambda out, mask: float(out["cost"][0])
    plain = (_result(plain_cost), {})
    runs: list[int | None] = []

    def refit(d, beta, robust=False, nfev=None):
        runs.append(nfev)
        return (trial if nfev == PLAIN_NFEV else full), {}

    loop.refit_with = refit
    new, _, _ = _Loop.start_chosen(loop, None, {}, plain, 0)
    return new, plain[0], runs


@pytest.mark.parametrize("above", [-1.5 * START_MARGIN, 1.5 * START_MARGIN, 0.2])
def test_a_trial_still_descending_near_the_plain_refit_is_run_on(above):
    # the same trial, its budget run out a few per cent below the margin's line or above
    # the plain refit: the full refit decides, and the same basin is kept either way
    plain_cost = 6000.0
    full = _result(0.62 * plain_cost)
    new, _, runs = _chooser(plain_cost, _result((1.0 + above) * plain_cost, converged=False),
                            full)
    assert new is full
    assert runs == [PLAIN_NFEV, None]


def test_a_converged_far_or_level_trial_costs_no_full_refit():
    # converged; far above; or within the margin of the plain refit (one minimum)
    plain_cost = 6000.0
    full = _result(0.62 * plain_cost)
    for trial in (_result(1.03 * plain_cost, converged=True),
                  _result((1.0 + 2.0 * RUN_ON_BAND) * plain_cost, converged=False),
                  _result((1.0 + 0.5 * START_MARGIN) * plain_cost, converged=False),
                  _result((1.0 - 0.5 * START_MARGIN) * plain_cost, converged=False)):
        new, plain, runs = _chooser(plain_cost, trial, full)
        assert new is plain and runs == [PLAIN_NFEV]


# --- the restart from the piston's resonance --------------------------------------------

def _resonance_loop(monkeypatch, excesses: list[float]):
    """A loop whose restart's refits leave the residual structure ``excesses`` in turn
    (1 is the verdict's line) and lower the validation cost each time."""
    gains: list[float] = []
    made: list[SimpleNamespace] = []

    def refit(fitter, theta0, free, credible, sigma=None, configured=None):
        gains.append(fitter.converged_gain)
        new = SimpleNamespace(theta=theta0.copy(), free=list(free), outputs=-len(made) - 1,
                              excess=excesses[len(made)])
        made.append(new)
        return new, {}

    monkeypatch.setattr(pipeline, "stiffness_at_line", lambda exp, theta, out: (1.9e7, 1339.0,
                                                                                1425.0))
    monkeypatch.setattr(pipeline, "guarded_fit", refit)
    monkeypatch.setattr(pipeline, "structure_excess", lambda a: a.excess)
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: float(out))
    current = SimpleNamespace(theta=np.zeros(N_PARAMS), free=["ks"], outputs=0.0, sigma={},
                              excess=58.8)
    current.theta[IDX["ks"]] = 2.24e7
    loop = SimpleNamespace(current=current, added=[SimpleNamespace(label="seal")],
                           defs_all={"seal": SimpleNamespace(params=("sf_coulomb_n",))},
                           exp=None, configured=None, sigma_ref=None, restarts=[], held={},
                           say=lambda msg: None,
                           # a refitter at a looser stop than the restart's
                           refitter=lambda: SimpleNamespace(converged_gain=50.0))
    loop.judged = lambda f: (f, None)
    loop.structure_left = lambda: "structure" if loop.current.excess >= 1.0 else ""
    loop.restart_kept = lambda *a: _Loop.restart_kept(loop, *a)  # the judgement as the loop's
    return loop, made, gains


def test_the_resonance_restart_runs_on_while_it_takes_structure_off(monkeypatch):
    # the conrod triple at seed 2 with the fits stopped at 50 variances: 1.35, 1.08, then
    # 1.00 of the line; a third refit that takes less than RUN_ON_PROGRESS off is the last
    loop, made, gains = _resonance_loop(monkeypatch, [1.35, 1.08, 1.0, 0.0])
    assert not _Loop.restart_resonance(loop)
    assert len(made) == 3
    assert gains == [JUDGED_GAIN] * 3 and JUDGED_GAIN <= fit.CONVERGED_GAIN
    # one that keeps taking it off goes on, and is kept where it explains the record
    loop, made, _ = _resonance_loop(monkeypatch, [1.5, 1.3, 1.1, 0.0])
    assert _Loop.restart_resonance(loop)
    assert len(made) == 4 <= RESONANCE_REFITS and loop.current is made[-1]
