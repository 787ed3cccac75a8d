"""Freshness on the master's time (:mod:`hil.fieldbus.box_clock`): a box thread that stalled
and catches up, running its late cycles back to back, finds at most the newest of the
records the master wrote meanwhile; each late cycle still counts the record it holds as a
fresh command when the master's write reached the frame side in that cycle's scheduled
millisecond, so the emulator's lateness never trips the MCUs' command watchdogs (10 ms,
then 50 ms more to switch the board off). A master that did not write in those
milliseconds still trips them. Each case is run on a controlled clock: the slaves' clock
ticked by hand (ethercat), a fake stamping clock (serial/udp)."""

from __future__ import annotations

import struct
import time

import numpy as np

from firmware_model.esc import compiled as cc
from firmware_model.mcu.mcu import CMD_TIMEOUT, SAFE_OFF
from hil.fieldbus import pdo
from hil.fieldbus.box_clock import PERIOD_NS, BoxClock, ClockedBoxes
from hil.fieldbus.chain import Chain
from hil.fieldbus.esc.master import EscMaster
from hil.fieldbus.esc.serve import ServedChain
from hil.fieldbus.master import Master
from hil.fieldbus.topology import load_topology
from tests.fieldbus.test_esc import THREE
from tests.fieldbus.test_esc_sync0 import _Frames

T0 = 10**12        # the slaves' zero on the monotonic clock (any)
ON_TIME = 20       # box cycles on schedule first
STALL = 40         # then the box thread stalls this many cycles (under MAX_LAG_CYCLES)
WRITE_AT_NS = 300_000  # the master writes 0.3 ms into each of its milliseconds
START_NS = 50_000      # a box cycle on time starts this long after its release


class _Ethercat:
    """A served chain (echo boxes) in OP, with box 0's first actuator commanded (force,
    enabled), its slaves' clock ticked by hand."""

    def __init__(self, cfg) -> None:  # noqa: ANN001
        self.chain = ServedChain(THREE, cfg, "echo")
        self.chain.t0 = T0
        self.frames = _Frames(self.chain)
        self.master = EscMaster(self.frames)
        self.master.bring_up()
        s = self.master.slaves[0]
        struct.pack_into("<BBi", self.master.image, s.out_lad, 1, pdo.FLAG_ENABLE, 10_000)
        self.box = 0  # the box cycles run so far
        self.now = T0  # when the box thread runs (CLOCK_MONOTONIC)
        self.chain.clock = lambda: self.now
        box = self.chain.boxes[0]
        self.applied = 0  # fresh commands box 0 took
        box.apply = lambda data, apply=box.apply: (setattr(self, "applied", self.applied + 1),
                                                   apply(data))

    def write(self, ms: int, at_ns: int = WRITE_AT_NS) -> None:
        """The master's cycle ``at_ns`` into millisecond ``ms`` of the slaves' clock."""
        self.frames.tick(ms * PERIOD_NS + at_ns - self.frames.now())
        self.master.cycle()

    def run_box(self, at_now: bool = False) -> int:
        """The next box cycle with its scheduled millisecond, on time (``START_NS`` after
        its release) or at ``self.now`` (``at_now``); box 0's actuator 0 status."""
        self.box += 1
        at = T0 + self.box * PERIOD_NS
        if not at_now:
            self.now = max(self.now, at + START_NS)
        self.chain.cycle(at - PERIOD_NS, at)
        return self.chain.boxes[0].model.status[0]


def _on_time(e: _Ethercat, cycles: int, write_at_ns: int = WRITE_AT_NS) -> list[int]:
    out = []
    for _ in range(cycles):
        e.write(e.box, write_at_ns)  # the master's write in the ms before the release
        out.append(e.run_box())
    return out


def test_box_cycles_run_late_keep_the_mcu_fed_on_the_masters_time(cfg):
    e = _Ethercat(cfg)
    seen = _on_time(e, ON_TIME)
    assert seen[-1] and not any(s & (CMD_TIMEOUT | SAFE_OFF) for s in seen)
    # the box thread stalls: the master writes on time every ms, no box cycle runs ...
    for ms in range(e.box, e.box + STALL):
        e.write(ms)
    # ... then the late cycles run back to back, half a ms after the last one's release
    # (the master's next write comes after them)
    e.now = T0 + (e.box + STALL) * PERIOD_NS + PERIOD_NS // 2
    late = [e.run_box(at_now=True) for _ in range(STALL)]
    assert not any(s & (CMD_TIMEOUT | SAFE_OFF) for s in late), [hex(s) for s in late]
    # the first late cycle took the newest record; those whose millisecond was over were
    # fresh by the schedule (not the last: on time); box 0 and box 2 have outputs, the IMU
    # box none
    assert e.chain.fresh_by_schedule == 2 * (STALL - 2)
    assert not any(s & CMD_TIMEOUT for s in _on_time(e, 5))


