"""A linear model's Jacobian columns by the recursion of their states' differences
(hil.identify.linear_columns) against the simulations they replace.

The recursion computes ``z_j - z`` exactly (a finite difference, not a derivative), so it
must match the two simulations' difference at any step: with steps of a thousandth (the
simulations' own rounding then a 1e-13 of the difference) the bound, 1e-8 of each column's
rms per state, is far above the agreement found (1e-11 to 1e-9) and far below a dropped
term (the force's map from a sub-step, the start states' difference: order one)."""

from __future__ import annotations

import numpy as np
import pytest

import hil.identify.fit as fit_module
from hil.identify import linear_columns
from hil.identify.experiment import prepare
from hil.identify.fit import OutputErrorFit
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config

#: (rig load, the parameters the linear simulation reads there)
CASES = {
    "fixed": ("fixed_piston", ("gain_n_per_a", "ds", "dp", "ks", "jp", "skew_s", "delay_s")),
    "free": ("free_piston", ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "skew_s")),
    "conrod": ("conrod_fixed", ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod",
                                "c_rod", "skew_s", "delay_s")),
}


def _model(load: str, seconds: float = 0.4) -> FastModel:
    rig = generate_rig(load, [], seconds=seconds, seed=2)
    return FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))


def _point(model: FastModel) -> np.ndarray:
    theta = model.start_vector()
    theta[IDX["skew_s"]] = 0.13 * model.exp.dt  # off zero: a band-limited shift
    return theta


def _moved(model: FastModel, theta: np.ndarray, names: tuple[str, ...], rel: float):
    columns, steps = [], []
    for name in names:
        step = (rel * model.exp.dt if name in ("skew_s", "delay_s")
                else rel * abs(theta[IDX[name]]))
        th = theta.copy()
        th[IDX[name]] += step
        columns.append(th)
        steps.append(step)
    return columns, np.array(steps)


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_recursion_is_the_difference_of_the_two_simulations(case):
    load, names = CASES[case]
    model = _model(load)
    theta = _point(model)
    n_stop = 1500  # a head, as a fit's iterations simulate
    z = model.states(theta, n_stop)
    columns, steps = _moved(model, theta, names, 1e-3)
    assert all(linear_columns.applies(model, theta, th) for th in columns)
    diff = linear_columns.state_differences(model, theta, z, columns, steps, n_stop)
    assert diff.shape == (len(names), n_stop, 5)
    for j, name in enumerate(names):
        simulated = (model.states(columns[j], n_stop, keep=False) - z)[:n_stop] / steps[j]
        scale = np.sqrt(np.mean(simulated ** 2, axis=0))
        moving = scale > 0.0
        err = np.sqrt(np.mean((diff[j] - simulated) ** 2, axis=0))
        assert np.all(err[moving] <= 1e-6 * scale[moving]), (name, err / np.maximum(scale,
                                                                                  1e-300))
        assert np.all(diff[j][:, ~moving] == 0.0), name


def test_a_column_that_switches_an_effect_on_or_moves_the_outputs_only_is_not_taken():
    model = _model("free_piston")
    theta = _point(model)
    for name, taken in (("pc_force_n", False), ("sf_coulomb_n", False),
                        ("strain_offset_n", False), ("ks", True)):
        th = theta.copy()
        th[IDX[name]] += 1.0
        assert linear_columns.applies(model, theta, th) == taken, name
    on = theta.copy()
    on[IDX["pc_force_n"]] = 40.0
    assert not linear_columns.linear(model, on)


def _jacobian(model: FastModel, on: bool, monkeypatch, jacobian_at) -> tuple[np.ndarray, int]:
    monkeypatch.setattr(fit_module, "LINEAR_COLUMNS", on)
    theta = _point(model)
    free = ["gain_n_per_a", "ds", "dp", "dc", "ks", "k_rod", "c_rod", "skew_s",
            "strain_offset_n", "lag_pressure_s"]
    theta[IDX["lag_pressure_s"]] = 1e-4
    fitter = OutputErrorFit(model, fit_module.NUISANCE_SCALES(model.exp.dt))
    fitter._ref = {n: theta[IDX[n]] for n in free if n in fit_module.LOG_PARAMS}
    return jacobian_at(fitter, free, theta)


def test_the_fits_jacobian_is_the_forward_difference_one_without_its_simulations(
        monkeypatch, jacobian_at):
    """Every simulated column of a linear conrod model from the recursion (no simulation),
    each within the forward difference's own rounding (1e-6 steps: a 1e-10 of a state in
    the difference of two runs, amplified where a column is small) of the simulated one."""
    model = _model("conrod_fixed", seconds=1.0)
    fd, sims_fd = _jacobian(model, False, monkeypatch, jacobian_at)
    rec, sims_rec = _jacobian(model, True, monkeypatch, jacobian_at)
    assert (sims_fd, sims_rec) == (8, 0)  # the offset and the lag map the same states
    rel = np.linalg.norm(rec - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert np.all(rel < 1e-5), rel
