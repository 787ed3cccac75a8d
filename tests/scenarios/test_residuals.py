"""F1's measured 25 Hz traced to how its piston was held (the testbed's rod path, rod end
fixed on the reinforced beam: hil.scenarios.f1_measured), the reinforced beam's stiffness
calibrated on F1 and F6 together and held to its bounds; the other figures with it. The
hydra_thesis preset carries the calibration, so the thesis-figure tests on that preset are
the figures with it on: F3-F6 in test_f3_f6.py (F6's reinforced figure is the one the
calibration moves, 45 -> 63 Hz), F7 and F8 in test_f7_f8.py, F2 here. The entrained air,
the alternative first examined, costs F5 its tolerance. The hip's rod path and leg enter F9
alone (``hil.sim.hip_stack.hip_config``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.scenarios import get
from hil.scenarios.f1_measured import (
    air_on,
    joint_cost,
    peak_hz,
    reinforced_bound,
    reinforced_figures,
)
from hil.scenarios.plant_figures import THESIS_F1
from plant.config import load_config


@pytest.fixture(scope="module")
def thesis():
    return load_config("hydra_thesis")


def test_the_reinforced_beam_is_inside_its_bounds(thesis):
    """The calibrated path lies between the weak beam (F6-calibrated) and EA/L of the CrMo
    rod (thesis 4.4: 5/8 mm pipe), and is stiffer than the weak beam times the lateral
    deflection ratio the preset used before (the F6 figure alone already asked for more)."""
    k = thesis.get("load.beam_reinforced_axial_stiffness_n_per_m")
    lo, hi = reinforced_bound(thesis)
    assert lo == thesis.get("load.beam_axial_stiffness_n_per_m")
    assert 5.0e7 < hi < 5.5e7
    assert lo < k < hi
    assert k > lo * thesis.get("load.beam_reinforcement_ratio")


@pytest.mark.slow
def test_f1_as_measured_through_the_rod_path(thesis):
    """Held at the cylinder's end the stepped-sine peak stays on the model's side (>45 Hz);
    held through the reinforced rod path it is the measured figure's, within 25 +/- 5 Hz;
    through the weak beam there is no peak in 4..70 Hz."""
    res = get("f1-measured").call(thesis)
    assert res.metric("peak, piston at the cylinder end").value > 45.0
    after = res.metric("peak, rod end fixed, reinforced beam")
    assert abs(after.value - THESIS_F1["measured_peak_hz"]) <= 5.0 and after.ok
    assert res.metric("reinforced beam's axial stiffness").ok
    (_, f, weak), = [b for b in res.series["bodes"] if b[0] == "rod end, weak beam"]
    assert math.isnan(peak_hz(tuple(f), weak))
    assert 20 * np.log10(abs(weak[-1])) < -20.0


@pytest.mark.slow
def test_the_preset_is_the_joint_calibration(thesis):
    """The preset's reinforced stiffness minimises the joint cost of F1 and F6 against
    10 % either side, and both figures are within their tolerances there (F1 25 +/- 5 Hz,
    F6 reinforced 53 +/- 12 Hz)."""
    k = thesis.get("load.beam_reinforced_axial_stiffness_n_per_m")
    f1, f6 = reinforced_figures(thesis, k)
    assert abs(f1 - 25.0) <= 5.0 and abs(f6 - 53.0) <= 12.0, (f1, f6)
    here = joint_cost(f1, f6)
    for factor in (0.9, 1.1):
        assert joint_cost(*reinforced_figures(thesis, k * factor)) > here


@pytest.mark.slow
def test_f2_within_its_bands_on_the_thesis_preset(thesis):
    res = get("f2").call(thesis)
    judged = [m for m in res.metrics if m.ok is not None]
    assert judged and all(m.ok for m in judged), [(m.name, m.value) for m in judged]


@pytest.mark.slow
def test_entrained_air_costs_f5_its_tolerance(thesis):
    """Why the air, which also puts F1's peak at 25 Hz with the piston at the cylinder's
    end, is not the answer: F5 (piston at the cylinder's end, closed loop) drops below
    75 Hz with it."""
    res = get("f5").call(air_on(thesis))
    assert res.metric("-3 dB bandwidth").value < 75.0
