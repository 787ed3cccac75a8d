"""The logging breakdown (``python -m hil.bench.log_parts``) names functions that exist: a
renamed one would silently drop out of the figures."""

from __future__ import annotations

import importlib

from hil.bench.log_parts import PARTS, _install, _Timer


def test_every_part_names_a_function() -> None:
    for module, path, _side in PARTS:
        owner = importlib.import_module(module)
        for name in path.split("."):
            owner = getattr(owner, name)
        assert callable(owner), path


def test_wrapped_parts_count_own_time_and_are_put_back() -> None:
    from hil.framelog import rawpb

    before = rawpb.pack_blocks
    timer = _Timer()
    undo = _install(timer)
    try:
        assert rawpb.pack_blocks is not before
        outer = timer.wrap(lambda: rawpb.pack_block(*_block()), "outer")
        outer()
    finally:
        for owner, name, fn in reversed(undo):
            setattr(owner, name, fn)
    assert rawpb.pack_blocks is before
    assert set(timer.own) == {"outer", "file: pack_blocks"}
    assert all(v >= 0 for v in timer.own.values())


def _block():  # noqa: ANN202
    import numpy as np

    return np.arange(3), np.zeros((3, 2), np.uint16), np.dtype(np.uint16)


def test_the_fieldbus_tap_is_timed_as_the_bus_signals_make_it(tmp_path) -> None:  # noqa: ANN001
    """run_logged's per-cycle tap is the closure ``BusSignals.tap`` makes for the bus
    system: the breakdown wraps it as it is made; it is called once per cycle, and the
    log holds every frame the bus system's per-frame tap saw, in its order."""
    from hil.bench.log_parts import TAP
    from hil.fieldbus.topology import load_topology
    from hil.framelog import FrameLogReader
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc
    from plant.config import load_config

    each = []
    timer = _Timer()
    undo = _install(timer)
    try:
        rec = run_logged(load_topology("bench_one_box"), load_config(None), 5, demo_pc(),
                         tmp_path / "t.mcap", capture=lambda *frame: each.append(frame))
    finally:
        for owner, name, fn in reversed(undo):
            setattr(owner, name, fn)
    assert timer.calls[TAP] == 5
    logged = [f for _, _, f in FrameLogReader(tmp_path / "t.mcap").frames(
        ["/fieldbus/frames"], order="file")]
    assert logged == [frame[2] for frame in each]
    assert sum(d == "tx" for *_, d in each) == rec.master["frames_sent"] > 0


def test_the_split_adds_up_to_what_the_logging_costs() -> None:
    """The parts of a breakdown are the logged run's extra CPU: the in-kernel part is the
    compiled calls' difference, the rest what no part holds."""
    from collections import Counter

    from hil.bench.log_parts import Parts, format_parts, timer_cost

    own = Counter({"file: zstd (in _finalize)": 0.05, "producer: RobotRecorder.finished": 0.02})
    p = Parts(2.0, 0.40, 0.70, 0.10, 0.13, own, Counter({"producer: RobotRecorder.finished":
                                                         2000}), 0.01, 0, [0.3])
    sp = p.split()
    assert round(sp["in_kernel"], 6) == 15.0 and round(sp["total"], 6) == 150.0
    assert round(sp["rest"], 6) == round(150.0 - 25.0 - 10.0 - 15.0 - 5.0, 6)
    assert "150.0 ms CPU per simulated second" in format_parts(p)
    full, inside = timer_cost(2000)
    assert full >= inside >= 0.0


def test_bench_log_reports_the_logging_per_simulated_second_and_its_budget() -> None:
    from hil.bench.log import Overhead, format_report

    ov = Overhead("mcu", "hydra_full, zstd, robot model", 2.0, 3, 1.5, 1.4, 1.45, 0.4, 1.0,
                  0.6, 1.3, 10**6, (1.4, 1.5, 1.6), (1.3, 1.4, 1.5), (80.0, 100.0, 120.0),
                  {"file": 60.0, "producer": 20.0, "in_kernel": 8.0, "timers": 5.0,
                   "rest": 7.0, "total": 100.0})
    text = format_report(ov, [])  # no encodings measured
    assert "CPU 1.500 (1.400-1.600)" in text
    assert "100 ms CPU per simulated second (80-120)" in text
    assert "the target allows 50 " in text  # (1.25 - 1) x 0.2 s per simulated second
    assert "compiled calls 8," in text
    assert "in order (*: bare run first): 1.400*, 1.500, 1.600*;" in text


def test_each_timed_run_collects_its_own_garbage_and_none_from_before() -> None:
    """The bench's runs: what a run leaves in reference cycles is freed inside its own
    timing (not in a later run's), and what existed before the runs is frozen out of the
    collector's way while they run, given back after."""
    import gc

    from hil.bench.log_parts import run_cpu, settled

    freed = []

    class Node:
        def __init__(self) -> None:
            self.me = self  # a cycle: only the cyclic collector frees it

        def __del__(self) -> None:
            freed.append(1)

    def leave_a_cycle() -> None:
        Node()

    was = gc.isenabled()
    gc.disable()  # (no automatic collection: only what run_cpu does)
    try:
        with settled():
            assert gc.get_freeze_count() > 0
            run = run_cpu(leave_a_cycle)
            assert freed == [1]
        assert gc.get_freeze_count() == 0
    finally:
        if was:
            gc.enable()
    assert run.cpu >= 0.0 and run.wall >= 0.0 and run.faults >= 0


def test_each_logged_run_writes_a_new_file(tmp_path) -> None:  # noqa: ANN001
    """The bench's logged runs write a new file each (as a user's run does), not the last
    run's truncated: ext4 would charge the truncation and a flush at close to the logging."""
    from hil.bench.log_parts import run_pair
    from hil.fieldbus.topology import load_topology
    from plant.config import load_config

    path = tmp_path / "bench.mcap"
    _bare, logged = run_pair(load_topology("bench_one_box"), load_config(None), 3, path,
                             "mcu", "stack", "zstd")
    logged()
    first = path.stat()
    keep = path.open("rb")  # the old inode stays readable while it is open
    try:
        logged()
        again = path.stat()
        assert again.st_ino != first.st_ino
        assert len(keep.read()) == first.st_size  # the first run's file left whole
    finally:
        keep.close()
