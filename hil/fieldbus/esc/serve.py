"""Serve the chain of ESC slaves on a raw Ethernet interface, on two clocks as the hardware
runs: ``eha-hil serve --transport ethercat --interface IF --topology hydra_full``.

* The **frame path** (:mod:`hil.fieldbus.esc.frames`) answers every frame at once from the
  slaves' memories (registers, SII, sync-manager buffers, FMMUs) in compiled code that holds
  no interpreter lock, and runs the slaves' own clock (process-data watchdogs) on the wall
  clock. It never waits for a box.
* The **box clock** (:class:`hil.fieldbus.box_clock.BoxClock`) advances the boxes behind
  the slaves (echo models, the full stack, or the whole-robot engine) one 1 ms cycle at a
  time in a thread of its own, released at absolute deadlines. At the start of a cycle
  each box takes the newest output record its ESC holds, at its end it publishes its input
  record: the sync managers' 3-buffers (:mod:`firmware_model.esc.compiled`), so neither
  side ever sees half a record and neither waits for the other. How far simulated time
  fell behind wall time is reported (``lag_max_ms``). A cycle run late (catching up) counts
  the record its box holds as a fresh command when the master's write reached the ESC in
  that cycle's scheduled millisecond of the slaves' clock (the ESCs stamp each output
  record), as the hardware's MCU would have found it: the box thread's lateness is the
  emulator's, not the master's, and must not trip the MCUs' command watchdogs.
  After each cycle the boxes' mailbox side (:mod:`hil.fieldbus.esc.mailbox`) serves the
  CoE requests the ESCs' SM0 handed over and posts answers and emergencies for SM1.

Before the frame path starts, the boxes run :data:`WARMUP_CYCLES` cycles and the frame loop
is compiled (or loaded): first calls take tens of ms (seconds with a cold cache), which
must not happen while a master reads the slaves' SII.

With distributed clocks active (a master started SYNC0 with a 1 ms cycle), the box clock
releases each cycle at the next SYNC0 pulse of the first slave that has one, as the MCU's
SYNC0 interrupt does, instead of its own grid (:meth:`ServedChain.sync0_release`).
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from firmware_model.esc import compiled as ec
from firmware_model.esc import dc_compiled as dcc
from firmware_model.esc.compiled import EscArrays
from firmware_model.esc.dc import DcParams
from hil.fieldbus.box_clock import PERIOD_NS, BoxClock, advance_boxes, take_outputs
from hil.fieldbus.boxes import box_engine, make_box
from hil.fieldbus.esc import frames as esc_frames
from hil.fieldbus.esc.mailbox import Mailboxes
from hil.fieldbus.esc.slaves import describe_all
from hil.fieldbus.topology import Topology
from hil.sim.cpu_account import run_delay_ns, steal_during, steal_s
from hil.transports.rawether import RawEthernet
from plant.config import Config

WARMUP_CYCLES = 3
#: A reply later than this [us] after its frame arrived counts as late (SOEM's stock
#: receive timeout is 2000 us; one cycle is 1000 us).
DEFAULT_LATE_US = 1000.0
#: The serving thread looks at its stop conditions this often [s] (or when woken).
WATCH_S = 0.5


class ServedChain:
    """The slaves' memories (:class:`EscArrays`) and the boxes behind them. ``model``:
    echo, stack or robot (every box; the whole-robot engine advances all at once);
    ``stack_boxes``: boxes that get the full stack whatever ``model`` says; ``coe``: the
    slaves have their CoE mailbox (False: none, process data on SM0/SM1). ``dc``: the
    slaves' clocks and delays (:func:`firmware_model.esc.dc.dc_line` by default)."""

    def __init__(self, topo: Topology, cfg: Config, model: str = "echo",
                 stack_boxes: tuple[int, ...] = (), coe: bool = True,
                 dc: list[DcParams] | None = None) -> None:
        self.topology = topo
        self.model = model
        described = describe_all(topo, coe)
        self.arrays = EscArrays(described, dc)
        #: CLOCK_MONOTONIC time [ns] of the slaves' clock zero (set by :func:`serve`).
        self.t0 = 0
        #: Largest system-time spread [ns] of the slaves per window of the slaves' clock
        #: (the frame thread's record, :meth:`FrameThread.dc_spread`, set by :func:`serve`)
        #: from window ``dc_spread_first`` on.
        self.dc_spread_ns: list[int] = []
        self.dc_spread_first = 0
        self.boxes = [make_box("stack" if b.id in stack_boxes and model != "robot" else model,
                               b, cfg) for b in topo.boxes]
        #: The boxes' mailbox side (CoE), run on the box clock after each cycle.
        self.mailboxes = Mailboxes(described, self.boxes, self.arrays, cfg)
        self.engine = box_engine(model, self.boxes, cfg, overlap=False)
        #: Box cycles run (the boxes' own clock; the optional cycle-counter TxPDO).
        self.box_cycles = 0
        #: Per box: the output record it took last (expanded to its full record), or None.
        self.taken: list[bytes | None] = [None] * len(self.boxes)
        #: Box cycles (per box) whose record was fresh by the slaves' clock alone (the
        #: master's write in their scheduled millisecond; its newest record taken before).
        self.fresh_by_schedule = 0
        #: The warm-up cycles have run (:func:`warm_up`).
        self.warmed = False
        #: CLOCK_MONOTONIC [ns]: is a cycle late? (a test's own clock)
        self.clock: Callable[[], int] = time.monotonic_ns
        self.publish_inputs()

    def take_outputs(self, since_ns: int | None = None, at_ns: int | None = None) -> None:
        """Each box takes the newest output record its ESC holds, if new; a cycle run late
        (back to back with others, it finds only the newest of their records) also the one
        it holds, if the master completed one in its scheduled ``(since_ns, at_ns]`` [ns,
        CLOCK_MONOTONIC] of the slaves' clock (:func:`hil.fieldbus.box_clock.take_outputs`)."""
        t0 = self.t0
        self.fresh_by_schedule += take_outputs(
            self.boxes, self._newest, self.taken,
            lambda a, b: self.arrays.outputs_written(a - t0, b - t0), since_ns, at_ns,
            self.clock)

    def _newest(self, i: int) -> bytes | None:
        out = self.arrays.pending_outputs(i)
        return None if out is None else self.mailboxes.expand(i, out)

    def advance(self) -> None:
        advance_boxes(self.engine, self.boxes)

    def publish_inputs(self) -> None:
        for i, box in enumerate(self.boxes):
            self.arrays.set_inputs(i, self.mailboxes.select(i, box.inputs(), self.box_cycles))

    def cycle(self, since_ns: int | None = None, at_ns: int | None = None) -> None:
        """One 1 ms cycle of every box, exchanging process data with the ESCs; ``(since_ns,
        at_ns]``: its scheduled millisecond (:class:`BoxClock`; None: off the clock)."""
        self.take_outputs(since_ns, at_ns)
        self.advance()
        self.box_cycles += 1
        self.mailboxes.step()
        self.publish_inputs()

    # --- distributed clocks --------------------------------------------------------------------
    def sync0_release(self, after_ns: int) -> int | None:
        """CLOCK_MONOTONIC time [ns] of the first SYNC0 pulse after ``after_ns`` of the first
        slave running SYNC0 with the boxes' 1 ms cycle, or None (free run)."""
        st = self.arrays.st
        for i in range(self.arrays.n):
            nxt = int(st[i, dcc.D_NEXT_SYNC0])
            if nxt < 0 or int(st[i, dcc.D_SYNC_CYCLE]) != PERIOD_NS:
                continue
            # the frame thread refreshed it at its last wake-up (the pulse after that): the
            # first pulse after ``after_ns`` is a whole number of cycles of this slave's
            # clock (its crystal and the loop's frequency correction) from it
            at = self.t0 + nxt
            cyc = PERIOD_NS * 1e9 / (1e9 + int(st[i, dcc.D_DRIFT]) + int(st[i, dcc.D_FREQ]))
            k = (at - after_ns - 1) // cyc
            return at - round(k * cyc)
        return None

    def dc_report(self) -> dict:
        """Per slave what the master set (offset, delay, SYNC0) beside the simulated clock,
        the loop's compares, out-of-order writes; the spread record: window ``k`` of
        ``spread_ns`` covers ``[(first + k) w, (first + k + 1) w)`` of the slaves' clock (``w``
        = ``spread_window_ms``, ``first`` = ``spread_first_window``), whose zero is
        ``spread_origin_monotonic_s`` (CLOCK_MONOTONIC); -1: the frame thread never woke in
        it."""
        a = self.arrays
        slaves = [{"slave": i, **dcc.slave_report(a.mem[i], a.st[i])} for i in range(a.n)]
        return {"slaves": slaves,
                "spread_window_ms": esc_frames.SPREAD_WINDOW_NS / 1e6,
                # (the same window in 1 ms bus cycles, for readers of the older record)
                "spread_window_cycles": esc_frames.SPREAD_WINDOW_NS // PERIOD_NS,
                "spread_first_window": self.dc_spread_first,
                "spread_origin_monotonic_s": self.t0 * 1e-9,
                "spread_ns": list(self.dc_spread_ns)}

    def watchdog_report(self) -> list[dict]:
        """Per slave: watchdog time and increment, trips, the delay of the last trip after
        the last output write on the slave's clock and of the tick that applied it [ms]
        (later by the frame thread's wake-up), AL status."""
        a = self.arrays
        return [{"box": i, "watchdog_ms": ec.watchdog_ns(a.mem[i]) / 1e6,
                 "watchdog_increment_ms": ec.watchdog_increment_ns(a.mem[i]) / 1e6,
                 "trips": int(a.st[i, ec.S_TRIPS]),
                 "last_trip_after_ms": int(a.st[i, ec.S_TRIP_DELAY]) / 1e6,
                 "last_trip_seen_after_ms": int(a.st[i, ec.S_TRIP_SEEN]) / 1e6,
                 "al_status": int(a.mem[i, 0x130]) | int(a.mem[i, 0x131]) << 8,
                 "al_status_code": int(a.mem[i, 0x134]) | int(a.mem[i, 0x135]) << 8}
                for i in range(a.n)]

