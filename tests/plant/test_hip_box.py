"""The hip box's compiled tick-by-tick loop against the same steps taken one by one in
Python (each stack's own ``advance(1)``, the coupling's Python function), and its
determinism."""

from __future__ import annotations

import numpy as np
import pytest

from hil.fieldbus.hip_box import HipBox
from hil.fieldbus.topology import load_topology
from hil.sim.hip_stack import hip_config
from plant.config import load_config
from plant.hip.thigh import couple_tick

TICKS = 400


def _box() -> HipBox:
    cfg = hip_config(load_config("hydra_thesis"), reinforced=True)
    box = HipBox(load_topology("hip_one_box").boxes[0], cfg, theta0=(0.02, -0.01))
    for i in range(2):  # a force command on each cylinder, so that the joint moves
        box.board.apply(i, "force", 300.0 * (1 - 2 * i), True, False, 0.0, 0.0, 0)
    return box


def _run_compiled(box: HipBox) -> np.ndarray:
    box.advance(TICKS)
    return np.concatenate([box.joint, box.stacks[0].plant.x, box.stacks[1].plant.x])


def _run_python(box: HipBox) -> np.ndarray:
    a, b = box.stacks

    def one_by_one(n: int) -> None:
        for _ in range(n):
            a.advance(1)
            b.advance(1)
            couple_tick.py_func(box.g, box.h, box.joint, box.dt, a.plant.params, a.plant.y,
                                b.plant.params, b.plant.y)

    box._advance_stacks = one_by_one
    box.advance(TICKS)
    return np.concatenate([box.joint, a.plant.x, b.plant.x])


@pytest.mark.slow
def test_compiled_loop_equals_the_python_steps():
    compiled, python = _run_compiled(_box()), _run_python(_box())
    assert np.array_equal(compiled, python)
    assert abs(compiled[0] - 0.02) > 1e-6  # the joint did move


def test_same_config_same_result():
    assert np.array_equal(_run_compiled(_box()), _run_compiled(_box()))
