"""The boxes on their own clock, whatever carries the frames: a thread that advances them
one 1 ms cycle at a time, paced to the wall clock by absolute deadlines, and exchanges
process data with the frame side through 3-buffers, never waiting for it.

* :class:`BoxClock` runs ``cycle(since, at)`` for cycle ``k`` at the absolute deadline
  ``at = t0 + k * 1 ms`` (``clock_nanosleep``, ``TIMER_ABSTIME``: computed from ``t0``,
  never from the previous wake-up, so nothing drifts; ``since``: the previous cycle's).
  Behind its schedule it runs cycles back to back; more than :data:`MAX_LAG_CYCLES` behind,
  it moves the schedule forward (slipped cycles). It counts overruns, runs of them
  (stalls), the worst lateness and how far simulated time fell behind wall time.
* Freshness on the master's time: a box's MCU takes a record as a fresh command when the
  master wrote one since its previous cycle (its command watchdog counts the cycles
  without). A cycle run late, back to back with others to catch up, finds at most the one
  newest record, though the master wrote one in each of those cycles' milliseconds, on
  time, as the hardware's sync manager would have got them: so a cycle that starts after
  its scheduled millisecond ``(since, at]`` is over (a whole period past its release) also
  counts the record it holds as fresh when a write arrived in that millisecond, stamped by
  the frame side's clock (the slaves' clock on ethercat): :func:`take_outputs`. A master
  that did not write in that millisecond gets no such credit: its stalls still trip the
  MCUs. A cycle on time takes only what is new (no credit: a write it took early, between
  the release and its start, would count twice).
* :class:`ClockedBoxes` puts the boxes of a paced :class:`~hil.fieldbus.chain.Chain`
  (serial, udp) behind one output and one input 3-buffer each
  (:func:`firmware_model.esc.compiled.publish` / ``take``, as an ESC's process-data sync
  managers): the chain's frame path then writes a box's outputs into its 3-buffer and
  reads the newest complete input record from the other, and never calls the box model,
  so a frame is never held up by a box's step. ``serve --transport ethercat`` does the
  same with the ESCs' own 3-buffers (:mod:`hil.fieldbus.esc.serve`).
"""

from __future__ import annotations

import ctypes
import gc
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from firmware_model.esc.compiled import B_READER, NEVER, OUT_RING, publish, take, written_in
from hil.fieldbus.chain import CYCLE_TICKS, Chain
from hil.sim.cpu_account import run_delay_ns

PERIOD_NS = 1_000_000
#: More than this many cycles behind, the schedule moves forward (the cycles are slipped).
MAX_LAG_CYCLES = 50
#: The busy share handed to ``behind`` is measured over windows this long [ns].
BUSY_WINDOW_NS = 250_000_000


@dataclass
class BoxClockStats:
    cycles: int = 0              # box cycles run (1 ms simulated each)
    overruns: int = 0            # cycles finished after their deadline
    stalls: int = 0              # runs of consecutive overruns
    worst_late_ms: float = 0.0   # largest lateness past a deadline
    slipped_cycles: int = 0      # cycles skipped when more than MAX_LAG_CYCLES behind
    lag_max_ms: float = 0.0      # largest lag of simulated behind wall time
    lag_max_at_s: float = 0.0    # when [s after the start]
    compute_s: float = 0.0       # wall time spent in the cycles
    worst_cycle_ms: float = 0.0
    worst_cycle_at: int = 0      # its number
    sync0_cycles: int = 0        # cycles released at a SYNC0 pulse (DC active)
    sync0_first_cycle: int = -1  # number of the first of them
    sync0_start_late_max_us: float = 0.0  # latest start of such a cycle after its pulse


