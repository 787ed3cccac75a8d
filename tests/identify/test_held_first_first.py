"""A friction that can hold the piston takes its held-first refit first.

Conrod, pump and seal friction (16 s, rig seed 3): the seal's plain refit (4.2 s of CPU) and
its residual analysis (1.4 s) were made only to be compared with the held-first refit, which
leaves the residual white and is kept. For the seal (``STICK_SLIP``) the held-first refit is
made first; where it leaves the residual white and passes the verdict, no plain refit is
made. Elsewhere the rule is as before: the plain refit, and the held-first one beside it
where the plain one leaves structure, made once. No model is simulated: the rule alone, on
stubs.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hil.identify import pipeline
from hil.identify.fit import FitResult
from hil.identify.model import IDX, N_PARAMS
from hil.identify.pipeline import START_MARGIN, STICK_SLIP, _Loop

SEAL = SimpleNamespace(label="seal_friction", params=("sf_coulomb_n", "sf_static_extra_n"))
PUMP = SimpleNamespace(label="pump_coulomb_friction", params=("pc_force_n",))


def _fit(cost: float, excess: float) -> FitResult:
    # the estimation cost and the residual's structure a stub loop reads back
    return FitResult(np.zeros(N_PARAMS), ["dc"], {}, {},
                     {"cost": np.array([cost]), "excess": np.array([excess])},
                     np.zeros((1, 5)))


def _loop(monkeypatch, made: tuple | None, plain: FitResult, refused: str = "") -> SimpleNamespace:
    monkeypatch.setattr(pipeline, "structure_excess", lambda a: a)
    calls: list[str] = []
    loop = SimpleNamespace(added=[SimpleNamespace(label="other")], unbiased=True, est_mask=None,
                           said=[], calls=calls)
    loop.say = loop.said.append
    loop.analysis_of = lambda fit: float(fit.outputs["excess"][0])
    loop.weighted_ss = lambda out, mask: float(out["cost"][0])
    loop.verdict_on = lambda ds_, new, held: refused

    def held_first(d, beta):
        calls.append("held_first")
        return made

    def refit_with(d, beta, **kw):
        calls.append("plain")
        return plain, {}

    loop.held_first = held_first
    loop.refit_with = refit_with
    loop.white_and_passes = lambda d, m: _Loop.white_and_passes(loop, d, m)
    loop.others_held_chosen = (lambda d, beta, p, rnd, m=None:
                               _Loop.others_held_chosen(loop, d, beta, p, rnd, m))
    return loop


def test_the_seal_is_a_stick_slip_friction_and_the_pump_friction_is_not():
    assert STICK_SLIP.intersection(SEAL.params)
    assert not STICK_SLIP.intersection(PUMP.params)
    assert "sf_coulomb_n" in IDX


def test_a_white_held_first_refit_of_the_seal_is_kept_without_a_plain_refit(monkeypatch):
    made = (_fit(19155.0, 0.0), {"c_rod": "held"}, "the refit with pc_force_n held first")
    loop = _loop(monkeypatch, made, _fit(28600.0, 68.0))
    new, held, other = _Loop.refit_added(loop, SEAL, {}, ["dc"], 1)
    assert new is made[0] and held == {"c_rod": "held"} and other is None
    assert loop.calls == ["held_first"]
    assert "white" in loop.said[-1]


@pytest.mark.parametrize("refused", ["", "not credible after the refit (sf_coulomb_n: held)"])
def test_a_held_first_refit_that_leaves_structure_is_compared_with_the_plain_one(
        monkeypatch, refused):
    # not white (or white but refused by the verdict): the plain refit is made, and the
    # held-first one already made is the one compared with it (not made again)
    plain = _fit(9734.0, 64.0)
    cases = [(8769.0, 36.0, True), ((1.0 - 0.5 * START_MARGIN) * 9734.0, 36.0, False)]
    if refused:
        cases.append((5000.0, 0.0, True))  # white, refused: compared, kept where lower
    for cost, excess, kept in cases:
        made = (_fit(cost, excess), {}, "the refit with pc_force_n held first")
        loop = _loop(monkeypatch, made, plain, refused)
        new, _, _ = _Loop.refit_added(loop, SEAL, {}, ["dc"], 1)
        assert loop.calls == ["held_first", "plain"]
        assert (new is made[0]) == kept, (cost, excess)


def test_other_effects_keep_the_plain_refit_first(monkeypatch):
    made = (_fit(100.0, 0.0), {}, "the refit with puls held first")
    # the plain refit leaves the residual white: no held-first refit at all
    loop = _loop(monkeypatch, made, _fit(621.0, 0.0))
    new, _, _ = _Loop.refit_added(loop, PUMP, {}, ["dc"], 1)
    assert loop.calls == ["plain"] and new is not made[0]
    # it leaves structure: the held-first refit after it, kept where lower by the margin
    loop = _loop(monkeypatch, made, _fit(621.0, 5.4))
    new, _, _ = _Loop.refit_added(loop, PUMP, {}, ["dc"], 1)
    assert loop.calls == ["plain", "held_first"] and new is made[0]


def test_the_seal_near_the_configuration_or_first_takes_the_plain_refit(monkeypatch):
    made = (_fit(100.0, 0.0), {}, "held first")
    # the fit near the configuration (no robust start): the plain refit alone
    loop = _loop(monkeypatch, made, _fit(621.0, 0.0))
    _Loop.refit_added(loop, SEAL, {}, [], 1)
    assert loop.calls == ["plain"]
    # where the input noise biases the cost (no low-pass): the plain refit alone
    loop = _loop(monkeypatch, made, _fit(621.0, 0.0))
    loop.unbiased = False
    _Loop.refit_added(loop, SEAL, {}, ["dc"], 1)
    assert loop.calls == ["plain"]
