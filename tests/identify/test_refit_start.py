"""Where an effect's refit starts when the fit without it has absorbed it.

The conrod's baseline without the seal friction put the seal's dissipation into the dampers
(``d_c`` 2.7x, ``c_rod`` 49x) and the strain lag (at its 1 ms bound). The robust start puts
all of those back to their configured values, the rod's damper and the lags included (they
are not judged for consistency, so the old start left them where the baseline had them); a
fit near the configuration is its own start. Of the refits from the fit as it stands and
from the robust start, the robust one is kept only when its estimation cost is lower by
more than a margin: two minima lie tens of per cent apart, two ends of one a hair apart, and
the last bits of the arithmetic must not choose. No fit is run here: the rule alone.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hil.identify.fit import FitResult
from hil.identify.model import IDX, N_PARAMS
from hil.identify.pipeline import PLAIN_NFEV, START_MARGIN, _Loop

CONFIGURED = {"gain_n_per_a": 120.0, "ds": 6.8e4, "dp": 1.5e4, "dc": 413.0, "ks": 2.23e7,
              "jp": 118.0, "jc": 0.295, "k_rod": 1.52e6, "c_rod": 50.0}
FREE = [*CONFIGURED, "skew_s", "lag_pressure_s", "lag_strain_s"]


def _fit(values: dict[str, float], cost: float = 0.0) -> FitResult:
    theta = np.zeros(N_PARAMS)
    for k, v in {**CONFIGURED, **values}.items():
        theta[IDX[k]] = v
    # the estimation cost a stub loop reads back (weighted_ss below)
    return FitResult(theta, list(FREE), {}, {}, {"cost": np.array([cost])}, np.zeros((1, 5)))


def _loop() -> SimpleNamespace:
    configured = _fit({}).theta
    loop = SimpleNamespace(exp=SimpleNamespace(start=dict(CONFIGURED)), configured=configured,
                           est_mask=None, said=[], unbiased=True)
    loop.say = loop.said.append
    loop.robust_start = lambda fit: _Loop.robust_start(loop, fit)
    loop.held_first = lambda d, beta: _Loop.held_first(loop, d, beta)
    loop.others_held = lambda: _Loop.others_held(loop)
    loop.weighted_ss = lambda out, mask: float(out["cost"][0])
    return loop


def test_an_absorbing_baseline_starts_from_its_dampers_and_lags_configured():
    loop = _loop()
    # conrod, seal friction, rig seed 1's baseline (docs/identify.md)
    absorbed = _fit({"dc": 2.71 * 413.0, "c_rod": 48.7 * 50.0, "lag_strain_s": 1e-3,
                     "skew_s": -3e-6, "ks": 0.91 * 2.23e7})
    start = _Loop.robust_start(loop, absorbed)
    assert set(start) == {"dc", "c_rod", "lag_strain_s"}
    # a parameter at its configured value (the pressure lag at 0) and the skew stay put;
    # k_s within the factor is not moved either.
    # A fit near the configuration is its own start, whatever its rod damper and lags
    near = _fit({"dc": 1.02 * 413.0, "c_rod": 2.5 * 50.0, "lag_pressure_s": 6e-5})
    assert _Loop.robust_start(loop, near) == []


def test_the_robust_refit_is_kept_only_when_lower_by_the_margin():
    loop = _loop()
    loop.current = _fit({"dc": 3.0 * 413.0})
    plain_cost = 6000.0
    plain = (_fit({}, plain_cost), {})
    for robust_cost, kept in ((0.6 * plain_cost, "robust"),
                              ((1.0 - 0.5 * START_MARGIN) * plain_cost, "plain"),
                              (plain_cost * (1.0 - 1e-15), "plain"),
                              (1.3 * plain_cost, "plain")):
        robust_fit = (_fit({}, robust_cost), {})
        runs = []

        def refit(d, beta, robust=False, nfev=None, r=robust_fit, runs=runs):
            runs.append(nfev)
            return r if robust else plain

        loop.refit_with = refit
        new, _, other = _Loop.start_chosen(loop, None, {}, plain, 0)
        assert (new is robust_fit[0]) == (kept == "robust"), robust_cost
        if kept == "robust":
            # the short trial led, so the robust refit was run in full; the plain one is
            # the other
            assert runs == [PLAIN_NFEV, None]
            assert other[0] is plain[0]
        else:
            # the short trial did not lead: no full robust refit, none to fall back on
            assert runs == [PLAIN_NFEV]
            assert other is None


def test_a_trial_that_leads_but_ends_behind_is_the_other():
    loop = _loop()
    loop.current = _fit({"dc": 3.0 * 413.0})
    plain = (_fit({}, 6000.0), {})
    trial, full = (_fit({}, 5000.0), {}), (_fit({}, 5990.0), {})
    loop.refit_with = lambda d, beta, robust=False, nfev=None: (
        plain if not robust else trial if nfev == PLAIN_NFEV else full)
    new, _, other = _Loop.start_chosen(loop, None, {}, plain, 0)
    assert new is plain[0] and other[0] is full[0]

def test_a_noisy_input_starts_from_the_far_parameters_alone():
    # without the low-pass the estimation cost carries the input noise's bias: the robust
    # start is the far parameters only, the rod's damper and the lags left as fitted
    loop = _loop()
    loop.unbiased = False
    absorbed = _fit({"dc": 2.71 * 413.0, "c_rod": 48.7 * 50.0, "lag_strain_s": 1e-3})
    assert _Loop.robust_start(loop, absorbed) == ["dc"]


def test_a_later_effect_is_refitted_with_those_in_held_first(monkeypatch):
    """Effects in already and the fit still far: the new effect's refit from the robust start
    with the effects in held, a search on the score tests' cheaper model, then all freed and
    polished on the loop's own; kept only when lower by the margin, and the loop's fit is
    left as it was whichever is kept."""
    from hil.identify import pipeline

    pump = SimpleNamespace(params=("pc_force_n",), nominal=(40.0,),
                           refit_extra=(("pc_shape", None),))
    loop = _loop()
    loop.added = [SimpleNamespace(label="pump")]
    loop.defs_all = {"pump": pump}
    loop.model, loop.test_model = "the loop's model", "half the sub-steps"
    loop.exp.dt = 2e-4
    current = _fit({"dc": 3.0 * 413.0})
    current.free = [*FREE, "pc_force_n", "pc_shape"]
    loop.current = current
    loop.held_since_baseline = lambda: []
    plain = (_fit({}, 6000.0), {})
    seen = {}

    def refit(d, beta, robust=False, nfev=None, model=None, run_on=False):
        seen["free"], seen["robust"], seen["model"] = list(loop.current.free), robust, model
        return _fit({}, 5000.0), {"c_rod": "held"}

    def polish(fitter, theta0, free, credible, **kw):
        seen["polish_free"], seen["polish_model"] = list(free), fitter
        return _fit({}, seen["polish_cost"]), {}

    loop.refit_with = refit
    loop.refitter = lambda: loop.model
    monkeypatch.setattr(pipeline, "guarded_fit", polish)
    for cost, kept in ((3000.0, True), ((1.0 - 0.5 * START_MARGIN) * 6000.0, False)):
        seen["polish_cost"] = cost
        new, held = _Loop.others_held_chosen(loop, None, {}, plain, 1)
        assert (new is not plain[0]) == kept
        assert held == ({"c_rod": "held"} if kept else {})
        assert seen["robust"] and "pc_force_n" not in seen["free"]
        assert "pc_shape" not in seen["free"] and "dc" in seen["free"]
        assert {"pc_force_n", "pc_shape"} <= set(seen["polish_free"])
        # the search on the cheap model, the polish (the fit kept) on the loop's
        assert seen["model"] == "half the sub-steps"
        assert seen["polish_model"] == "the loop's model"
        assert loop.current is current
    # no effect of those in free: nothing to hold, the plain refit as it is, no refit run
    loop.current = _fit({"dc": 3.0 * 413.0})
    seen.clear()
    assert _Loop.others_held_chosen(loop, None, {}, plain, 1) is plain and not seen


def test_a_parameter_held_in_an_earlier_effects_refit_is_free_in_the_held_first_refit(
        monkeypatch):
    """Conrod, pump friction, seal friction and pulsation, rig seed 1: ``k_s`` held in the
    pulsation's round (the frictions still missing) kept the seal's refit out of the rig's
    basin, held-first or not. The held-first refit frees it (from its held value) and the
    polish keeps it free; a parameter the baseline itself held (``J_c`` at its bound) stays
    held."""
    from hil.identify import pipeline

    pump = SimpleNamespace(params=("pc_force_n",), nominal=(40.0,), refit_extra=())
    loop = _loop()
    loop.added = [SimpleNamespace(label="pump")]
    loop.defs_all = {"pump": pump}
    loop.held = {"jc": "ran to its bound; held at 0.295",
                 "ks": "after adding the pulsation: interval wider than the value"}
    loop.base = SimpleNamespace(held={"jc": loop.held["jc"]})
    current = _fit({"dc": 3.0 * 413.0})
    current.free = [p for p in FREE if p not in ("jc", "ks")] + ["pc_force_n"]
    loop.current = current
    loop.held_since_baseline = lambda: _Loop.held_since_baseline(loop)
    loop.model, loop.test_model = "the loop's model", "half the sub-steps"
    assert loop.held_since_baseline() == ["ks"]
    seen = {}

    def refit(d, beta, robust=False, nfev=None, model=None, run_on=False):
        seen["free"] = list(loop.current.free)
        first = _fit({}, 5000.0)
        first.free = list(loop.current.free)
        return first, {}

    def polish(fitter, theta0, free, credible, **kw):
        seen["polish_free"] = list(free)
        return _fit({}, 3000.0), {}

    loop.refit_with = refit
    loop.refitter = lambda: None
    monkeypatch.setattr(pipeline, "guarded_fit", polish)
    new, _ = _Loop.others_held_chosen(loop, None, {}, (_fit({}, 6000.0), {}), 2)
    assert "ks" in seen["free"] and "jc" not in seen["free"]
    assert "pc_force_n" not in seen["free"]
    assert {"ks", "pc_force_n"} <= set(seen["polish_free"]) and "jc" not in seen["polish_free"]
    assert "ks free again" in loop.said[-1] and loop.current is current
    # a parameter free in the fit as it stands is not "held since the baseline"
    loop.current = _fit({})
    assert loop.held_since_baseline() == []