@dataclass
class EcatServeStats:
    wall_s: float = 0.0
    cycles: int = 0
    overruns: int = 0
    slipped_cycles: int = 0
    lag_max_ms: float = 0.0
    lag_max_at_s: float = 0.0
    compute_s: float = 0.0
    worst_cycle_ms: float = 0.0
    worst_cycle_at: int = 0
    sync0_cycles: int = 0
    sync0_first_cycle: int = -1
    sync0_start_late_max_us: float = 0.0
    #: Box cycles (per box) whose command was fresh by a write in their scheduled ms only
    #: (run late, catching up: ServedChain.take_outputs).
    fresh_by_schedule: int = 0
    frames_received: int = 0
    frames_answered: int = 0
    frames_late: int = 0
    other_frames: int = 0
    dropped_frames: int = 0
    send_errors: int = 0
    late_us: float = DEFAULT_LATE_US
    reply_max_us: float = 0.0
    #: Longest the frame thread did not run past its 1 ms poll, and its longest wake-up.
    frame_gap_max_us: float = 0.0
    frame_work_max_us: float = 0.0
    #: Time the frame / box thread was runnable but waited for its CPU [ms] (None: unknown).
    frame_run_delay_ms: float | None = None
    box_run_delay_ms: float | None = None
    #: ... and the serving thread's (it stops the other two at the end).
    serve_run_delay_ms: float | None = None
    #: Per CPU: time the hypervisor did not run it during the serving [ms] (None: unknown).
    steal_ms: dict | None = None
    #: The first late replies: when, how long, wake-up and work (FrameThread.late_replies).
    late_replies: list = field(default_factory=list)
    #: CLOCK_MONOTONIC at the start [s], the origin of the times above (to find them in a
    #: system trace, e.g. ftrace with trace_clock mono).
    start_monotonic_s: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)


