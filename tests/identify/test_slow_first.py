"""The first stage of the refit below the piston's line (:mod:`hil.identify.slowfirst`): the
pressures, measured and simulated alike, low-passed below the line; every other channel as
it was; a fit's head the same as the whole record's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

FS = 5000.0
N = 10000
T = np.arange(N) / FS
SLOW = np.sin(2 * np.pi * 20.0 * T)
RING = np.sin(2 * np.pi * 1241.0 * T)


class StandIn:
    """A model whose outputs are fixed signals: the pressures a slow part plus the piston's
    ring, the motor speed the ring alone (not a pressure: left as it is)."""

    def __init__(self) -> None:
        self.exp = SimpleNamespace(data=SimpleNamespace(sample_rate_hz=FS),
                                   measured={"p_cyl_a": SLOW + RING, "p_pump_a": SLOW + RING,
                                             "omega_m": RING.copy()})
        self.n_sub = 7

    def outputs(self, theta, z=None, n_stop=None, channels=None):
        n = N if n_stop is None else n_stop
        out = {"p_cyl_a": (SLOW + RING)[:n], "p_pump_a": (SLOW + RING)[:n],
               "omega_m": RING[:n]}
        return out if channels is None else {c: out[c] for c in channels}


def test_the_pressures_are_low_passed_below_the_line():
    from hil.identify.slowfirst import LowPassedPressures

    model = StandIn()
    measured = dict(model.exp.measured)
    lp = LowPassedPressures(model, 0.4 * 1241.0)
    tail = slice(N // 2, None)
    for c in ("p_cyl_a", "p_pump_a"):
        y = lp.exp.measured[c][tail]
        # the ring about 30 dB down, the slow part through within 1 % (its phase moved)
        amp = np.sqrt(2.0 * np.mean((y - np.mean(y)) ** 2))
        assert 0.99 < amp < 1.05
        spec = np.abs(np.fft.rfft(y))
        f = np.fft.rfftfreq(y.size, 1.0 / FS)
        assert spec[np.argmin(np.abs(f - 1241.0))] < 0.05 * spec[np.argmin(np.abs(f - 20.0))]
    # not a pressure: the same signal; the model's own experiment untouched
    np.testing.assert_array_equal(lp.exp.measured["omega_m"], measured["omega_m"])
    for c, y in measured.items():
        assert model.exp.measured[c] is y
    # the model's other attributes read through
    assert lp.n_sub == 7


def test_the_simulated_pressures_take_the_same_filter_and_a_head_is_the_whole_records():
    from hil.identify.slowfirst import LowPassedPressures

    lp = LowPassedPressures(StandIn(), 500.0)
    whole = lp.outputs(None)
    for c in ("p_cyl_a", "p_pump_a"):
        # a model equal to the record leaves no residual through the filter
        np.testing.assert_array_equal(whole[c], lp.exp.measured[c])
        # causal: a fit's head has the whole record's values there
        np.testing.assert_array_equal(lp.outputs(None, n_stop=1234)[c], whole[c][:1234])
    np.testing.assert_array_equal(whole["omega_m"], RING)
    only = lp.outputs(None, channels=frozenset({"p_cyl_a"}))
    assert set(only) == {"p_cyl_a"}
    np.testing.assert_array_equal(only["p_cyl_a"], whole["p_cyl_a"])


def test_a_gap_in_a_pressure_is_refused():
    from hil.identify.slowfirst import pressures_finite

    exp = StandIn().exp
    assert pressures_finite(exp)
    exp.measured["p_cyl_a"] = exp.measured["p_cyl_a"].copy()
    exp.measured["p_cyl_a"][17] = np.nan
    assert not pressures_finite(exp)
    exp.measured["omega_m"][3] = np.nan
    exp.measured["p_cyl_a"][17] = 0.0
    assert pressures_finite(exp)


# --- the loop's step (:meth:`_Loop.restart_slow_first`), on stand-ins --------------------

JC_CONFIGURED = 0.295


def _slow_loop(monkeypatch, left_after: bool, seal: bool = True, line=(1.84e7, 1241.0, 1371.0),
               jc: float = JC_CONFIGURED, disagree: tuple[str, ...] = (),
               absorbed: tuple[str, ...] = ()):
    """A loop at the free piston's pair (``K``, ``d_s``, ``k_s``, ``J_c`` held since the
    baseline, the seal's Stribeck velocity held since it came in); the full band's refit
    leaves structure where ``left_after``, and ``disagree`` (names) disagreeing between
    parts of the record with the residual white, until a refit holds them; ``absorbed``
    (names) held by the baseline for structure they had absorbed."""
    from hil.identify import pipeline
    from hil.identify.model import IDX, N_PARAMS

    calls: dict = {"slow": [], "full": [], "cutoff": [], "model": []}

    class Fitter:
        def __init__(self, model, scales):
            self.model = model

        def fit(self, theta0, free, sigma=None, passes=2, max_nfev=40):
            calls["slow"].append((theta0.copy(), list(free), max_nfev))
            theta = theta0.copy()
            theta[IDX["gain_n_per_a"]] = 101.0  # the slow part's gain
            return SimpleNamespace(theta=theta, free=list(free))

    def full(fitter, theta0, free, credible, sigma=None, passes=2, configured=None):
        calls["full"].append((theta0.copy(), list(free), fitter.converged_gain, passes))
        bad = [p for p in disagree if p in free]
        return SimpleNamespace(theta=theta0.copy(), free=list(free), outputs=1.0,
                               left=left_after or bool(bad), white=not left_after,
                               bad=bad), {}

    def low_passed(model, cutoff_hz):
        calls["cutoff"].append(cutoff_hz)
        calls["model"].append(model)
        return SimpleNamespace(low_passed=model, cutoff_hz=cutoff_hz)

    monkeypatch.setattr(pipeline, "stiffness_at_line", lambda exp, theta, out, conf: line)
    monkeypatch.setattr(pipeline, "pressures_finite", lambda exp: True)
    monkeypatch.setattr(pipeline, "OutputErrorFit", Fitter)
    monkeypatch.setattr(pipeline, "LowPassedPressures", low_passed)
    monkeypatch.setattr(pipeline, "NUISANCE_SCALES", lambda dt: {})
    monkeypatch.setattr(pipeline, "_all_scales", lambda defs: {})
    monkeypatch.setattr(pipeline, "guarded_fit", full)
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: float(out))
    monkeypatch.setattr(pipeline, "_verdict", lambda a: (not a.white, ""))
    theta = np.zeros(N_PARAMS)
    theta[IDX["gain_n_per_a"]] = 119.4
    theta[IDX["ks"]] = 2.24e7
    theta[IDX["jc"]] = jc
    theta[IDX["ds"]] = 6.79e4
    theta[IDX["sf_vs_m_per_s"]] = 5e-3
    current = SimpleNamespace(theta=theta, free=["dp", "jp", "sf_coulomb_n"], outputs=2.0,
                              sigma={}, left=True)
    if jc != JC_CONFIGURED:
        current.free.append("jc")  # run away with the line's ratio kept
    configured = np.zeros(N_PARAMS)
    configured[IDX["jc"]] = JC_CONFIGURED
    added = [SimpleNamespace(name="pump_coulomb_friction", label="pump_coulomb_friction")]
    defs = {"pump_coulomb_friction": SimpleNamespace(params=("pc_force_n",), refit_extra=())}
    if seal:
        added.append(SimpleNamespace(name="seal_friction", label="seal_friction"))
        defs["seal_friction"] = SimpleNamespace(params=("sf_coulomb_n", "sf_static_n"),
                                                refit_extra=(("sf_vs_m_per_s", None),))
    held = {p: "held at the preset" for p in ("gain_n_per_a", "ds", "ks", "jc")
            if p not in current.free}
    for p in absorbed:
        held[p] = ("not identifiable from this record: the fit moved it to 0.01x the "
                   f"configured value, {pipeline.ABSORBED} ({p} drifts): structure the "
                   "linear model lacks, taken into it; held at 6.79e+04")
    if seal:
        held["sf_vs_m_per_s"] = "after adding seal_friction: held at 0.005"
    loop = SimpleNamespace(current=current, added=added, defs_all=defs, held=held,
                           exp=SimpleNamespace(dt=2e-4, load="free",
                                               const=SimpleNamespace(eps_seal=2e-3)),
                           model="the loop's model", test_model="the half-step model",
                           configured=configured, sigma_ref=None, restarts=[],
                           freed_at=None, say=lambda msg: None,
                           # the loop's fitter of a given model (the low-passed one), else
                           # the full band's
                           refitter=lambda model=None: (Fitter(model, {}) if model is not None
                                                        else SimpleNamespace(converged_gain=50.0)))
    loop.structure_left = lambda: "structure" if loop.current.left else ""
    loop.judged = lambda fit: (fit, SimpleNamespace(
        inconsistent=[SimpleNamespace(name=p) for p in fit.bad]))
    from hil.identify.pipeline import _Loop
    loop.restart_kept = lambda *a: _Loop.restart_kept(loop, *a)  # the judgement as the loop's
    loop.freed_disagreeing = lambda *a: _Loop.freed_disagreeing(loop, *a)
    return loop, calls


def test_the_slow_part_frees_the_holds_with_the_line_placed_then_frees_ks_jc(monkeypatch):
    from hil.identify import pipeline
    from hil.identify.model import IDX

    loop, calls = _slow_loop(monkeypatch, left_after=False)
    before = loop.current
    assert pipeline._Loop.restart_slow_first(loop)
    (theta0, free1, nfev), = calls["slow"]
    # below the line: the held baseline parameters but the line's two, the seal's Stribeck
    # velocity held since it came in, and the seal's eps from the preset; the line already
    # where the record has it (J_c at the preset here: k_s the line's), on the half-step
    # model, with the Jacobians of a search
    assert {"gain_n_per_a", "ds", "sf_vs_m_per_s", "sf_eps_m_per_s"} <= set(free1)
    assert not {"ks", "jc"} & set(free1)
    assert theta0[IDX["sf_eps_m_per_s"]] == 2e-3
    assert theta0[IDX["ks"]] == 1.84e7 and theta0[IDX["jc"]] == JC_CONFIGURED
    assert calls["cutoff"] == [pipeline.SLOW_CUTOFF * 1241.0]
    assert calls["model"] == ["the half-step model"] and nfev == pipeline.ROBUST_NFEV
    # the full band from the slow part's end, k_s and J_c free, at the tight stop
    (theta2, free2, gain, _), = calls["full"]
    assert theta2[IDX["gain_n_per_a"]] == 101.0 and theta2[IDX["ks"]] == 1.84e7
    assert {"ks", "jc"} <= set(free2) and gain == pipeline.JUDGED_GAIN
    # kept: explained, cheaper; the freed parameters no longer held; the freeing at the
    # end not asked again of this fit
    assert loop.current is not before and not loop.held
    assert loop.restarts[-1]["outcome"] == "kept"
    assert loop.freed_at is loop.current


def test_a_run_away_piston_mass_goes_back_to_the_configured_one_on_the_line(monkeypatch):
    from hil.identify import pipeline
    from hil.identify.model import IDX

    # the fit's J_c 2x the configured, its line at 1371 Hz: the record's at 1241 Hz is
    # reached with J_c configured and k_s the line's ratio times it
    loop, calls = _slow_loop(monkeypatch, left_after=False, jc=2 * JC_CONFIGURED)
    assert pipeline._Loop.restart_slow_first(loop)
    (theta0, free1, _), = calls["slow"]
    assert theta0[IDX["jc"]] == JC_CONFIGURED
    assert theta0[IDX["ks"]] == pytest.approx(1.84e7 / 2)
    assert not {"ks", "jc"} & set(free1)
    (theta2, free2, _, _), = calls["full"]
    assert {"ks", "jc"} <= set(free2)


def test_a_freed_hold_that_disagrees_between_parts_is_held_again(monkeypatch):
    from hil.identify import pipeline
    from hil.identify.model import IDX

    loop, calls = _slow_loop(monkeypatch, left_after=False, disagree=("ds",))
    assert pipeline._Loop.restart_slow_first(loop)
    first, again = calls["full"]
    assert "ds" in first[1] and "ds" not in again[1]
    # from the first's end, d_s back at its hold, one pass
    assert again[0][IDX["ds"]] == 6.79e4 and again[3] == 1
    assert "ds" in loop.held and "once freed" in loop.held["ds"]
    assert loop.restarts[-1]["outcome"] == "kept"


def test_a_hold_for_absorbed_structure_stays_held_through_the_step(monkeypatch):
    from hil.identify import pipeline
    from hil.identify.model import IDX

    # d_s held by the baseline where, far from its preset, it disagreed between parts of the
    # record: neither part frees it (freed, it would disagree again and be held again after
    # a second full-band refit), so one full-band refit, at d_s's hold
    loop, calls = _slow_loop(monkeypatch, left_after=False, disagree=("ds",),
                             absorbed=("ds",))
    why = loop.held["ds"]
    assert pipeline._Loop.restart_slow_first(loop)
    (theta0, free1, _), = calls["slow"]
    assert "ds" not in free1 and "gain_n_per_a" in free1
    assert theta0[IDX["ds"]] == 6.79e4
    (theta2, free2, _, _), = calls["full"]
    assert "ds" not in free2 and theta2[IDX["ds"]] == 6.79e4
    assert loop.held == {"ds": why}
    assert loop.restarts[-1]["outcome"] == "kept"
    assert loop.freed_at is loop.current


def test_no_hold_again_where_the_disagreement_is_not_a_freed_holds(monkeypatch):
    from hil.identify import pipeline

    loop, calls = _slow_loop(monkeypatch, left_after=False, disagree=("dp",))
    assert not pipeline._Loop.restart_slow_first(loop)
    assert len(calls["full"]) == 1
    assert loop.restarts[-1]["outcome"] == "not kept (structure left)"


def test_the_slow_first_refit_is_not_kept_with_structure_left(monkeypatch):
    from hil.identify import pipeline

    loop, calls = _slow_loop(monkeypatch, left_after=True)
    before, held = loop.current, dict(loop.held)
    assert not pipeline._Loop.restart_slow_first(loop)
    assert loop.current is before and loop.held == held
    assert loop.restarts[-1]["outcome"] == "not kept (structure left)"
    assert loop.freed_at is None


def test_no_line_no_refit_and_no_seal_no_eps(monkeypatch):
    from hil.identify import pipeline

    loop, calls = _slow_loop(monkeypatch, left_after=False, line=None)
    assert not pipeline._Loop.restart_slow_first(loop)
    assert not calls["slow"] and not calls["full"] and not loop.restarts
    loop, calls = _slow_loop(monkeypatch, left_after=False, seal=False)
    assert pipeline._Loop.restart_slow_first(loop)
    assert "sf_eps_m_per_s" not in calls["slow"][0][1]
