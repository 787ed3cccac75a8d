"""The process image over every transport: the full robot's (echo model) exchanged on each
backend, and one bench scenario (stack model) giving byte-identical input records on all."""

from __future__ import annotations

import numpy as np
import pytest

from hil.fieldbus.system import BusSystem
from hil.fieldbus.topology import load_topology

from .conftest import force_profile, full_robot_pc

#: (transport, remote, transport options): udp and the pty-served serial run the chain in
#: another process; serial over a pty and over loop://, and can, run it inline. udp on a
#: free port (the default, 34980, may be taken by a parallel run).
BACKENDS = [
    ("inproc", None, None),
    ("udp", None, {"port": 0}),
    ("serial", None, None),
    ("serial", True, None),
    ("serial", None, {"url": "loop://"}),
    ("can", None, None),
]
IDS = ["inproc", "udp-process", "serial-pty", "serial-pty-process", "serial-loop", "can"]


def _run(topo, cfg, backend, model, cycles, pc):
    transport, remote, opts = backend
    with BusSystem(topo, cfg, transport, model=model, remote=remote,
                   transport_options=opts) as bs:
        rec = bs.run(cycles, pc)
        inputs = [bs.master.actuator_inputs(j) for j in range(topo.n_actuators)]
    return rec, inputs


@pytest.fixture(scope="module")
def full_reference(cfg):
    return _run(load_topology("hydra_full"), cfg, BACKENDS[0], "echo", 40, full_robot_pc)


@pytest.mark.parametrize("backend", BACKENDS, ids=IDS)
def test_full_robot_image(cfg, full, backend, full_reference):
    rec, inputs = _run(full, cfg, backend, "echo", 40, full_robot_pc)
    n_frames = 2 * 40
    assert rec.master["frames_sent"] == rec.master["frames_ok"] == n_frames
    for key in ("wkc_errors", "bad_frames", "stale_frames", "lost_frames"):
        assert rec.master[key] == 0, key
    # loop:// is one port for both sides: it receives the requests and the replies
    shared = backend[2] is not None and "url" in backend[2]
    assert rec.transport["frames_received"] == n_frames * (2 if shared else 1)
    for j, x in enumerate(inputs):
        assert x["fresh"]
        assert x["f_filtered"] == pytest.approx(10.0 * (j + 1) + 0.39, abs=0.5)
        assert x["status"] & 0x80  # BOARD_ENABLED
    ref_rec, _ = full_reference
    np.testing.assert_array_equal(rec.inputs, ref_rec.inputs)


@pytest.fixture(scope="module")
def bench_reference(cfg):
    return _run(load_topology("bench_one_box"), cfg, BACKENDS[0], "stack", 300, force_profile)


@pytest.mark.slow  # the fast lane has every backend in test_full_robot_image
@pytest.mark.parametrize("backend", BACKENDS[1:], ids=IDS[1:])
def test_same_scenario_same_bytes(cfg, bench, backend, bench_reference):
    ref, ref_inputs = bench_reference
    rec, _ = _run(bench, cfg, backend, "stack", 300, force_profile)
    assert rec.master == ref.master
    assert rec.inputs.shape == (300, ref.inputs.shape[1])
    assert rec.inputs.tobytes() == ref.inputs.tobytes()


def test_bench_scenario_does_something(bench_reference):
    ref, inputs = bench_reference
    assert ref.master["frames_ok"] == 300
    # the stack followed the force command: 300 N +/- 200 N sine at the end
    assert 50.0 < inputs[0]["f_filtered"] < 550.0
    assert np.unique(ref.inputs, axis=0).shape[0] > 250  # inputs change every cycle
