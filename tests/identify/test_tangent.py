"""The tangent-linear simulation (hil.identify.tangent) against central differences of the
simulation itself, and the fit's Jacobian from it against the forward-difference one.

The states' derivatives along each column must match ``(z(theta + h) - z(theta - h)) / 2h``
of :meth:`FastModel.states` with the friction solves' tolerance tightened (their early
returns otherwise leave ~1e-10 of a velocity in a difference of two runs): every load, every
effect on the path, every parameter the tangent differentiates. The bound, 1e-3 of each
state's rms derivative along the column, is far above the agreement found (1e-10 to 1e-7
for most columns; up to 1e-4 on a small column, the k_s(x) curvature's on a rod-held
piston, where the differences' own noise is of that order) and far below what a dropped
term gives (the friction's slope F'(v): order one)."""

from __future__ import annotations

import numpy as np
import pytest

import hil.identify.fit as fit_module
from hil.identify.experiment import prepare
from hil.identify.fit import OutputErrorFit
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from hil.identify.tangent import on_path, state_sensitivities
from plant.config import load_config

_FRICTIONS = {"pc_force_n": 40.0, "sf_coulomb_n": 10.0, "sf_static_n": 15.0,
              "pc_eps_m_per_s": 2e-4, "sf_vs_m_per_s": 4e-3, "sf_eps_m_per_s": 1.5e-3,
              "pc_shape": 0.3, "sf_shape": 0.6}
_PULSATION = {"puls1_flow_s": 0.02, "puls1_flow_c": -0.01, "puls2_flow_s": 0.01,
              "puls1_torque_s": 0.5, "puls2_torque_c": 1.0}
_LINEAR = ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod", "skew_s",
           "delay_s")

#: (load, rig effects, parameter values, columns): every effect on the tangent's path.
CASES = {
    "fixed": ("fixed_piston", ["viscosity_temperature", "pump_pulsation"],
              {"pc_force_n": 40.0, "pc_eps_m_per_s": 2e-4, "visc_coeff_per_c": 0.03,
               **_PULSATION},
              ("gain_n_per_a", "ds", "dp", "ks", "jp", "skew_s", "pc_force_n",
               "pc_eps_m_per_s", "visc_coeff_per_c", "puls1_flow_s", "puls2_torque_c")),
    "free": ("free_piston", ["stiffness_vs_position"],
             {**_FRICTIONS, "ks_k1": 0.2, "ks_k2": 0.3},
             (*_LINEAR[:7], "skew_s", *_FRICTIONS, "ks_k1", "ks_k2")),
    "conrod": ("conrod_fixed", ["viscosity_temperature", "pump_pulsation"],
               {**_FRICTIONS, **_PULSATION, "ks_k1": 0.2, "ks_k2": 0.3,
                "visc_coeff_per_c": 0.03, "delay_s": 1e-4},
               (*_LINEAR, *_FRICTIONS, "ks_k1", "ks_k2", "visc_coeff_per_c",
                "puls1_flow_s", "puls2_flow_s", "puls1_torque_s", "puls2_torque_c")),
}


def _model(load: str, effects: list[str], seconds: float = 0.4) -> FastModel:
    rig = generate_rig(load, effects, seconds=seconds, seed=2)
    return FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))


def _columns(model: FastModel, theta: np.ndarray, names: tuple[str, ...]):
    plus, minus, steps = [], [], []
    for name in names:
        step = (1e-5 * model.exp.dt if name in ("skew_s", "delay_s")
                else 1e-5 * max(abs(theta[IDX[name]]), 1e-3))
        tp = theta.copy()
        tp[IDX[name]] += step
        tm = theta.copy()
        tm[IDX[name]] -= step
        plus.append(tp)
        minus.append(tm)
        steps.append(step)
    return plus, minus, np.array(steps)


@pytest.mark.parametrize("case", sorted(CASES))
def test_tangent_matches_central_differences_of_the_simulation(case):
    load, effects, values, names = CASES[case]
    model = _model(load, effects)
    model.solve_tol = 1e-4
    theta = model.start_vector()
    for name, value in values.items():
        theta[IDX[name]] = value
    plus, minus, steps = _columns(model, theta, names)
    sens = state_sensitivities(model, theta, plus, minus, steps, None)
    moving = 3 if load == "fixed_piston" else 5
    for j, name in enumerate(names):
        assert on_path(model, theta, plus[j], minus[j]), name
        fd = (model.states(plus[j], keep=False) - model.states(minus[j], keep=False)) / (
            2.0 * steps[j])
        rms = np.sqrt(np.mean(fd[:, :moving] ** 2, axis=0))
        err = np.sqrt(np.mean((sens[j][:, :moving] - fd[:, :moving]) ** 2, axis=0))
        if not rms.any():  # a rod's parameters on a free piston: no effect at all
            assert not err.any(), name
            continue
        assert np.all(err <= 1e-3 * rms + 1e-300), (name, err / rms)


