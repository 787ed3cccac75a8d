"""The candidate tests' algebra (hil.identify.candidates): the declared parameters' columns
from one tangent-linear simulation against the simulated forward differences, and the
projection off them by a Gram solve against the pseudo-inverse it replaces.

The tangent's columns are the forward difference's to first order in the step (1e-4 of
each parameter): here within 2e-4 of each column's norm (bound 1e-2), on a bench record
within 1e-3 but the timing skew's near its bound, whose forward and backward differences
themselves differ by a fifth there; a dropped term gives order one. The candidates'
verdicts must not change (the coefficients here move by under 1e-3 of a standard error;
bound 0.05)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify import candidates
from hil.identify.effects import library
from hil.identify.experiment import prepare
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config

_DECLARED = ["gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod",
             "strain_offset_n", "pc_force_n", "puls4_flow_s", "puls4_torque_c"]


def test_the_projection_is_the_pseudo_inverse_s():
    """``_Projection(J^T).coef(x)`` equals ``_pinv(J) @ x`` to rounding, for columns of
    very different scales, one of them twice and one zero (the pseudo-inverse's rank
    cut-off), and with no declared column at all."""
    rng = np.random.default_rng(5)
    n = 4000
    jac = rng.normal(size=(n, 6)) * np.array([1e-3, 1.0, 1e4, 3.0, 1.0, 1.0])
    jac[:, 4] = jac[:, 1]
    jac[:, 5] = 0.0
    x = rng.normal(size=(n, 3)) + jac[:, :3] @ rng.normal(size=(3, 3))
    want = candidates._pinv(jac) @ x
    got = candidates._Projection(np.ascontiguousarray(jac.T)).coef(x)
    scale = np.abs(want).max(axis=0)
    assert np.all(np.abs(got - want) <= 1e-9 * scale)
    # the projected columns: what the test regresses on
    assert np.allclose(x - jac @ got, x - jac @ want, rtol=0, atol=1e-9 * np.abs(x).max())
    empty = candidates._Projection(np.zeros((0, n))).coef(x)
    assert empty.shape == (0, 3)


@pytest.fixture(scope="module")
def round_inputs():
    rig = generate_rig("conrod_fixed", ["pump_coulomb_friction", "pump_pulsation"],
                       seconds=1.5, seed=2)
    exp = prepare(rig.data, load_config("hydra_default"), "zoh")
    model = FastModel(exp, n_sub=max(1, FastModel(exp).n_sub // 2))
    theta = model.start_vector()
    # a model that runs effects: the pump's friction and the fourth pulsation order in
    theta[IDX["pc_force_n"]] = 30.0
    theta[IDX["puls4_flow_s"]] = 0.01
    theta[IDX["puls4_torque_c"]] = 0.5
    out = model.outputs(theta)
    # the residual: a seal's friction the model lacks, and white noise of a thousandth of
    # each channel's spread (the weights)
    with_seal = theta.copy()
    with_seal[IDX["sf_coulomb_n"]] = 8.0
    seal = model.outputs(with_seal)
    rng = np.random.default_rng(7)
    sigma = {c: 1e-3 * float(np.std(out[c])) for c in exp.channels}
    residual = {c: seal[c] - out[c] + rng.normal(0.0, sigma[c], exp.n) for c in exp.channels}
    est = exp.est & np.all([np.isfinite(exp.measured[c]) for c in exp.channels], axis=0)
    defs = [d for d in library(exp) if d.name != "pump_coulomb_friction"
            and d.label != "pump_pulsation[order=4]"]
    return defs, model, theta, exp, sigma, residual, est


def _run(round_inputs, tangent: bool, monkeypatch):
    defs, model, theta, exp, sigma, residual, est = round_inputs
    monkeypatch.setattr(candidates, "TANGENT", tangent)
    seen: dict[str, np.ndarray] = {}
    calls = []

    class Recorded(candidates._Projection):
        def __init__(self, rows):
            seen["rows"] = rows.copy()
            super().__init__(rows)

    import hil.identify.tangent as tangent_module

    real = tangent_module.state_sensitivities

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(candidates, "_Projection", Recorded)
    monkeypatch.setattr(tangent_module, "state_sensitivities", counted)
    tests = candidates.test_candidates(defs, model.outputs, theta, IDX, exp, sigma,
                                       residual, est, exp.val, list(_DECLARED),
                                       states=model.states)
    return tests, seen["rows"], len(calls)


def test_tangent_columns_are_the_simulated_ones_and_the_verdicts_the_same(round_inputs,
                                                                          monkeypatch):
    simulated, rows_sim, n_sim = _run(round_inputs, False, monkeypatch)
    tangent, rows_tan, n_tan = _run(round_inputs, True, monkeypatch)
    assert (n_sim, n_tan) == (0, 1)  # the tangent ran once, and only when on
    for name, a, b in zip(_DECLARED, rows_sim, rows_tan, strict=True):
        norm = np.linalg.norm(a)
        assert norm > 0.0, name
        assert np.linalg.norm(b - a) <= 1e-2 * norm, (name, np.linalg.norm(b - a) / norm)
    assert [(t.label, t.status, t.params) for t in tangent] == [
        (t.label, t.status, t.params) for t in simulated]
    assert [t.label for t in candidates.rank(tangent)] == [
        t.label for t in candidates.rank(simulated)]
    tested = [(a, b) for a, b in zip(simulated, tangent, strict=True) if a.status == "tested"]
    assert len(tested) >= 3 and candidates.rank(simulated)[0].label == "seal_friction"
    for a, b in tested:
        for p in a.beta:
            assert abs(a.beta[p] - b.beta[p]) <= 0.05 * a.se[p], (a.label, p)