class BoxClock(threading.Thread):
    """Runs ``cycle(since, at)`` every :data:`PERIOD_NS` of the monotonic clock from
    ``t0_ns``, sleeping to absolute deadlines, until :meth:`stop`: ``at`` is the cycle's
    release [ns, CLOCK_MONOTONIC] on the schedule (whenever it actually runs), ``since`` the
    previous cycle's. ``on_start``: run first inside the thread (its scheduling, its CPU)."""

    def __init__(self, cycle: Callable[[int, int], None],
                 on_start: Callable[[], None] | None = None,
                 behind: Callable[[int, float], None] | None = None,
                 sync0: Callable[[int], int | None] | None = None) -> None:
        super().__init__(name="box-clock", daemon=True)
        self.cycle = cycle
        self.on_start = on_start
        #: behind(cycles, busy): after each cycle, how many whole cycles it is behind
        #: schedule, and the share of the last full BUSY_WINDOW_NS it spent in cycles.
        self.behind = behind
        #: sync0(after): the next SYNC0 pulse [ns, monotonic] after ``after``, or None
        #: (then the cycle grid of t0).
        self.sync0 = sync0
        self.stats = BoxClockStats()
        self.error: BaseException | None = None
        #: Time the thread was runnable but waited for its CPU while on the clock [ns].
        self.run_delay_ns: int | None = None
        self._stop_ev = threading.Event()
        self._set_up = threading.Event()
        self.t0 = 0

    def begin(self, t0_ns: int) -> None:
        """Start (returns once the thread set itself up) with cycle 0 released at t0_ns."""
        self.t0 = t0_ns
        self.start()
        self._set_up.wait()

    def stop(self) -> None:
        self._stop_ev.set()
        self.join()

    def run(self) -> None:
        try:
            try:
                if self.on_start is not None:
                    self.on_start()
            finally:
                self._set_up.set()
            d0 = run_delay_ns()
            try:
                self._run()
            finally:
                d1 = run_delay_ns()
                if d0 is not None and d1 is not None:
                    self.run_delay_ns = d1 - d0
        except BaseException as exc:  # reported by the owner, never lost with the thread
            self.error = exc

    def _run(self) -> None:
        st, clock, sleep_until = self.stats, time.monotonic_ns, _sleep_until
        t0 = self.t0
        k = 0
        last = t0 - 1   # the previous cycle's release
        was_late = False
        busy, window0, window_spent = 0.0, t0, 0
        gc.disable()  # a collection inside the loop would be a stall; collected between
        try:
            while not self._stop_ev.is_set():
                release = t0 + k * PERIOD_NS
                pulse = self.sync0(last) if self.sync0 is not None else None
                if pulse is not None:
                    release = pulse
                if clock() < release:
                    sleep_until(release)
                    continue
                begin = clock()
                self.cycle(last, release)
                done = clock()
                last = release
                if pulse is not None:
                    if st.sync0_first_cycle < 0:
                        st.sync0_first_cycle = st.cycles
                    st.sync0_cycles += 1
                    st.sync0_start_late_max_us = max(st.sync0_start_late_max_us,
                                                     (begin - pulse) / 1e3)
                k += 1
                st.cycles += 1
                spent = done - begin
                st.compute_s += spent * 1e-9
                if spent / 1e6 > st.worst_cycle_ms:
                    st.worst_cycle_ms, st.worst_cycle_at = spent / 1e6, k - 1
                late = done - (release + PERIOD_NS)
                behind = max(late, 0) // PERIOD_NS
                if late > 0:
                    st.overruns += 1
                    st.stalls += not was_late
                    st.worst_late_ms = max(st.worst_late_ms, late / 1e6)
                    if behind > MAX_LAG_CYCLES:
                        t0 += behind * PERIOD_NS
                        st.slipped_cycles += behind
                        if pulse is not None:   # the missed pulses are skipped too
                            last = done - PERIOD_NS
                was_late = late > 0
                window_spent += spent
                if done - window0 >= BUSY_WINDOW_NS:
                    busy, window0, window_spent = window_spent / (done - window0), done, 0
                if self.behind is not None:
                    self.behind(behind, busy)
                lag = done - self.t0 - st.cycles * PERIOD_NS
                if lag / 1e6 > st.lag_max_ms:
                    st.lag_max_ms, st.lag_max_at_s = lag / 1e6, (done - self.t0) * 1e-9
        finally:
            gc.enable()


class _Sleeper:
    """``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`` through ctypes (which drops the
    interpreter lock while it sleeps)."""

    def __init__(self) -> None:
        libc = ctypes.CDLL(None, use_errno=True)
        self._ts = (ctypes.c_long * 2)()
        f = libc.clock_nanosleep
        f.restype, f.argtypes = ctypes.c_int, [ctypes.c_int, ctypes.c_int, ctypes.c_void_p,
                                               ctypes.c_void_p]
        self._f = f

    def sleep_until(self, deadline_ns: int) -> None:
        ts = self._ts
        ts[0], ts[1] = divmod(deadline_ns, 1_000_000_000)
        self._f(1, 1, ts, None)


_sleeper = _Sleeper()


def _sleep_until(deadline_ns: int) -> None:
    """Sleep to an absolute CLOCK_MONOTONIC deadline [ns]."""
    _sleeper.sleep_until(deadline_ns)


def take_outputs(boxes: list, newest: Callable[[int], bytes | None], held: list,
                 written: Callable[[int, int], np.ndarray], since_ns: int | None,
                 at_ns: int | None, now: Callable[[], int]) -> int:
    """Each box ``i`` applies ``newest(i)`` (its newest output record, None if nothing new)
    and keeps it in ``held[i]``; with nothing new, a cycle run late (``now()`` a period or
    more past its release ``at_ns``) applies ``held[i]`` again when ``written(since_ns,
    at_ns)[i]``: the master's write in the cycle's scheduled millisecond. How many boxes
    were fresh by that alone."""
    credited, late, wrote = 0, None, None
    for i, box in enumerate(boxes):
        rec = newest(i)
        if rec is not None:
            held[i] = rec
            box.apply(rec)
            continue
        if since_ns is None or held[i] is None:
            continue
        if late is None:
            late = now() >= at_ns + PERIOD_NS
        if not late:
            continue
        if wrote is None:
            wrote = written(since_ns, at_ns)
        if wrote[i]:
            box.apply(held[i])
            credited += 1
    return credited


