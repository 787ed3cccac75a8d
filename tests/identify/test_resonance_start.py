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


def test_a_model_line_above_nyquist_is_looked_for_around_the_configured_resonance():
    # the fit's J_c ran to 0.07x (its line at ~3.4 kHz, above the record's 2.5 kHz): the
    # band around it holds no bin; around the configured resonance the record's line is
    # found, and the model's undamped frequency stands for its line
    rig, fit = _theta(1.93e7, jc=0.29, k_rod=0.0), _theta(1.013e7, jc=0.0217, k_rod=0.0)
    configured = _theta(2.24e7, jc=0.295, k_rod=0.0)
    f_rig = undamped_hz(SimpleNamespace(load="free"), rig)
    exp = _exp("free", _rung(f_rig, 1))
    model = _outputs(np.random.default_rng(4).normal(size=N))
    assert undamped_hz(exp, fit) > FS / 2
    assert stiffness_at_line(exp, fit, model) is None
    line = stiffness_at_line(exp, fit, model, configured)
    assert line is not None
    ks, f_rec, f_mod = line
    assert f_rec == pytest.approx(f_rig, rel=0.01)
    assert f_mod == pytest.approx(undamped_hz(exp, fit))
    # k_s that puts the line there with the fit's J_c
    assert ks == pytest.approx(0.0217 * (2 * math.pi * f_rig) ** 2, rel=0.02)
    # a model line inside the record's band is looked for around it, as before
    near = _theta(2.24e7, k_rod=0.0)
    assert stiffness_at_line(exp, near, _outputs(_rung(undamped_hz(exp, near), 2)),
                             configured)[2] < FS / 2
