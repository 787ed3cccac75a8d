"""Thesis F9 (hip pitch, position control over the whole stack) on a reduced frequency set:
the bandwidths come out of the simulation and are held to the issue's tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.scenarios import ON_THESIS_PRESET, SCENARIOS, names
from hil.scenarios.hip import f9_result
from plant.config import load_config

FREQS = (5.0, 20.0, 30.0, 40.0, 50.0, 60.0)


@pytest.fixture(scope="module")
def f9():
    return f9_result(load_config("hydra_thesis"), FREQS)


def test_registered_on_the_thesis_preset():
    names()
    assert "f9" in SCENARIOS and "f9" in ON_THESIS_PRESET


@pytest.mark.slow
def test_torque_bandwidth_through_the_stack(f9):
    bw = f9.metric("torque -3 dB, reinforced").value
    assert 20.0 <= bw <= 50.0, bw


@pytest.mark.slow
def test_reinforcement_raises_the_torque_bandwidth(f9):
    """The thesis overlays the unreinforced case to show the reinforcement's effect."""
    weak = f9.metric("torque -3 dB, unreinforced").value
    strong = f9.metric("torque -3 dB, reinforced").value
    assert math.isnan(weak) is False and weak < strong


@pytest.mark.slow
def test_slow_references_are_tracked(f9):
    """Well below the loop's modes the measured angle follows the command (0 dB, no lag)."""
    name, f, h = f9.series["bodes"][0]
    assert name.startswith("angle") and f[0] == FREQS[0]
    assert abs(20 * np.log10(abs(h[0]))) < 1.5 and abs(np.degrees(np.angle(h[0]))) < 20.0
