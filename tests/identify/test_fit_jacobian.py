"""The fit's Jacobian: columns of parameters that act on the outputs only reuse the states.

An offset, a gauge's drift, the sensors' lags and the clips never enter the simulation
(:data:`hil.identify.model.OUTPUT_ONLY`), so their Jacobian columns map the base states to
new outputs instead of simulating again. That shortcut must give the very same Jacobian as
simulating every column, and a parameter the simulation reads must never be in the set."""

from __future__ import annotations

import numpy as np

from hil.identify.experiment import prepare
from hil.identify.fit import OutputErrorFit
from hil.identify.model import IDX, OUTPUT_ONLY, PARAM_NAMES, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def _model() -> FastModel:
    rig = generate_rig("conrod_fixed", ["strain_thermal_drift"], seconds=0.8, seed=2)
    return FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))


def test_output_only_parameters_leave_the_states_alone():
    """Each of them moved, with the simulation's effects on: the states bit for bit the
    same; the simulation's own parameters (a control) move them."""
    model = _model()
    theta = model.start_vector()
    for name, value in (("pc_force_n", 40.0), ("sf_coulomb_n", 10.0), ("sf_static_n", 15.0),
                        ("visc_coeff_per_c", 0.03), ("puls1_flow_s", 0.01)):
        theta[IDX[name]] = value
    base = model.states(theta)
    control = ("gain_n_per_a", "ks", "k_rod", "skew_s", "pc_force_n", "sf_coulomb_n")
    assert OUTPUT_ONLY <= set(PARAM_NAMES)
    for name in sorted(OUTPUT_ONLY) + list(control):
        th = theta.copy()
        th[IDX[name]] += 1e-3 * (abs(th[IDX[name]]) or 1.0)
        assert np.array_equal(model.states(th), base) == (name in OUTPUT_ONLY), name


def test_the_shortcut_gives_the_jacobian_of_a_simulation_per_column(monkeypatch):
    import hil.identify.fit as fit_module

    # the forward differences' shortcut (the tangent's columns: tests/identify/test_tangent.py)
    monkeypatch.setattr(fit_module, "TANGENT", False)
    # (and the linear model's recursion: tests/identify/test_linear_columns.py)
    monkeypatch.setattr(fit_module, "LINEAR_COLUMNS", False)
    model = _model()
    theta = model.start_vector()
    theta[IDX["lag_pressure_s"]] = 6e-5
    theta[IDX["lag_strain_s"]] = 1.5e-4
    theta[IDX["drift_n_per_c"]] = 1.0
    free = ["gain_n_per_a", "ks", "strain_offset_n", "lag_pressure_s", "lag_strain_s",
            "drift_n_per_c"]
    assert set(free) & OUTPUT_ONLY
    fitter = OutputErrorFit(model)
    fitter._ref = {n: max(abs(theta[IDX[n]]), 1e-12) for n in free if n in ("gain_n_per_a", "ks")}
    sigma = {c: 1.0 for c in model.exp.channels}
    mask = fitter.fit_mask()
    x = fitter._to_x(theta, free)
    _, jac = fitter._problem(free, theta, sigma, mask)
    fast = jac(x)
    sims_fast = fitter.n_sims
    monkeypatch.setattr(fit_module, "OUTPUT_ONLY", frozenset())
    _, jac_all = fitter._problem(free, theta, sigma, mask)
    slow = jac_all(x)
    assert np.array_equal(fast, slow)
    assert fitter.n_sims - sims_fast == len(free) + 1  # every column simulated, and the base
    assert sims_fast == len(free) + 1 - len(set(free) & OUTPUT_ONLY)


def test_columns_are_not_kept_and_one_thread_gives_the_same_jacobian():
    """A fit's columns leave the model's kept runs alone (a vector asked for again, the
    fit's point, stays kept), and the Jacobian does not depend on the thread count."""
    import threading

    from hil.identify.model import map_threads, set_threads

    model = _model()
    theta = model.start_vector()
    theta[IDX["pc_force_n"]] = 40.0
    free = ["gain_n_per_a", "ks", "pc_force_n", "strain_offset_n"]
    fitter = OutputErrorFit(model)
    fitter._ref = {n: max(abs(theta[IDX[n]]), 1e-12) for n in ("gain_n_per_a", "ks")}
    sigma = {c: 1.0 for c in model.exp.channels}
    mask = fitter.fit_mask()
    x = fitter._to_x(theta, free)
    _, jac = fitter._problem(free, theta, sigma, mask)
    several = jac(x)
    assert len(model._runs) == 1  # the base point only, not its columns
    try:
        set_threads(1)
        ids = map_threads(lambda _: threading.get_ident(), range(4))
        assert set(ids) == {threading.get_ident()}
        one = jac(x)
    finally:
        set_threads(None)
    assert np.array_equal(one, several)


def test_the_assembled_jacobian_is_the_column_by_column_one():
    """The Jacobian as assembled (the tangent's columns on the outputs' samples only, an
    output-only column on the channels it moves, each written into its row) against each
    column computed whole: the base states copied and stepped along the tangent, every
    channel's residual, ``(r - r0) / step``; to the bit, on a head of the record (the
    iterations' mask) and on all of it."""
    model = _model()
    theta = model.start_vector()
    theta[IDX["pc_force_n"]] = 40.0
    theta[IDX["lag_pressure_s"]] = 6e-5
    theta[IDX["lag_strain_s"]] = 1.5e-4
    free = ["gain_n_per_a", "ks", "k_rod", "pc_force_n", "strain_offset_n",
            "lag_pressure_s", "lag_strain_s", "drift_n_per_c"]
    fitter = OutputErrorFit(model, {"pc_force_n": 10.0})
    fitter._ref = {n: theta[IDX[n]] for n in ("gain_n_per_a", "ks", "k_rod")}
    sigma = {c: 1.0 + i for i, c in enumerate(model.exp.channels)}
    full = fitter.fit_mask()
    head = full.copy()
    head[np.flatnonzero(full)[full.sum() // 3]:] = False
    for mask in (head, full):
        fun, jac = fitter._problem(free, theta, sigma, mask)
        x = fitter._to_x(theta, free)
        r0 = fun(x)
        got = jac(x)
        z0 = model.states(theta, fitter._span(mask)[0])
        steps = 1e-6 * np.maximum(1.0, np.abs(x))
        tangent = fitter._tangent_columns(x, free, theta, steps, fitter._span(mask)[0])
        assert len(tangent) == 4  # every simulated column from the tangent
        for i, name in enumerate(free):
            xx = x.copy()
            xx[i] += steps[i]
            th = fitter._to_theta(xx, free, theta)
            z = z0
            if i in tangent:
                z = z0.copy()
                z[:tangent[i].shape[0]] += steps[i] * tangent[i]
            want = (fitter._stack(th, sigma, mask, z) - r0) / steps[i]
            assert np.array_equal(got[:, i], want), name
            assert np.any(want != 0.0), name
