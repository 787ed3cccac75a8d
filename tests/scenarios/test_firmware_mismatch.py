"""Firmware built for one actuator on a plant that differs: F3 with a 10 % J_p mismatch.

The MCU's momentum observer uses the firmware's nominal J_p (``firmware.jp_kg``), the plant
its true one (``hydraulics.jp_kg``). A plant 10 % heavier than the firmware assumes changes
the current-based step response (the observer books 10 % of the pump's inertial force as a
disturbance and fights it) while the velocity-based controller, which uses no J_p, gives the
very same response; both stay within the thesis's bands.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.scenarios.thesis import _f3_run
from plant.config import load_config


@pytest.fixture(scope="module")
def runs():
    cfg = load_config()
    heavy = cfg.get("hydraulics.jp_kg") * 1.1
    matched = cfg.with_overrides({"hydraulics.jp_kg": heavy, "firmware.jp_kg": heavy})
    mismatched = cfg.with_overrides({"hydraulics.jp_kg": heavy})  # firmware stays nominal
    assert mismatched.get("firmware.jp_kg") == cfg.get("hydraulics.jp_kg")
    return {(name, ctl): _f3_run(c, ctl)
            for name, c in (("matched", matched), ("mismatched", mismatched))
            for ctl in ("current", "velocity")}


def test_current_based_step_feels_the_mismatch(runs):
    rise_m, t, f_m = runs["matched", "current"]
    rise_x, _, f_x = runs["mismatched", "current"]
    assert not np.array_equal(f_m, f_x)
    # Measured: 5.2 ms matched, 5.0 ms with the firmware's J_p 10 % low; the observer's
    # extra push shows in the first milliseconds of the step.
    assert rise_x < rise_m
    assert abs(rise_x - rise_m) <= 1e-3
    for rise in (rise_m, rise_x):
        assert abs(rise * 1e3 - 5.0) <= 2.0
    early = (t > 0) & (t < 0.004)
    assert np.mean(f_x[early]) > np.mean(f_m[early])


def test_velocity_based_step_does_not_use_jp(runs):
    _, _, f_m = runs["matched", "velocity"]
    _, _, f_x = runs["mismatched", "velocity"]
    assert np.array_equal(f_m, f_x)