class _Port:
    """What the frame side of a :class:`Chain` sees of box ``i`` once the boxes run on
    their own clock: ``apply`` publishes an output record, ``inputs`` is the newest
    complete input record the box published (the box model is never called)."""

    def __init__(self, owner: ClockedBoxes, i: int) -> None:
        self.o, self.i = owner, i

    def apply(self, data: bytes) -> None:
        o, i = self.o, self.i
        rec = np.frombuffer(data, dtype=np.uint8)
        publish(o.obuf[i], o.olen[i], o.oidx[i], rec, rec.size)
        k = o.writes[i]
        o.written_at[i, k % o.written_at.shape[1]] = o.clock()  # (a ring)
        o.writes[i] = k + 1

    def inputs(self) -> bytes:
        o, i = self.o, self.i
        k = take(o.iidx[i])
        if k < 0:  # nothing new since the last frame: the record already taken
            k = o.iidx[i, B_READER]
        return o.ibuf[i, k, :o.ilen[i, k]].tobytes()


def advance_boxes(engine, boxes: list) -> None:  # noqa: ANN001 (RobotEngine | None)
    """One 1 ms cycle of every box: the whole-robot engine's one step when there is one,
    else each box's own."""
    if engine is not None:
        engine.advance(CYCLE_TICKS)
    else:
        for box in boxes:
            box.advance(CYCLE_TICKS)


class ClockedBoxes:
    """The boxes of a paced ``chain`` taken off its frame path onto their own clock:
    afterwards ``chain.handle`` answers from the 3-buffers and :meth:`cycle` (one 1 ms step
    of every box: newest outputs in, advance, inputs out) is the box clock's. ``clock``
    stamps each output record as the frame side publishes it [ns, the box clock's]."""

    def __init__(self, chain: Chain, clock: Callable[[], int] = time.monotonic_ns) -> None:
        if not chain.paced:
            raise ValueError("ClockedBoxes needs Chain(..., paced=True)")
        self.chain = chain
        self.clock = clock
        self.boxes, self.engine = chain.boxes, chain.engine
        n = len(self.boxes)
        out_max = max([w.out_len for w in chain.plan.windows] + [1])
        in_max = max([w.in_len for w in chain.plan.windows] + [1])
        self.obuf = np.zeros((n, 3, out_max), dtype=np.uint8)
        self.olen = np.zeros((n, 3), dtype=np.int64)
        self.ibuf = np.zeros((n, 3, in_max), dtype=np.uint8)
        self.ilen = np.zeros((n, 3), dtype=np.int64)
        self.oidx = np.tile(np.array([0, 1, 2], dtype=np.int64), (n, 1))
        self.iidx = self.oidx.copy()
        #: Per box: output records published, and when (CLOCK_MONOTONIC [ns], a ring).
        self.writes = np.zeros(n, dtype=np.int64)
        self.written_at = np.full((n, OUT_RING), NEVER, dtype=np.int64)
        #: Per box: the output record it took last (None: none yet).
        self.taken: list[bytes | None] = [None] * n
        #: Box cycles (per box) fresh only by a write in their scheduled millisecond.
        self.fresh_by_schedule = 0
        self.publish_inputs()
        chain.boxes = [_Port(self, i) for i in range(n)]
        chain.engine = None

    def release(self) -> None:
        """Hand the boxes back to the chain once their clock has stopped (what follows the
        serving, e.g. a log's replay metadata, reads the boxes themselves, not the ports)."""
        self.chain.boxes, self.chain.engine = self.boxes, self.engine

    def take_outputs(self, since_ns: int | None = None, at_ns: int | None = None) -> None:
        """Each box takes its newest output record if new; a late cycle also the one it
        holds, if the master wrote one in its scheduled ``(since_ns, at_ns]``
        (:func:`take_outputs`)."""
        self.fresh_by_schedule += take_outputs(
            self.boxes, self._newest, self.taken,
            lambda a, b: written_in(self.written_at, a, b), since_ns, at_ns, self.clock)

    def _newest(self, i: int) -> bytes | None:
        k = take(self.oidx[i])
        return None if k < 0 else self.obuf[i, k, :self.olen[i, k]].tobytes()

    def advance(self) -> None:
        advance_boxes(self.engine, self.boxes)

    def publish_inputs(self) -> None:
        for i, box in enumerate(self.boxes):
            rec = np.frombuffer(box.inputs(), dtype=np.uint8)
            publish(self.ibuf[i], self.ilen[i], self.iidx[i], rec, rec.size)

    def cycle(self, since_ns: int | None = None, at_ns: int | None = None) -> None:
        """One 1 ms cycle of every box, exchanging process data with the frame side;
        ``(since_ns, at_ns]``: its scheduled millisecond (:class:`BoxClock`), None for a
        cycle off the clock (warm-up)."""
        self.take_outputs(since_ns, at_ns)
        self.advance()
        self.publish_inputs()
        chain = self.chain
        chain.cycle = (chain.cycle + 1) & 0xFF
        chain.stats.cycles_advanced += 1
        if chain.on_advance is not None:
            chain.on_advance()
