"""The series stiffness that puts the model's piston line on the record's.

Both lines are white noise rung through a narrow resonance (numpy only): the record's at
the undamped frequency of a "rig" stiffness, the model's at the fit's. The restart's
``k_s`` must be the rig's, with the rod's stiffness in the sum under the square root.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import iirpeak, lfilter

from hil.identify.model import IDX, N_PARAMS
from hil.identify.resonance import stiffness_at_line, undamped_hz

FS = 5000.0
N = 30000


def _theta(ks: float, jc: float = 0.29, k_rod: float = 1.43e6) -> np.ndarray:
    th = np.zeros(N_PARAMS)
    th[IDX["ks"]], th[IDX["jc"]], th[IDX["k_rod"]] = ks, jc, k_rod
    return th


def _rung(hz: float, seed: int, floor: float = 0.05) -> np.ndarray:
    rng = np.random.default_rng(seed)
    b, a = iirpeak(hz, 200.0, fs=FS)
    return 1e5 * (lfilter(b, a, rng.normal(size=N)) + floor * rng.normal(size=N))


def _exp(load: str, measured: np.ndarray) -> SimpleNamespace:
    return SimpleNamespace(load=load, data=SimpleNamespace(sample_rate_hz=FS),
                           measured={"p_pump_a": measured, "p_pump_b": np.zeros(N)})


def _outputs(y: np.ndarray) -> dict[str, np.ndarray]:
    return {"p_pump_a": y, "p_pump_b": np.zeros(N)}


@pytest.mark.parametrize("load", ["conrod", "free"])
def test_the_restart_stiffness_moves_the_models_line_onto_the_records(load):
    k_rod = 5e6 if load == "conrod" else 0.0
    rig, fit = _theta(1.93e7, k_rod=k_rod), _theta(2.24e7, k_rod=k_rod)
    exp = _exp(load, _rung(undamped_hz(SimpleNamespace(load=load), rig), 1))
    line = stiffness_at_line(exp, fit, _outputs(_rung(undamped_hz(exp, fit), 2)))
    assert line is not None
    ks, f_rec, f_mod = line
    assert f_rec < f_mod
    # the Welch bins are ~1.2 Hz wide at ~1.4 kHz, the line a few bins: within 1 %
    assert ks == pytest.approx(1.93e7, rel=0.01)


def test_no_restart_without_a_line_on_a_fixed_piston_or_on_the_line():
    fit = _theta(2.24e7)
    model = _outputs(_rung(undamped_hz(SimpleNamespace(load="conrod"), fit), 2))
    white = np.random.default_rng(3).normal(size=N)
    assert stiffness_at_line(_exp("conrod", white), fit, model) is None
    rung = _rung(1300.0, 1)
    assert stiffness_at_line(_exp("fixed", rung), fit, model) is None
    assert stiffness_at_line(_exp("conrod", model["p_pump_a"]), fit, model) is None
    assert math.isfinite(undamped_hz(SimpleNamespace(load="conrod"), fit))
