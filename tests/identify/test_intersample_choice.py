"""How the identification tells a held (``zoh``) logged current from a sampled continuous one
(``bl``, ``foh``): each mode with its best timing skew at the provisional fit."""

import re
from types import SimpleNamespace

import pytest
from threadpoolctl import threadpool_limits

from hil.identify import pipeline
from hil.identify.pipeline import choose_intersample
from hil.identify.rig import generate_rig
from plant.config import load_config

_CFG = load_config("hydra_default")
_MODE = re.compile(r"(bl|foh|zoh) ([0-9.]+) \(skew ([+-][0-9]+) us(, on its search edge)?\)")


def _choose(rig):
    with threadpool_limits(limits=1, user_api="blas"):
        exp, theta = choose_intersample(rig.data, _CFG, None, lambda msg: None)
    modes = {m: (float(c), float(s), bool(edge))
             for m, c, s, edge in _MODE.findall(exp.intersample_reason)}
    return exp, modes


@pytest.mark.parametrize("load", ["fixed_piston", "conrod_fixed"])
def test_a_held_current_finds_its_skew_inside_the_search(load):
    """A current the motor got held over each sample: the bl fit takes it about half a
    sample late, and zoh's search is centred half a sample earlier, around the true skew 0
    (centred half a sample later, its best lay on the search's edge at 2-12x the cost)."""
    rig = generate_rig(load, [], seconds=2.0, seed=1, intersample="zoh")
    exp, modes = _choose(rig)
    dt_us = exp.dt * 1e6
    cost, skew, edge = modes["zoh"]
    assert not edge, exp.intersample_reason
    assert abs(skew) < 0.25 * dt_us, exp.intersample_reason
    assert cost < 1.01, exp.intersample_reason
    # bl takes the held current about half a sample late
    assert 0.25 * dt_us < modes["bl"][1] < 0.75 * dt_us, exp.intersample_reason


def test_a_mode_whose_best_skew_is_on_the_edge_ties(monkeypatch):
    """bl and foh stopped on their search's upper edge half a per cent above zoh: their cost
    is lower beyond it, so zoh has not shown it fits better; the tie goes to bl."""
    calls = []

    def edge_for_continuous(cost, bounds, method, options):
        calls.append(bounds)
        lo, hi = bounds
        if len(calls) <= 2:  # bl, foh
            x = hi - 1e-7
            return SimpleNamespace(x=x, fun=1.005 * cost(x))
        x = 0.5 * (lo + hi)
        return SimpleNamespace(x=x, fun=cost(x))

    monkeypatch.setattr(pipeline, "minimize_scalar", edge_for_continuous)
    rig = generate_rig("fixed_piston", [], seconds=1.0, seed=2)
    exp, modes = _choose(rig)
    assert len(calls) == 3
    assert modes["bl"][2] and modes["foh"][2] and not modes["zoh"][2]
    assert exp.intersample == "bl", exp.intersample_reason
    assert "fit equally well" in exp.intersample_reason
