"""The residuals' effects against the other thesis figures: entrained air (calibrated on F1's
measured 25 Hz) switched on for F2-F4, F7 and F8, which must stay within their tolerances,
and F1 as measured reproduced with it. F5 and the reinforced F6 fall below theirs with it
(71 and 39 Hz, docs/residuals.md): that is why the effect is off by default. The hip's rod
path and leg enter F9 alone (``hil.sim.hip_stack.hip_config``)."""

from __future__ import annotations

import pytest

from hil.scenarios import get
from hil.scenarios.f1_measured import AIR_FRACTION_BOUND, air_on
from hil.scenarios.plant_figures import THESIS_F1
from plant.config import load_config


@pytest.fixture(scope="module")
def thesis_air():
    return air_on(load_config("hydra_thesis"))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["f2", "f3", "f4", "f7", "f8"])
def test_figures_stay_within_tolerance_with_air_on(thesis_air, name):
    res = get(name).call(thesis_air)
    judged = [m for m in res.metrics if m.ok is not None]
    assert judged and all(m.ok for m in judged), [(m.name, m.value) for m in judged]


@pytest.mark.slow
def test_f1_as_measured_with_air():
    """The calibrated air moves the stepped-sine peak from the model's side (~55 Hz) to the
    measured figure's; without air the peak stays above 45 Hz."""
    res = get("f1-measured").call(load_config("hydra_thesis"))
    before = res.metric("peak, without air").value
    after = res.metric("peak, entrained air").value
    assert before > 45.0
    assert abs(after - THESIS_F1["measured_peak_hz"]) <= 2.0
    assert res.metric("air volume fraction").ok
    lo, hi = AIR_FRACTION_BOUND
    assert lo * 100 <= res.metric("air volume fraction").value <= hi * 100
