"""The consistency test itself (:mod:`hil.identify.consistency`): the linear model's
parameters refitted on frequency bands, time segments and channel groups of records from the
independent rig (truth from the generator, never from the fit).

It must flag a stiffness that depends on frequency (a Maxwell branch in the series
elasticity) and a parameter that changes over the record (the dampers following the oil's
temperature), both absorbed by the linear model that lacks them, and must not flag a
consistent rig whose parameters lie 4x from the preset the fit starts from. Each record is
simulated and fitted (~5 s CPU): marked slow, out of ``make test-fast``."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_limits

from hil.identify.consistency import Consistency, consistency
from hil.identify.fit import FitResult, OutputErrorFit, fit_baseline
from hil.identify.model import FastModel
from hil.identify.pipeline import choose_intersample
from hil.identify.rig import generate_rig
from plant.config import load_config

_CFG = load_config("hydra_default")


def _baseline(load: str, effects=(), preset=_CFG, **kw) -> tuple[FitResult, Consistency]:
    """The linear model (no library effect) fitted to a 4 s rig record, and its consistency."""
    rig = generate_rig(load, list(effects), seconds=4.0, seed=1, preset=preset, **kw)
    with threadpool_limits(limits=1, user_api="blas"):
        exp, theta = choose_intersample(rig.data, _CFG, None, lambda msg: None)
        model = FastModel(exp)
        fit = fit_baseline(model, theta0=theta)
        return fit, consistency(fit, exp, OutputErrorFit(model).fit_mask())


def _flagged(c: Consistency) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for s in c.inconsistent:
        out.setdefault(s.name, set()).add(s.split)
    return out


@pytest.mark.slow
def test_flags_a_frequency_dependent_stiffness():
    """A 30 Hz Maxwell branch (half the series stiffness) on the fixed piston: the linear
    fit whitens the residual with k_s 30 % and d_p 100 % above the truth; the stiffness the
    bands and the channel groups ask for differs."""
    fit, c = _baseline("fixed_piston", ("hose_viscoelastic",))
    flagged = _flagged(c)
    assert "ks" in flagged, [s.describe(s.name) for s in c.inconsistent]
    ks = [s for s in c.inconsistent if s.name == "ks"][0]
    assert ks.ratio > 1.03 and ks.p_holm < 1e-3
    assert "k_s" in ks.describe("k_s") and " at " in ks.describe("k_s")
    # a Maxwell branch is the softer k_s below its corner and k_s + k_m above it: the higher
    # band asks for the stiffer spring
    bands = [s for s in c.splits if s.name == "ks" and s.split == "frequency"]
    if bands:
        values = [p.value for p in bands[0].parts]
        assert values[-1] > values[0], bands[0].describe("k_s")


@pytest.mark.slow
def test_flags_a_time_varying_parameter():
    """The oil heats 15 -> 25 degC over the record and the dampers follow it
    (``viscosity_temperature`` at 0.03/degC: -26 % over the record), fitted by constant
    dampers: the dampers differ between the time segments, beyond their intervals."""
    fit, c = _baseline("fixed_piston", ("viscosity_temperature",), temperature="ramp")
    timed = [s for s in c.inconsistent if s.split == "time"]
    assert {s.name for s in timed} & {"ds", "dp"}, [s.describe(s.name) for s in c.splits]
    s = max(timed, key=lambda s: s.ratio)
    a, b = (s.parts[i] for i in s.far)
    assert a.ci_high < b.ci_low and s.ratio > 1.03
    # warmer oil is thinner: every damper the segments disagree on falls over the record
    for s in timed:
        if s.name in ("ds", "dp"):
            first, last = s.parts[0].value, s.parts[-1].value
            assert last < first, s.describe(s.name)


@pytest.mark.slow
@pytest.mark.parametrize("load,overrides", [
    ("fixed_piston", {"hydraulics.ks_n_per_m": 4.0}),
    ("conrod_fixed", {"load.conrod_stiffness_n_per_m": 4.0}),
    ("conrod_fixed", {"load.conrod_stiffness_n_per_m": 0.25}),
])
def test_a_consistent_rig_4x_off_the_preset_is_not_flagged(load, overrides):
    """Another hose, another rod: the rig's parameters 4x (or 1/4) of the preset's. The fit
    moves them there from the preset and they agree in every part."""
    preset = _CFG.with_overrides({k: f * _CFG.get(k) for k, f in overrides.items()})
    fit, c = _baseline(load, preset=preset)
    assert c.splits, c.notes
    assert not c.inconsistent, [s.describe(s.name) for s in c.inconsistent]
    key, factor = next(iter(overrides.items()))
    name = {"hydraulics.ks_n_per_m": "ks", "load.conrod_stiffness_n_per_m": "k_rod"}[key]
    assert fit.value(name) / _CFG.get(key) == pytest.approx(factor, rel=0.25)
