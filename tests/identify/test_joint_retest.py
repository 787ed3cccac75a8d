"""The joint search's candidates tested again at the robust start
(:meth:`hil.identify.pipeline._Loop.tests_for_sets`), on stand-ins: only those the last
round found not excited, at the fit with its far parameters put back, as a latest round
that ranks them; nothing where the robust start moves nothing."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np


def _test(label: str, status: str, p: float = 1.0, share: float = 0.0):
    from hil.identify.candidates import CandidateTest

    return CandidateTest(label=label, name=label.split("[")[0], params=[], status=status,
                         p_holm=p, share_val=share)


def _loop(monkeypatch, far: list[str]):
    from hil.identify import pipeline
    from hil.identify.model import IDX, N_PARAMS

    calls = []

    def test_candidates(defs, outputs, theta, idx, exp, weights, residual, est, val, free,
                        states=None):
        calls.append(([d.label for d in defs], theta.copy(), residual))
        return [_test(d.label, "tested", 0.7, 6e-4) for d in defs]

    monkeypatch.setattr(pipeline, "test_candidates", test_candidates)
    theta = np.zeros(N_PARAMS)
    theta[IDX["jp"]], theta[IDX["jc"]] = 2.7e4, 2128.0  # absorbed the frictions
    configured = np.zeros(N_PARAMS)
    configured[IDX["jp"]], configured[IDX["jc"]] = 118.0, 0.295
    labels = ("seal_friction", "pump_coulomb_friction", "pump_pulsation[order=6]",
              "strain_thermal_drift", "input_delay")
    defs = {lbl: SimpleNamespace(label=lbl, name=lbl.split("[")[0], params=(),
                                 judged_at_fit=lbl == "input_delay") for lbl in labels}
    rounds = [[_test("seal_friction", "tested", 1e-8, 0.15),
               _test("pump_coulomb_friction", "not_excited"),
               _test("pump_pulsation[order=6]", "tested", 1.0, 1e-4),
               _test("strain_thermal_drift", "tested", 1.0, -1e-7),
               _test("input_delay", "not_excited")]]
    exp = SimpleNamespace(channels=["p"], measured={"p": np.ones(3)}, val=None)
    model = SimpleNamespace(outputs=lambda th: {"p": np.full(3, th[IDX["jc"]])}, states=None)
    loop = SimpleNamespace(exp=exp, current=SimpleNamespace(theta=theta, free=["jp", "jc"],
                                                            weights={}),
                           configured=configured, rounds=rounds, defs_all=defs,
                           added_labels=set(), test_model=model, est_mask=None,
                           robust_start=lambda fit: far, say=lambda msg: None)
    return loop, calls, rounds


def test_not_excited_candidates_are_tested_again_at_the_robust_start(monkeypatch):
    from hil.identify import pipeline
    from hil.identify.model import IDX

    loop, calls, rounds = _loop(monkeypatch, ["jp", "jc"])
    # the rounds' pool never holds the pump friction: not excited at the absorbing fit
    assert "pump_coulomb_friction" not in pipeline._joint_pool(rounds, loop.defs_all, set())
    tests = pipeline._Loop.tests_for_sets(loop)
    (labels, theta, residual), = calls
    # only the one not excited (the delay is judged at its own fit), at the configured J_p,
    # J_c, against the residual there
    assert labels == ["pump_coulomb_friction"]
    assert theta[IDX["jp"]] == 118.0 and theta[IDX["jc"]] == 0.295
    np.testing.assert_allclose(residual["p"], 1.0 - 0.295)
    assert tests[:-1] == rounds
    pool = pipeline._joint_pool(tests, loop.defs_all, set())
    assert pool[:2] == ["seal_friction", "pump_coulomb_friction"]


def test_nothing_tested_again_where_the_robust_start_moves_nothing(monkeypatch):
    from hil.identify import pipeline

    loop, calls, rounds = _loop(monkeypatch, [])
    assert pipeline._Loop.tests_for_sets(loop) is rounds
    assert not calls
