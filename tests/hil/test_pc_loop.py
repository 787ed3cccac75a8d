"""The demo PC loop's compiled commands equal its readable reference bit for bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.sim.pc import demo_commands, demo_commands_into


@settings(max_examples=40, deadline=None)
@given(cycle=st.integers(0, 10**7), amplitude=st.floats(-1e4, 1e4, allow_nan=False),
       frequency=st.floats(0.0, 500.0), n=st.integers(1, 64))
def test_the_compiled_demo_commands_are_the_references(cycle, amplitude, frequency, n):
    got = np.zeros(n)
    demo_commands_into(got, cycle, amplitude, frequency)
    assert got.tobytes() == np.array(demo_commands(cycle, n, amplitude, frequency)).tobytes()


def test_a_run_of_demo_commands_is_the_references():
    """Every cycle of 10 s of the bench's loop (300 N, 2 Hz, 47 actuators)."""
    got = np.zeros(47)
    for cycle in range(0, 10_000, 7):
        demo_commands_into(got, cycle, 300.0, 2.0)
        assert got.tobytes() == np.array(demo_commands(cycle, 47, 300.0, 2.0)).tobytes()