def warm_up(chain: ServedChain) -> None:
    """The boxes' first :data:`WARMUP_CYCLES` cycles and the frame loop compiled (or
    loaded), once: what :func:`serve` needs before it answers a frame. A caller that must
    stay interruptible meanwhile (a long compile on a cold cache) calls it first."""
    if chain.warmed:
        return
    for _ in range(WARMUP_CYCLES):
        chain.cycle()
    esc_frames.warm_up()
    chain.warmed = True


def serve(chain: ServedChain, link: RawEthernet, seconds: float | None = None,
          stop: Callable[[], bool] = lambda: False, wake: threading.Event | None = None,
          ready: Callable[[], None] = lambda: None, late_us: float = DEFAULT_LATE_US,
          frame_setup: Callable[[], None] | None = None,
          box_setup: Callable[[], None] | None = None,
          box_behind: Callable[[int], None] | None = None
          ) -> tuple[EcatServeStats, np.ndarray]:
    """Serve until ``seconds`` of wall time pass or ``stop()`` returns True (looked at when
    ``wake`` is set, e.g. by a signal handler, else every WATCH_S); (stats, reply
    time histogram, 1 us bins). ``ready()`` is called once frames are answered (a master
    started after it finds every slave answering from its first frame). ``frame_setup`` /
    ``box_setup`` run first in the frame / box thread (priority, CPU)."""
    wake = wake or threading.Event()
    warm_up(chain)
    frames = esc_frames.FrameThread(link.sock, chain.arrays, late_us, frame_setup)
    boxes = BoxClock(chain.cycle, box_setup, box_behind, chain.sync0_release)
    gc.collect()
    gc.freeze()  # what exists now is never collected: no pause scans it
    clock = time.monotonic_ns
    steal0 = steal_s()
    waited0 = run_delay_ns()
    start = clock()
    chain.t0 = start
    frames.start(start)
    boxes.begin(start)
    ready()
    end = None if seconds is None else start + int(seconds * 1e9)
    try:
        # This thread holds the interpreter lock only a moment every WATCH_S (a holder
        # preempted by the machine's load would hold up the box thread waiting for it).
        while (not stop() and frames.alive() and boxes.is_alive()
               and (end is None or clock() < end)):
            left = WATCH_S if end is None else min(WATCH_S, (end - clock()) * 1e-9)
            if left > 0:
                wake.wait(left)
    finally:
        frames.stop()
        boxes.stop()
        wall = (clock() - start) * 1e-9
        waited = run_delay_ns()
        steal1 = steal_s()
        gc.unfreeze()
    chain.dc_spread_first, chain.dc_spread_ns = frames.dc_spread()
    for err in (frames.error, boxes.error):
        if err is not None:
            raise err
    f, b = frames.stats, boxes.stats
    st = EcatServeStats(wall_s=wall, cycles=b.cycles, overruns=b.overruns,
                        slipped_cycles=b.slipped_cycles, lag_max_ms=b.lag_max_ms,
                        lag_max_at_s=b.lag_max_at_s,
                        compute_s=b.compute_s, worst_cycle_ms=b.worst_cycle_ms,
                        worst_cycle_at=b.worst_cycle_at, sync0_cycles=b.sync0_cycles,
                        sync0_first_cycle=b.sync0_first_cycle,
                        sync0_start_late_max_us=b.sync0_start_late_max_us,
                        fresh_by_schedule=chain.fresh_by_schedule,
                        frames_received=int(f[esc_frames.F_RECEIVED]),
                        frames_answered=int(f[esc_frames.F_ANSWERED]),
                        frames_late=int(f[esc_frames.F_LATE]),
                        other_frames=int(f[esc_frames.F_OTHER]),
                        dropped_frames=int(f[esc_frames.F_DROPPED]),
                        send_errors=int(f[esc_frames.F_SEND_ERRORS]), late_us=late_us,
                        reply_max_us=int(f[esc_frames.F_MAX_NS]) / 1e3,
                        frame_gap_max_us=max(int(f[esc_frames.F_MAX_GAP_NS]), 0) / 1e3,
                        frame_work_max_us=int(f[esc_frames.F_MAX_WORK_NS]) / 1e3,
                        frame_run_delay_ms=_ms(frames.run_delay_ns),
                        box_run_delay_ms=_ms(boxes.run_delay_ns),
                        serve_run_delay_ms=_ms(None if waited0 is None or waited is None
                                               else waited - waited0),
                        steal_ms=steal_during(steal0, steal1),
                        late_replies=frames.late_replies(start),
                        start_monotonic_s=start * 1e-9)
    return st, frames.hist.copy()


def _ms(ns: int | None) -> float | None:
    return None if ns is None else round(ns / 1e6, 3)
