"""The plant's per-tick path is compiled without the runtime's reference counting: the
physics blocks take the state and parameter arrays, and counting those references was
most of a 1.3x slowdown of the RK4 step (docs/architecture.md)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from plant import kernel
from plant import layout as L
from plant.blocks import TICK, load
from plant.config import load_config
from plant.model import Plant

PER_TICK = (kernel.derivatives, kernel.rk4_tick, kernel.stored_energy, kernel.outputs,
            kernel.advance, load.end_stops)


def test_per_tick_functions_use_the_tick_options():
    for fn in PER_TICK:
        assert fn.targetoptions.get("_nrt") is False, fn.__name__


@pytest.mark.slow
def test_derivatives_compiled_so_has_no_reference_counting():
    plant = Plant(load_config(None, ()))
    opts = {k: v for k, v in TICK.items() if k != "cache"}
    fresh = njit(**opts)(kernel.derivatives.py_func)
    dx = np.zeros(L.N_STATES)
    fresh(plant.x, plant.params, plant.u, dx)
    ir = "".join(fresh.inspect_llvm().values())
    assert "NRT_incref" not in ir and "NRT_decref" not in ir
    # and it computes what the kernel does
    dx2 = np.zeros(L.N_STATES)
    kernel.derivatives(plant.x, plant.params, plant.u, dx2)
    assert np.array_equal(dx, dx2)
