"""The demo PC loop's compiled commands equal its readable reference bit for bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.sim.pc import demo_commands, demo_commands_into


@settings(max_examples=25, deadline=None)
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


def test_timing_the_per_cycle_python_changes_no_result():
    """bench robot --stages' last row runs the bus with one worker and no overlap, timing
    around the compiled call: the engine's settings come back and the bytes are the same."""
    from hil.bench.robot_cycle import python_per_cycle
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc
    from plant.config import load_config

    topo, cfg = load_topology("bench_one_box"), load_config()
    images = []
    for timed in (False, True):
        with BusSystem(topo, cfg, "inproc", model="robot") as bs:
            eng = bs.chain.engine
            eng.workers = 2
            bs.run(5, demo_pc())
            if timed:
                assert python_per_cycle(bs, demo_pc(), 10) > 0.0
                assert (eng.workers, eng.overlap, "_compute" in vars(eng)) == (2, True, False)
            else:
                bs.run(2 + 3 * 10, demo_pc(), keep=0)  # (its warm-up, 3 runs of 10)
            images.append(bs.run(5, demo_pc()).inputs)
    assert np.array_equal(images[0], images[1])
