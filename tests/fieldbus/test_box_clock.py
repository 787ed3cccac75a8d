"""The boxes on their own clock behind a serial/udp chain (:mod:`hil.fieldbus.box_clock`):
the frame path answers from the 3-buffers and never calls a box model, and with one frame
per cycle it answers byte for byte what the chain answered when it called the boxes
directly (the readable reference)."""

from __future__ import annotations

import threading

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.fieldbus.box_clock import ClockedBoxes
from hil.fieldbus.chain import Chain
from hil.fieldbus.master import Master
from hil.fieldbus.topology import load_topology
from plant.config import load_config

CFG = load_config()


def _chains(topology: str, model: str) -> tuple[Chain, Chain, ClockedBoxes]:
    topo = load_topology(topology)
    ref = Chain(topo, CFG, model, paced=True, crc_trailer=False)
    dut = Chain(topo, CFG, model, paced=True, crc_trailer=False)
    return ref, dut, ClockedBoxes(dut)


@settings(max_examples=8, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2), st.floats(-2000.0, 2000.0), st.booleans(),
                          st.integers(1, 3)), min_size=1, max_size=40))
def test_clocked_chain_answers_as_the_direct_chain_echo(steps):
    _same_replies("hydra_full", "echo", steps)


def test_clocked_chain_answers_as_the_direct_chain_stack():
    rng = np.random.default_rng(7)
    steps = [(0, float(rng.uniform(-500, 500)), bool(rng.random() < 0.9),
              int(rng.integers(1, 3))) for _ in range(300)]
    _same_replies("bench_one_box", "stack", steps)


def _same_replies(topology: str, model: str, steps) -> None:  # noqa: ANN001
    """Per step: a force command for actuator ``j``, the cycle's frames through both chains
    (the reference applies outputs at once, the clocked one at the next box cycle), then
    ``advances`` (>= 1) box cycles: every reply equal, bit for bit. (Two output records
    before one box cycle differ by design: the box takes only the newest, as behind an
    ESC's 3-buffer, where the direct chain applied both.)"""
    ref, dut, clocked = _chains(topology, model)
    master = Master(ref.topology, crc_trailer=False)
    n_act = len(master.act_offsets)
    for j, force, enable, advances in steps:
        master.set_actuator(j % n_act, "force", force, enable=enable)
        for frame in master.frames():
            a, b = ref.handle(frame), dut.handle(frame)
            assert a == b
            master.receive(a)
        master.end_cycle()
        for _ in range(advances):
            ref.advance()
            clocked.cycle()
    assert ref.stats.frames == dut.stats.frames > 0


def test_a_frame_never_waits_for_a_box_step():
    """A box held inside its step (another thread) does not hold up a frame: the frame is
    answered from the record the box published last, and its outputs wait in the 3-buffer
    for the box's next cycle."""
    ref, dut, clocked = _chains("bench_one_box", "echo")
    box = clocked.boxes[0]
    entered, release = threading.Event(), threading.Event()
    step, applied = box.advance, []

    def held(ticks: int) -> None:
        entered.set()
        release.wait(10)
        step(ticks)

    box.advance = held
    box.apply = lambda data, apply=box.apply: (applied.append(bytes(data)), apply(data))
    stepping = threading.Thread(target=clocked.cycle)
    stepping.start()
    try:
        assert entered.wait(10)
        master = Master(dut.topology, crc_trailer=False)
        master.set_actuator(0, "force", 123.0)
        replies = [dut.handle(f) for f in master.frames()]  # while the box is held
        assert all(r is not None for r in replies)
        assert applied == []  # the box model was not called by the frame path
    finally:
        release.set()
        stepping.join(10)
    box.advance = step
    clocked.cycle()  # the next cycle takes the newest outputs
    assert len(applied) == 1 and applied[0] == bytes(master.image[:len(applied[0])])
