"""The statistics behave: Holm, Newey-West on autocorrelated data, the Wald test's size."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify import stats


def test_holm_orders_and_caps():
    adj = stats.holm([0.01, 0.04, 0.03, 0.5])
    assert adj == [0.04, 0.09, 0.09, 0.5]


def test_newey_west_widens_for_autocorrelated_scores():
    rng = np.random.default_rng(0)
    e = rng.standard_normal(20000)
    ar = np.zeros_like(e)
    for k in range(1, e.size):
        ar[k] = 0.9 * ar[k - 1] + e[k]
    naive = float(ar @ ar)
    hac = float(stats.newey_west(ar[:, None], stats.nw_lags(ar.size, 60))[0, 0])
    # long-run variance of AR(1) with phi = 0.9 is (1+phi)/(1-phi) = 19 x the variance
    assert 8 < hac / naive < 25


def test_wald_size_under_autocorrelated_null():
    """A regressor unrelated to an AR(1) residual: the HAC Wald test rejects at about its
    nominal rate, where a white-noise test would reject far too often."""
    rng = np.random.default_rng(1)
    rejections = 0
    trials = 60
    for _ in range(trials):
        e = rng.standard_normal(4000)
        r = np.zeros_like(e)
        x = np.zeros_like(e)
        u = rng.standard_normal(4000)
        for k in range(1, e.size):
            r[k] = 0.8 * r[k - 1] + e[k]
            x[k] = 0.8 * x[k - 1] + u[k]
        beta = (x @ r) / (x @ x)
        s = stats.newey_west((x * (r - beta * x))[:, None], stats.nw_lags(r.size, 40))
        var = s[0, 0] / (x @ x) ** 2
        _, p, _ = stats.wald(np.array([beta]), np.array([[var]]))
        rejections += p < 0.05
    assert rejections <= 9  # nominal 3 of 60


def test_ljung_box_white_and_not():
    rng = np.random.default_rng(2)
    w = rng.standard_normal(5000)
    assert stats.ljung_box(w, 30)[1] > 0.001
    assert stats.ljung_box(np.convolve(w, np.ones(5), "same"), 30)[1] < 1e-10


def test_predictable_share_of_white_noise_is_near_zero_at_any_length():
    """Adjusted for the AR's own fit: a short white record would otherwise look 20/n
    predictable (0.7 % at n = 3000, near the 1 % that counts as material)."""
    from hil.identify.residuals import predictable_share

    rng = np.random.default_rng(11)
    shares = [predictable_share(rng.standard_normal(3000)) for _ in range(40)]
    assert abs(float(np.mean(shares))) < 0.1 * 20 / 3000
    assert max(shares) < 0.01


def test_predictable_share_of_an_ar1_is_its_explained_variance():
    from hil.identify.residuals import predictable_share

    rng = np.random.default_rng(12)
    e = rng.standard_normal(20000)
    x = np.zeros_like(e)
    for k in range(1, x.size):
        x[k] = 0.5 * x[k - 1] + e[k]
    # var(x) = 1/(1 - 0.25), the innovation's 1: a quarter of x is predictable
    assert predictable_share(x) == pytest.approx(0.25, abs=0.02)


def test_a_joint_refit_that_runs_away_on_the_validation_part_is_named_so():
    """A joint refit's validation cost as a relative change; a runaway (beyond 10x, or not
    finite) is 'diverged', with no percentage of it (once printed as +5.9e20 %)."""
    from hil.identify.pipeline import DIVERGED_RATIO, joint_change

    assert joint_change(100.0, 11.0) == (pytest.approx(-0.89), "")
    assert joint_change(100.0, 100.0 * DIVERGED_RATIO)[1] == ""
    for after in (100.0 * DIVERGED_RATIO * 1.01, 5.9e20, float("inf"), float("nan")):
        change, why = joint_change(100.0, after)
        assert change is None and why.startswith("diverged on the validation part"), after


def test_candidates_refitted_alone_again_are_the_rejected_and_the_collinear():
    """Where no pair passes, the joint search refits alone the candidates its forward rounds
    rejected (the model has changed since) and those the last round called collinear with a
    declared parameter: one per library effect, none of an effect already in, none judged
    at its own fit, none merely tested (a single that did not pass its score test is the
    pairs' business)."""
    from hil.identify.candidates import CandidateTest
    from hil.identify.effects import library
    from hil.identify.experiment import prepare
    from hil.identify.pipeline import _single_pool
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    exp = prepare(generate_rig("free_piston", {}, seconds=0.5, seed=1).data,
                  load_config("hydra_default"), "bl")
    defs = {d.label: d for d in library(exp)}

    def t(label: str, status: str) -> CandidateTest:
        return CandidateTest(label, defs[label].name, list(defs[label].params), status)

    first = [t("pump_coulomb_friction", "collinear"), t("seal_friction", "tested")]
    last = [t("pump_coulomb_friction", "collinear"), t("pump_pulsation[order=3]", "collinear"),
            t("pump_pulsation[order=5]", "collinear"), t("strain_thermal_drift", "tested"),
            t("input_delay", "collinear")]
    pool = _single_pool([first, last], defs, {"pump_pulsation[order=4]"}, {"seal_friction"})
    assert pool == ["seal_friction", "pump_coulomb_friction"]
    # nothing rejected, the pulsation not in: its first collinear order stands for the effect
    pool = _single_pool([last], defs, set(), set())
    assert pool == ["pump_coulomb_friction", "pump_pulsation[order=3]"]
    assert _single_pool([], defs, set(), set()) == []
