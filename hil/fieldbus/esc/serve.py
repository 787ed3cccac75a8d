"""Serve the chain of ESC slaves on a raw Ethernet interface, on two clocks as the hardware
runs: ``eha-hil serve --transport ethercat --interface IF --topology hydra_full``.

* The **frame thread** answers every arriving frame at once from the slaves' memories
  (registers, SII, sync-manager buffers, FMMUs): it never waits for the boxes. It also runs
  the slaves' own clock, their process-data watchdogs, on the wall clock, as an ESC does.
* The **box thread** advances the boxes behind the slaves (echo models, or the full stack)
  one 1 ms cycle at a time, cycle ``k`` released at the absolute deadline ``t0 + k * 1 ms``
  (never from the previous wake-up, so no drift). At each cycle's start it takes the
  outputs the master wrote since the last one; at its end it hands the inputs to the ESCs.
  A box thread that falls behind runs cycles back to back; more than
  :data:`MAX_LAG_CYCLES` behind, it moves its schedule forward (slipped cycles): the
  simulated time then lags the wall clock, which the report gives as ``lag_max_ms``.

The two meet only at the process-data exchange (a lock held for a copy). Before the frame
thread starts, the boxes run :data:`WARMUP_CYCLES` cycles: the first call of the compiled
models loads them (tens of ms; seconds with a cold cache), which must not happen while a
master is reading the slaves' SII.
"""

from __future__ import annotations

import gc
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from hil.fieldbus.esc.chain import EscChain
from hil.transports.base import TransportError
from hil.transports.rawether import RawEthernet

PERIOD_NS = 1_000_000
MAX_LAG_CYCLES = 50
WARMUP_CYCLES = 3
#: The frame thread wakes at least this often [s] (watchdogs, stop requests).
POLL_S = 1e-3
#: Interpreter switch interval while serving [s]: a frame thread waiting for the
#: interpreter gets it within this (the default, 5 ms, exceeds a master's reply timeout).
SWITCH_INTERVAL_S = 1e-4


@dataclass
class EcatServeStats:
    cycles: int = 0              # box cycles run (1 ms simulated each)
    wall_s: float = 0.0
    overruns: int = 0            # box cycles finished after their deadline
    slipped_cycles: int = 0      # cycles skipped when more than MAX_LAG_CYCLES behind
    lag_max_ms: float = 0.0      # largest lag of simulated behind wall time
    frames_received: int = 0
    frames_answered: int = 0
    reply_us: list = field(default_factory=list)  # per answered frame, receive -> sent

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("reply_us")
        return d


def warm_up(chain: EscChain, cycles: int = WARMUP_CYCLES) -> None:
    """Run the boxes a few cycles before serving (first calls load compiled code)."""
    for _ in range(cycles):
        chain.advance_boxes()
    chain.publish_inputs()


class _Boxes(threading.Thread):
    def __init__(self, chain: EscChain, lock: threading.Lock, st: EcatServeStats,
                 t0_ns: int, stop: threading.Event) -> None:
        super().__init__(name="esc-boxes", daemon=True)
        self.chain, self.lock, self.st, self.t0, self.stop_ev = chain, lock, st, t0_ns, stop
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self._run()
        except BaseException as exc:  # reported by serve(), never lost with the thread
            self.error = exc
            self.stop_ev.set()

    def _run(self) -> None:
        chain, lock, st = self.chain, self.lock, self.st
        t0, k, clock = self.t0, 0, time.monotonic_ns
        while not self.stop_ev.is_set():
            release = t0 + k * PERIOD_NS
            now = clock()
            if release > now:
                time.sleep((release - now) * 1e-9)
                continue
            with lock:
                outs = chain.take_outputs()
            chain.apply_outputs(outs)
            chain.advance_boxes()
            with lock:
                chain.publish_inputs()
            k += 1
            st.cycles += 1
            done = clock()
            late = done - (t0 + k * PERIOD_NS)
            if late > 0:
                st.overruns += 1
                behind = late // PERIOD_NS
                if behind > MAX_LAG_CYCLES:
                    t0 += behind * PERIOD_NS
                    st.slipped_cycles += behind
            lag = done - self.t0 - st.cycles * PERIOD_NS
            st.lag_max_ms = max(st.lag_max_ms, lag / 1e6)


def serve(chain: EscChain, link: RawEthernet, seconds: float | None = None,
          stop: Callable[[], bool] = lambda: False,
          ready: Callable[[], None] = lambda: None) -> EcatServeStats:
    """Serve until ``seconds`` of wall time pass or ``stop()`` returns True. ``ready()`` is
    called once frames are answered at once (a master started after it finds the slaves
    answering from its first frame)."""
    st = EcatServeStats()
    lock = threading.Lock()
    stop_ev = threading.Event()
    switch = sys.getswitchinterval()
    gc.collect()
    gc.freeze()  # long-lived objects out of the collector's way: shorter pauses
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    clock = time.monotonic_ns
    start = clock()
    end = None if seconds is None else start + int(seconds * 1e9)
    boxes = _Boxes(chain, lock, st, start, stop_ev)
    boxes.start()
    ready()
    try:
        while not stop() and not stop_ev.is_set() and (end is None or clock() < end):
            frame = link.recv(POLL_S)
            t_rx = clock()
            with lock:
                chain.run_clock(t_rx - start)
                if frame is None:
                    continue
                st.frames_received += 1
                reply = chain.handle(frame)
            if reply is not None:
                link.send(reply)
                st.frames_answered += 1
                st.reply_us.append((clock() - t_rx) / 1e3)
    except TransportError:
        raise
    finally:
        stop_ev.set()
        boxes.join()
        sys.setswitchinterval(switch)
        gc.unfreeze()
        st.wall_s = (clock() - start) / 1e9
    if boxes.error is not None:
        raise boxes.error
    return st


def latency_summary(us: list[float]) -> dict:
    """p50/p99/p99.9/max of reply times [us] (None when nothing was answered)."""
    if not us:
        return {"p50": None, "p99": None, "p99_9": None, "max": None}
    a = np.asarray(us)
    p50, p99, p999 = np.percentile(a, [50, 99, 99.9])
    return {"p50": float(p50), "p99": float(p99), "p99_9": float(p999), "max": float(a.max())}
