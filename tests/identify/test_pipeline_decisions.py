"""Decisions of the identification loop that send a fit to another start: a linear parameter
whose configured value beats the fit's own (the fit sits behind a hump along it), and a
joint set whose refit shrank some members to nothing (the rest is tried alone)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify import pipeline
from hil.identify.effects import EFFECTS
from hil.identify.experiment import prepare
from hil.identify.fit import FitResult
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def _fit_at(model: FastModel, theta: np.ndarray, free: list[str]) -> FitResult:
    """A fit result at ``theta`` (weights: its own residual rms per channel)."""
    out = model.outputs(theta)
    exp = model.exp
    sigma = {c: float(np.sqrt(np.nanmean((exp.measured[c] - out[c])[exp.est] ** 2)))
             for c in exp.channels}
    return FitResult(theta, free, {}, sigma, out, np.zeros((1, 1)))


@pytest.fixture(scope="module")
def free_piston_loop():
    """A loop on a short free-piston record with the rig's own linear parameters as its
    fit (no baseline fit: only the probes are under test)."""
    rig = generate_rig("free_piston", seconds=0.6, seed=2)
    exp = prepare(rig.data, load_config("hydra_default"), "bl")
    model = FastModel(exp)
    theta = model.start_vector()
    truth = rig.truth["parameters"]
    free = ["gain_n_per_a", "ds", "dc", "ks", "jp", "jc"]
    for name in free:
        theta[IDX[name]] = truth[name]
    loop = object.__new__(pipeline._Loop)
    loop.model, loop.exp, loop.configured = model, exp, model.start_vector()
    return loop, theta, free


def test_configured_value_that_beats_the_fit_is_named(free_piston_loop):
    """At the rig's own parameters no configured value fits better; with J_p moved to 1.6x
    the configured J_p (within 15 % of the rig's) does, and only J_p is named."""
    loop, theta, free = free_piston_loop
    loop.current = _fit_at(loop.model, theta, free)
    assert loop.better_configured() == []
    off = theta.copy()
    off[IDX["jp"]] *= 1.6
    loop.current = _fit_at(loop.model, off, free)
    assert loop.better_configured() == ["jp"]


def test_a_set_with_a_shrunk_member_leaves_the_rest():
    """A pump friction at its size beside a pulsation shrunk to a hundredth of its realistic
    size: the pulsation is the shrunk one; both at their sizes: none is."""
    exp = prepare(generate_rig("free_piston", seconds=0.2, seed=1).data,
                  load_config("hydra_default"), "bl")
    defs = {d.label: d for name in ("pump_coulomb_friction", "pump_pulsation")
            for d in EFFECTS[name].definitions(exp)}
    pair = [defs["pump_coulomb_friction"], defs["pump_pulsation[order=3]"]]
    theta = np.zeros(len(IDX))
    theta[IDX["pc_force_n"]] = 80.0
    theta[IDX["puls3_flow_s"]] = 1e-4
    theta[IDX["puls3_torque_c"]] = -0.5
    fit = FitResult(theta, [], {}, {}, {}, np.zeros((1, 1)))
    assert [d.label for d in pipeline._shrunk(pair, fit)] == ["pump_pulsation[order=3]"]
    theta[IDX["puls3_torque_c"]] = -20.0
    assert pipeline._shrunk(pair, fit) == []
