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
    # A dispatcher of its own over the function reads the kernel the runs load from numba's
    # cache; its library then holds the module's optimised LLVM IR (the code numba links
    # and inlines elsewhere). Without a cached kernel it compiles here, with the same
    # options, and its IR is read the usual way.
    fresh = njit(**TICK)(kernel.derivatives.py_func)
    dx = np.zeros(L.N_STATES)
    fresh(plant.x, plant.params, plant.u, dx)
    library = next(iter(fresh.overloads.values())).library
    shared = getattr(library, "_shared_module", None)
    ir = str(shared) if fresh.stats.cache_hits and shared is not None \
        else "".join(fresh.inspect_llvm().values())
    body = ir[ir.index("@_ZN5plant6kernel11derivatives"):]
    assert body.count("fmul") > 50  # the physics is in what is read
    assert "NRT_incref" not in ir and "NRT_decref" not in ir
    # and it computes what the kernel does
    dx2 = np.zeros(L.N_STATES)
    kernel.derivatives(plant.x, plant.params, plant.u, dx2)
    assert np.array_equal(dx, dx2)