def test_a_step_that_switches_an_effect_on_is_left_to_a_simulation():
    """A friction at zero moved by its column: the step switches the solve on, which is no
    derivative of the path the tangent follows; so is a shape velocity taken from the
    preset (zero in the vector)."""
    model = _model("free_piston", [])
    theta = model.start_vector()
    theta[IDX["pc_force_n"]] = 40.0
    for name, expected in (("sf_coulomb_n", False), ("sf_vs_m_per_s", True),
                           ("pc_eps_m_per_s", False), ("pc_force_n", True), ("ks", True)):
        theta_on = theta.copy()
        if name == "sf_vs_m_per_s":
            theta_on[IDX["sf_coulomb_n"]] = 10.0
            theta_on[IDX[name]] = 4e-3
        plus, minus, _ = _columns(model, theta_on, (name,))
        assert on_path(model, theta_on, plus[0], minus[0]) == expected, name


def _fit_problem(tangent: bool, monkeypatch):
    monkeypatch.setattr(fit_module, "TANGENT", tangent)
    model = _model("conrod_fixed", ["pump_coulomb_friction"], seconds=1.0)
    theta = model.start_vector()
    theta[IDX["pc_force_n"]] = 30.0
    free = ["gain_n_per_a", "ds", "dp", "dc", "ks", "k_rod", "c_rod", "skew_s",
            "strain_offset_n", "pc_force_n"]
    fitter = OutputErrorFit(model, {"skew_s": model.exp.dt, "pc_force_n": 10.0})
    return fitter, theta, free


def test_the_jacobian_from_the_tangent_is_the_forward_difference_one(monkeypatch):
    """Column by column within the forward difference's own truncation error, from one
    tangent simulation for every simulated column (the output-only offset: none)."""
    jacs = {}
    sims = {}
    for tangent in (False, True):
        fitter, theta, free = _fit_problem(tangent, monkeypatch)
        fitter._ref = {n: theta[IDX[n]] for n in free if n in fit_module.LOG_PARAMS}
        sigma = {c: 1.0 for c in fitter.exp.channels}
        fun, jac = fitter._problem(free, theta, sigma, fitter.fit_mask())
        x = fitter._to_x(theta, free)
        fun(x)
        before = fitter.n_sims
        jacs[tangent] = jac(x)
        sims[tangent] = fitter.n_sims - before
    assert sims == {False: len(free) - 1, True: 1}
    fd, tan = jacs[False], jacs[True]
    rel = np.linalg.norm(tan - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert np.all(rel < 1e-3), rel


def test_a_fit_with_the_tangent_reaches_the_forward_difference_fits_optimum(monkeypatch):
    results = {}
    for tangent in (False, True):
        fitter, theta, free = _fit_problem(tangent, monkeypatch)
        results[tangent] = fitter.fit(theta, free, passes=2, max_nfev=30)
    fd, tan = results[False], results[True]
    for name in fd.free:
        se = fd.se[name]
        assert abs(tan.value(name) - fd.value(name)) <= 0.1 * se, (
            name, tan.value(name), fd.value(name), se)


def test_a_linear_model_keeps_a_simulation_per_column(monkeypatch, jacobian_at):
    """Without an effect on the path the model's sub-step is a few multiply-adds, and the
    tangent would cost more than the columns it replaces: every column is simulated (with
    the linear model's own recursion switched off: tests/identify/test_linear_columns.py)."""
    monkeypatch.setattr(fit_module, "LINEAR_COLUMNS", False)
    fitter, theta, free = _fit_problem(True, monkeypatch)
    theta[IDX["pc_force_n"]] = 0.0
    free.remove("pc_force_n")
    fitter._ref = {n: theta[IDX[n]] for n in free if n in fit_module.LOG_PARAMS}
    _, sims = jacobian_at(fitter, free, theta)
    assert sims == len(free) - 1  # the offset maps the same states