def test_box_cycles_on_time_take_each_write_once(cfg):
    """A write that lands between a cycle's release and its start is that cycle's (it
    takes the newest record as it starts) and not the next one's too, though it lies in the
    next one's scheduled millisecond: on time there is no credit."""
    e = _Ethercat(cfg)
    writes = 0
    for k in range(30):
        if k % 2:  # every other millisecond, after the release, before the cycle starts
            e.write(e.box + 1, START_NS // 5)
            writes += 1
        e.run_box()
    assert e.applied == writes and e.chain.fresh_by_schedule == 0


def test_a_master_that_stalls_still_trips_the_mcu(cfg):
    """No write in a cycle's millisecond, no credit: a master silent for 70 ms trips the
    command watchdog after 10 ms and switches the board off after 60, whether the box
    thread ran those cycles on time or late and back to back."""
    for late in (False, True):
        e = _Ethercat(cfg)
        _on_time(e, ON_TIME)
        silent = 70
        if late:  # the master's last write long before: stamped outside these cycles
            e.now = T0 + (e.box + silent + 1) * PERIOD_NS
            status = [e.run_box(at_now=True) for _ in range(silent)]
        else:
            status = []
            for _ in range(silent):
                e.frames.tick((e.box + 1) * PERIOD_NS - e.frames.now())  # time passes
                status.append(e.run_box())
        trips = [k for k, s in enumerate(status) if s & CMD_TIMEOUT]
        offs = [k for k, s in enumerate(status) if s & SAFE_OFF]
        assert trips and 9 <= trips[0] <= 11, (late, trips[:3])
        assert offs and 59 <= offs[0] <= 61, (late, offs[:3])
        assert e.chain.fresh_by_schedule == 0


def test_a_write_counts_only_in_its_own_millisecond(cfg):
    """The ESCs' ring of write times, on the slaves' clock: a write counts for the
    interval that holds its stamp, for the slaves it wrote (not the IMU box, which has no
    outputs), and for no other interval."""
    e = _Ethercat(cfg)
    _on_time(e, 3)
    e.write(30)
    a = e.chain.arrays
    at = 30 * PERIOD_NS + WRITE_AT_NS
    assert a.outputs_written(at - 1, at).tolist() == [True, False, True]
    assert a.outputs_written(at, at + PERIOD_NS).tolist() == [False, False, False]
    assert a.outputs_written(at - PERIOD_NS, at - 1).tolist() == [False, False, False]
    assert a.st[0, cc.S_OUT_WRITES] == 4 and a.st[1, cc.S_OUT_WRITES] == 0


def test_clocked_boxes_credit_the_masters_writes_by_their_stamps(cfg):
    """serial/udp: the frame side stamps each output record it publishes; a late cycle
    counts the held record fresh by those stamps, as on ethercat."""
    now = [T0]
    chain = Chain(load_topology("bench_one_box"), cfg, "echo", paced=True,
                  crc_trailer=False)
    clocked = ClockedBoxes(chain, clock=lambda: now[0])
    master = Master(chain.topology, crc_trailer=False)
    master.set_actuator(0, "force", 100.0, enable=True)
    model = clocked.boxes[0].model

    def write(ms: int) -> None:
        now[0] = T0 + ms * PERIOD_NS + WRITE_AT_NS
        for f in master.frames():
            master.receive(chain.handle(f))
        master.end_cycle()

    k = 0
    for k in range(1, ON_TIME + 1):
        write(k - 1)
        clocked.cycle(T0 + (k - 1) * PERIOD_NS, T0 + k * PERIOD_NS)
    for ms in range(k, k + STALL):
        write(ms)
    now[0] = T0 + (k + STALL) * PERIOD_NS + PERIOD_NS // 2  # the box thread resumes
    status = []
    for j in range(k + 1, k + STALL + 1):
        clocked.cycle(T0 + (j - 1) * PERIOD_NS, T0 + j * PERIOD_NS)
        status.append(model.status[0])
    assert not any(s & (CMD_TIMEOUT | SAFE_OFF) for s in status), [hex(s) for s in status]
    assert clocked.fresh_by_schedule == STALL - 2


def test_the_box_clock_hands_each_cycle_its_scheduled_millisecond():
    """A cycle that stalls 20 ms: the cycles after it run late, back to back, each handed
    its own millisecond of the schedule (contiguous, 1 ms each), not the time it ran."""
    got: list[tuple[int, int, int]] = []

    def cycle(since: int, at: int) -> None:
        got.append((since, at, time.monotonic_ns()))
        if len(got) == 3:
            time.sleep(0.02)

    clock = BoxClock(cycle)
    clock.begin(time.monotonic_ns())
    while clock.stats.cycles < 30:
        time.sleep(0.005)
    clock.stop()
    assert clock.error is None
    since, at, ran = (np.array(c) for c in zip(*got, strict=True))
    assert since[0] == clock.t0 - 1 and at[0] == clock.t0
    if clock.stats.slipped_cycles == 0:  # (this process stalled > 50 ms: cycles skipped)
        assert (since[1:] == at[:-1]).all() and (np.diff(at) == PERIOD_NS).all()
    assert (ran >= at).all()
    # the stall's catch-up: cycles that ran over 2 ms after their release (whatever else
    # this machine did, the 20 ms sleep made some)
    assert (ran - at > 2 * PERIOD_NS).sum() >= 5
