"""``eha-hil serve``: the simulated robot's side of the fieldbus, paced to the wall clock.

The chain of joint driver boxes (:class:`~hil.fieldbus.chain.Chain`, plant + driver boards
+ MCU per actuator with the ``stack`` model) answers EtherCAT frames (the PDU, with a CRC-32
trailer on serial and without on udp by default: :mod:`hil.fieldbus.wire`) on a serial port
(COBS + CRC-32 framing) or a UDP socket, so that a real master (an MCU board, the PC's
EtherCAT code, or another program such as :class:`hil.fieldbus.master.Master` in another
process) closes the loop in real time.

Two clocks, as on the hardware (:class:`PacedServer`, docs/ethercat-slaves.md "Timing"):
the frames are the master's, answered in this thread as they arrive from the boxes'
latest published process data; the boxes keep their own 1 ms clock in a thread of their
own (:mod:`hil.fieldbus.box_clock`: cycle ``k`` released at ``t0 + k * 1 ms``, absolute
deadlines, no drift), exchanging process data with the frames through 3-buffers, so a
frame never waits for a box step and a box step never for a frame. A cycle finished after
its deadline is an *overrun* (counted, worst lateness kept); a late box clock catches up
by running cycles back to back, and if it falls more than
:data:`~hil.fieldbus.box_clock.MAX_LAG_CYCLES` behind, the schedule is moved forward and
the skipped cycles are counted as *slipped* (simulated time then lags the wall clock).
The chain runs in paced mode: frames never move time; their ``idx`` only discards a frame
older than the newest one.
"""

from __future__ import annotations

import argparse
import gc
import math
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from hil.cli.args import common, float_range, int_range, output_file
from hil.cli.contract import EXIT_FAILED, EXIT_OK, Context, Outcome, UsageError, command
from hil.transports import TransportError

# The fieldbus, the engines and their reply statistics (numpy) are imported where they are
# used, not here: the parser is built at every start of the console script.
if TYPE_CHECKING:  # the boxes' kernels (numba) are imported by the command, not the parser
    from hil.fieldbus.box_clock import ClockedBoxes
    from hil.fieldbus.chain import Chain

#: One fieldbus cycle of wall time [s].
PERIOD_S = 1e-3
#: Cycles run before the clock starts (first-call set-up of the models takes ~10 ms).
WARMUP_CYCLES = 3
#: A pause longer than this [s] between two frames starts a new master session: the
#: cycle numbers before and after it are not compared (no missed cycles counted).
SESSION_GAP_S = 0.2
#: Default allowance of overrunning cycles [% of cycles] before the run counts as failed.
DEFAULT_MAX_OVERRUN_PERCENT = 1.0
#: Default allowance of late replies [% of frames] (ethercat) before the run fails.
DEFAULT_MAX_LATE_PERCENT = 0.1
#: Default allowance of simulated time behind wall time [ms] (the slaves' watchdog time).
DEFAULT_MAX_LAG_MS = 100.0
#: The frame loop looks at its stop conditions and progress at least this often [s].
WATCH_S = 0.1
#: The interpreter's switch interval while serving [s] (see PacedServer.run).
SWITCH_INTERVAL_S = 2e-4


@dataclass
class ServeStats:
    """What a paced run did; ``as_dict`` adds the derived figures."""

    cycles: int = 0             # cycles of the boxes run on the clock (1 ms simulated each)
    wall_s: float = 0.0         # wall time from the clock's start to the end
    overruns: int = 0           # cycles finished after their deadline
    stalls: int = 0             # runs of consecutive overruns (one stall: several cycles)
    worst_late_s: float = 0.0   # largest lateness past a deadline
    slipped_cycles: int = 0     # cycles skipped when the loop fell MAX_LAG_CYCLES behind
    advance_s: float = 0.0      # wall time spent simulating the boxes
    worst_advance_s: float = 0.0
    handle_s: float = 0.0       # wall time spent answering frames
    frames_received: int = 0    # frames the transport delivered
    frames_served: int = 0      # frames answered
    bad_frames: int = 0         # CRC trailer / PDU failed: not answered (chain)
    stale_frames: int = 0       # older than the newest frame seen: not answered (chain)
    missed_cycles: int = 0      # master cycle numbers skipped within a session
    incomplete_cycles: int = 0  # master cycles whose frames did not cover every box
    sessions: int = 0           # runs of frames separated by more than SESSION_GAP_S
    send_errors: int = 0        # replies the transport refused
    lag_max_s: float = 0.0      # largest lag of simulated time behind wall time
    fresh_by_schedule: int = 0  # box cycles fresh by a write in their scheduled ms only
    # time the serving / box thread was runnable but waited for a CPU [ms] (None: unknown)
    serve_run_delay_ms: float | None = None
    box_run_delay_ms: float | None = None

    def as_dict(self) -> dict:
        d = asdict(self)
        sim = self.cycles * PERIOD_S
        d["simulated_s"] = sim
        d["real_time_factor"] = sim / self.wall_s if self.wall_s > 0 else 0.0
        d["compute_speed_factor"] = sim / self.advance_s if self.advance_s > 0 else 0.0
        d["load"] = (self.advance_s + self.handle_s) / self.wall_s if self.wall_s > 0 else 0.0
        d["mean_advance_ms"] = self.advance_s / self.cycles * 1e3 if self.cycles else 0.0
        d["worst_advance_ms"] = self.worst_advance_s * 1e3
        d["worst_late_ms"] = self.worst_late_s * 1e3
        d["overrun_fraction"] = self.overruns / self.cycles if self.cycles else 0.0
        d["lag_max_ms"] = self.lag_max_s * 1e3
        return d


class PacedServer:
    """A paced chain on one transport end. :meth:`run` serves until ``seconds`` of wall
    time pass (``None``: until ``stop()`` returns True) or the transport fails."""

    def __init__(self, chain: Chain, end, period_s: float = PERIOD_S,
                 clock: Callable[[], float] = time.perf_counter,
                 capture: Callable[[int, str, bytes], None] | None = None,
                 late_us: float = 1000.0) -> None:
        if not chain.paced:
            raise ValueError("PacedServer needs Chain(..., paced=True)")
        from hil.fieldbus import wire
        from hil.fieldbus.reply_times import ReplyTimes
        from protocols import ethercat as ec

        self._open_frame = wire.open_frame  # (bound once: looked up at every frame)
        self._lrw = ec.Command.LRW
        self.chain = chain
        self.end = end
        self.period = period_s
        self.clock = clock
        #: capture(wall time ns, "tx"/"rx", frame): every frame received and reply sent.
        self.capture = capture
        self.stats = ServeStats()
        #: Per answered frame: from its arrival (the transport's recv returning) to the
        #: reply's send returning.
        self.replies = ReplyTimes(late_us)
        self.error: str | None = None  # a transport failure that ended the run
        self._windows = [(w.lad, w.end) for w in chain.plan.windows]
        self._all = (1 << len(self._windows)) - 1
        self._idx: int | None = None
        self._covered = 0
        self._last_frame_t = -1e9
        self._boxes: ClockedBoxes | None = None

    # --- frames ---------------------------------------------------------------------------
    def _serve(self, frame: bytes) -> None:
        st = self.stats
        t = self.clock()
        st.frames_received += 1
        if self.capture is not None:
            self.capture(time.time_ns(), "tx", frame)
        if t - self._last_frame_t > SESSION_GAP_S:
            # A new master session (restarted, cycle numbers from anywhere): do not judge
            # its first frame stale against the previous session's numbers.
            self.chain.started = False
        before = self.chain.stats.bad_frames, self.chain.stats.stale_frames
        reply = self.chain.handle(frame)
        if reply is not None:
            try:
                self.end.send(reply)
                st.frames_served += 1
                self.replies.add((self.clock() - t) * 1e6)
                if self.capture is not None:
                    self.capture(time.time_ns(), "rx", reply)
            except TransportError as exc:
                st.send_errors += 1
                self.error = f"send: {exc}"
            self._audit(frame, t)
        done = self.clock()
        st.handle_s += done - t
        st.bad_frames += self.chain.stats.bad_frames - before[0]
        st.stale_frames += self.chain.stats.stale_frames - before[1]

    def _audit(self, frame: bytes, t: float) -> None:
        """Track the master's cycle numbers: skipped ones and cycles not covering every box
        (the last cycle of a session is not judged: it may be cut short)."""
        dgs = self._open_frame(frame, self.chain.crc_trailer)
        if not dgs:
            return
        covered = 0
        for d in dgs:
            if d.cmd != self._lrw:
                continue
            lo, hi = d.lad, d.lad + len(d.data)
            for k, (a, b) in enumerate(self._windows):
                if lo <= a and b <= hi:
                    covered |= 1 << k
        idx = dgs[0].idx
        st = self.stats
        if self._idx is None or t - self._last_frame_t > SESSION_GAP_S:
            st.sessions += 1
            self._idx, self._covered = idx, covered
        elif idx == self._idx:
            self._covered |= covered
        else:
            if self._covered != self._all:
                st.incomplete_cycles += 1
            st.missed_cycles += ((idx - self._idx) & 0xFF) - 1
            self._idx, self._covered = idx, covered
        self._last_frame_t = t

    def _drain(self) -> None:
        while (frame := self.end.recv(timeout=0)) is not None:
            self._serve(frame)

    # --- the loop -------------------------------------------------------------------------
    def prepare(self) -> ClockedBoxes:
        """The boxes taken onto their own clock and their first :data:`WARMUP_CYCLES` cycles
        run (the kernels compiled or loaded), once: before the ready line, while a signal
        still ends the command (a cold cache compiles for minutes on a loaded machine)."""
        if self._boxes is None:
            from hil.fieldbus.box_clock import ClockedBoxes

            self._boxes = ClockedBoxes(self.chain)
            for _ in range(WARMUP_CYCLES):
                self._boxes.cycle()
        return self._boxes

    def release(self) -> None:
        """The boxes handed back to the chain (after :meth:`run`, or instead of it)."""
        if self._boxes is not None:
            self._boxes.release()

    def run(self, seconds: float | None = None, stop: Callable[[], bool] = lambda: False,
            progress: Callable[[ServeStats], None] | None = None,
            progress_every_s: float = 1.0, box_setup: Callable[[], None] | None = None,
            box_behind: Callable[[int], None] | None = None) -> ServeStats:
        """Serve frames in this thread while the boxes run on their own clock in another
        (:class:`~hil.fieldbus.box_clock.BoxClock`); ``box_setup`` / ``box_behind``: the
        box thread's real-time hooks (:class:`hil.sim.realtime.RealtimePlan`)."""
        from hil.fieldbus.box_clock import BoxClock
        from hil.sim.cpu_account import run_delay_ns

        st, clock = self.stats, self.clock
        boxes = self.prepare()
        box_clock = BoxClock(boxes.cycle, box_setup, box_behind)
        gc.collect()
        gc.freeze()  # long-lived objects out of the collector's way: shorter pauses
        # A box model's Python holds the interpreter lock between its compiled parts; a
        # frame waiting for the lock gets it after this long, not after the default 5 ms.
        switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        waited0 = run_delay_ns()
        start = clock()
        box_clock.begin(time.monotonic_ns())
        end = None if seconds is None else start + seconds  # wall seconds, whatever the lag
        # (no progress callback: no report is ever due)
        next_report = start + (progress_every_s if progress is not None else float("inf"))
        try:
            while (not stop() and self.error is None and box_clock.is_alive()
                   and (end is None or clock() < end)):
                now = clock()
                wait = min(WATCH_S, next_report - now) if end is None else \
                    min(WATCH_S, next_report - now, end - now)
                frame = self.end.recv(timeout=max(wait, 0.0))
                if frame is not None:
                    self._serve(frame)
                    self._drain()
                if progress is not None and clock() >= next_report:
                    self._box_stats(box_clock.stats)
                    st.wall_s = clock() - start
                    progress(st)
                    next_report += progress_every_s
        except TransportError as exc:
            self.error = str(exc)
        finally:
            box_clock.stop()
            boxes.release()
            sys.setswitchinterval(switch)
            gc.unfreeze()
            st.wall_s = clock() - start
            waited = run_delay_ns()
            self._box_stats(box_clock.stats)
            st.fresh_by_schedule = boxes.fresh_by_schedule
            st.serve_run_delay_ms = _delay_ms(waited0, waited)
            st.box_run_delay_ms = _delay_ms(0, box_clock.run_delay_ns)
        if box_clock.error is not None:
            raise box_clock.error
        return st

    def _box_stats(self, b) -> None:  # noqa: ANN001 - BoxClockStats
        st = self.stats
        st.cycles, st.overruns, st.stalls = b.cycles, b.overruns, b.stalls
        st.worst_late_s, st.slipped_cycles = b.worst_late_ms / 1e3, b.slipped_cycles
        st.advance_s, st.worst_advance_s = b.compute_s, b.worst_cycle_ms / 1e3
        st.lag_max_s = max(b.lag_max_ms, 0.0) / 1e3

    def transport_errors(self) -> int:
        """Frames the transport dropped as damaged (CRC, framing, oversize)."""
        s = self.end.stats
        return s.crc_errors + s.framing_errors + s.oversize


# --- command line ------------------------------------------------------------------------------
def _delay_ms(a: int | None, b: int | None) -> float | None:
    return None if a is None or b is None else round((b - a) / 1e6, 3)


def _usage(msg: str) -> Exception:
    return UsageError(msg)


def serve_backends() -> list[str]:
    """The transports ``eha-hil serve`` offers, known without importing them (the parser is
    built at every start: a class's import can be python-can's)."""
    from hil.transports import SERVING_BACKENDS

    return list(SERVING_BACKENDS)


def _open_end(args: argparse.Namespace):
    """(transport end, where it listens, release callable or None). The backend's listen
    takes the options of ours it declares (``host``, ``baudrate``)."""
    import inspect

    from hil.transports import backend

    kind = backend(args.transport)
    declared = inspect.signature(kind.listen).parameters
    opts = {k: v for k, v in (("host", args.host), ("baudrate", args.baudrate))
            if k in declared}
    port = args.port if args.port is not None else kind.default_listen_address
    if port is None:
        raise _usage(f"--port: required with --transport {args.transport}")
    try:
        listening = kind.listen(port, **opts)
    except TransportError as exc:
        raise _usage(str(exc)) from None
    return listening.end, listening.where, listening.close


def _compute_workers(engine, rt) -> None:  # noqa: ANN001 - RobotEngine, RealtimePlan
    """The whole-robot engine computes on the CPUs the frames leave it: one worker per
    compute CPU (the frame thread keeps a CPU of its own; on two CPUs: one worker)."""
    if engine is None:
        return
    from hil.sim.realtime import compute_cpu_count

    engine.workers = max(1, min(compute_cpu_count(rt), engine._workers()))


def _realtime_note(rt) -> str:  # noqa: ANN001 - RealtimePlan
    return "; real time: " + ", ".join(rt.applied) if rt.applied else ""


def _realtime_warnings(rt) -> None:  # noqa: ANN001 - RealtimePlan
    for w in rt.warnings:
        print(f"eha-hil serve: warning: --realtime: {w}; running without it",
              file=sys.stderr, flush=True)


def _status_line(st: ServeStats, errors: int) -> str:
    load = 100 * (st.advance_s + st.handle_s) / max(st.wall_s, 1e-9)
    return (f"serve: {st.wall_s:6.1f} s  {st.cycles} cycles  overruns {st.overruns} "
            f"(worst {st.worst_late_s * 1e3:.2f} ms)  frames {st.frames_served} served  "
            f"errors {errors}  load {load:.0f}%")


def _live_view(args: argparse.Namespace, chain: Chain, cfg, log=None):  # noqa: ANN001, ANN202
    """``--foxglove`` and/or ``--log`` (``log``, an open writer): (live view or None, the
    recorders sending the boxes' decoded signals there and logging them), or (None, [])."""
    if args.foxglove is None and log is None:
        return None, []
    from hil.replay.record import attach_recorders

    live = None
    if args.foxglove is not None:
        from hil.framelog.live import FoxgloveLive, LiveError, parse_address

        try:
            live = FoxgloveLive(*parse_address(args.foxglove))
        except (ValueError, LiveError) as exc:
            raise _usage(str(exc)) from None
    recs = attach_recorders(chain, cfg, log, live, args.level, background=True)
    if live is not None:
        print(f"eha-hil serve: foxglove live view at {live.url} (decoded signals of "
              f"{len(chain.boxes)} box(es), sent every {_block_ms(recs, args.level)} ms)",
              file=sys.stderr, flush=True)
    return live, recs


def _block_ms(recs: list, level: str) -> int:
    """Simulated ms between the recorders' blocks of decoded signals (a cycle is 1 ms)."""
    from hil.replay.record import flush_cycles

    if not recs:
        return flush_cycles(level)
    # a RobotRecorder's block, else a RecordingStackBox's
    return getattr(recs[0], "cycles", None) or getattr(recs[0], "flush_cycles",
                                                       flush_cycles(level))


def _open_log(args: argparse.Namespace, path: str | None, model: str):  # noqa: ANN202
    """``--log``: the frame log's writer (None without it); the echo model has no MCU."""
    if path is None:
        return None
    if model == "echo":
        raise _usage("--log records the MCU's words: use --model stack or robot (the echo "
                     "model has no MCU)")
    from hil.framelog import FrameLogWriter
    from hil.replay.record import flush_cycles

    return FrameLogWriter(path, level=args.level, compression=args.log_compression,
                          flush_every_ns=flush_cycles(args.level) * 1_000_000,
                          metadata={"mode": "serve (paced to the wall clock)"})


def _close_log(log, recs: list, topo, cfg, chain, model: str, cycles: int) -> None:  # noqa: ANN001
    """Write out the recorders' last blocks and what a replay needs; close the log."""
    try:
        for r in recs:
            getattr(r, "close", r.flush)()
    finally:
        if log is not None:
            from hil.replay.record import replay_metadata  # (mcap with it: only for a log)

            log.add_metadata("eha-hil.replay", replay_metadata(topo, cfg, chain.boxes, model,
                                                               cycles))
            log.close()


def run_serve(args: argparse.Namespace, ctx: Context) -> Outcome:
    """``eha-hil serve``: its report once the serving ends (a signal here ends the serving,
    not the command: the report is the point)."""
    return cmd_serve(args, ctx.config())


def cmd_serve(args: argparse.Namespace, cfg) -> Outcome:
    from hil.fieldbus.topology import TopologyError, load_topology

    try:
        topo = load_topology(args.topology)
    except TopologyError as exc:
        raise _usage(str(exc)) from None
    if args.transport == "ethercat":
        return cmd_serve_ethercat(args, cfg, topo)
    from hil.cli import outputs

    # capture and log are written under a temporary name, renamed when closed
    # (hil.cli.outputs)
    with outputs.streaming({"capture": args.capture, "log": args.log},
                           {"capture": "capture", "log": "log"}, _LOG_CHECK) as tmp:
        return _serve(args, cfg, topo, tmp.get("capture"), tmp.get("log"))


def _readable_log(path) -> str:  # noqa: ANN001
    from hil.cli.progress import readable_log

    return readable_log(path)


_LOG_CHECK = {"log": _readable_log}


def _serve(args: argparse.Namespace, cfg, topo, capture: str | None,
           log_path: str | None = None) -> Outcome:
    from hil.fieldbus import reply_times
    from hil.fieldbus.capture import CaptureError, CaptureWriter
    from hil.fieldbus.chain import Chain
    from hil.sim.cpu_account import steal_during, steal_s
    from hil.sim.realtime import RealtimePlan
    from hil.transports import backend

    model = args.model or ("stack" if topo.n_actuators <= 5 else "echo")
    trailer = (backend(args.transport).crc_trailer_by_default if args.crc_trailer is None
               else args.crc_trailer)
    chain = Chain(topo, cfg, model, paced=True, crc_trailer=trailer)
    rt = RealtimePlan(args.realtime)
    _compute_workers(chain.engine, rt)
    log = _open_log(args, log_path, model)
    live, live_boxes = _live_view(args, chain, cfg, log)
    end, where, release = _open_end(args)
    cap = None
    if args.capture:

        def endpoints():
            ends = end.capture_endpoints()  # (ours: the chain's, the master's)
            return None if ends is None else (ends[1], ends[0])

        try:
            cap = CaptureWriter(capture, trailer, endpoints)
        except CaptureError as exc:
            end.close()
            if release is not None:
                release()
            raise _usage(str(exc)) from None
    server = PacedServer(chain, end, capture=None if cap is None else cap.write,
                         late_us=args.late_us)
    frames = [{"lad": lad, "length": n, "wkc": wkc} for lad, n, wkc in chain.plan.frames]
    plan = ", ".join(f"LRW lad {f['lad']} len {f['length']} WKC {f['wkc']}" for f in frames)
    tty = sys.stderr.isatty()

    def progress(st: ServeStats) -> None:
        line = _status_line(st, st.bad_frames + server.transport_errors())
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr,
              flush=True)

    stopping = []

    def on_signal(signum, frame) -> None:
        stopping.append(signum)

    try:
        # the boxes' first cycles before the ready line (the kernels compiled or loaded),
        # while a signal still ends the command, and before --realtime: a compile at
        # SCHED_FIFO would hold a CPU from everything below it for minutes
        server.prepare()
        rt.process()
        rt.frame_thread()  # this thread answers the frames
        old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        print(f"eha-hil serve: ready on {where}; {topo.name}, {model} model, "
              f"{len(frames)} frame(s) per 1 ms cycle: {plan}; "
              f"{'with' if trailer else 'without'} CRC-32 trailer"
              + _realtime_note(rt), file=sys.stderr, flush=True)
        _realtime_warnings(rt)
        steal0 = steal_s()
        try:
            st = server.run(args.seconds, stop=lambda: bool(stopping),
                            progress=None if args.quiet else progress,
                            box_setup=rt.box_thread, box_behind=rt.box_behind)
        finally:
            for s, h in old.items():
                signal.signal(s, h)
    finally:
        server.release()
        transport = end.stats.as_dict()
        terrors = server.transport_errors()
        end.close()
        if release is not None:
            release()
        if cap is not None:
            cap.close()
        try:
            _close_log(log, live_boxes, topo, cfg, chain, model,
                       chain.stats.cycles_advanced)
        finally:
            if live is not None:
                live.close()
    if tty and not args.quiet:
        print(file=sys.stderr)

    allowed = args.max_overrun_percent / 100.0 * st.cycles
    failures = []
    if server.error:
        failures.append(f"transport failed: {server.error}")
    if st.frames_served == 0:
        failures.append("no frame was served (nothing arrived from a master)")
    for key, what in (("bad_frames", "bad frames"), ("stale_frames", "stale frames"),
                      ("missed_cycles", "master cycles missed"),
                      ("incomplete_cycles", "incomplete master cycles"),
                      ("send_errors", "replies not sent")):
        if getattr(st, key):
            failures.append(f"{getattr(st, key)} {what}")
    if terrors:
        failures.append(f"{terrors} frames damaged on the transport")
    if st.bad_frames and not st.frames_served:
        failures.append("(no frame decoded: does the master add a CRC-32 trailer? then "
                        "--crc-trailer)" if not trailer else "(no frame decoded: does the "
                        "master send bare EtherCAT frames? then --no-crc-trailer)")
    if st.overruns > allowed:
        failures.append(f"{st.overruns} overruns > {args.max_overrun_percent:g}% of "
                        f"{st.cycles} cycles")
    failures += _timing_failures(server.replies.late, st.frames_served, st.lag_max_s * 1e3,
                                 args)
    data = {"transport": args.transport, "where": where, "topology": topo.name,
            "crc_trailer": trailer, "capture": args.capture,
            "captured_frames": None if cap is None else cap.frames,
            "boxes": len(topo.boxes), "actuators": topo.n_actuators, "model": model,
            "period_ms": PERIOD_S * 1e3, "frames_per_cycle": frames,
            "max_overrun_percent": args.max_overrun_percent,
            "overrun_limit_exceeded": st.overruns > allowed,
            **st.as_dict(), "transport_stats": transport,
            "frames_late": server.replies.late, "late_us": args.late_us,
            "reply_us": reply_times.summary(server.replies.hist, server.replies.max_us),
            "reply_histogram_us": reply_times.decades(server.replies.hist),
            "max_late_percent": args.max_late_percent, "max_lag_ms": args.max_lag_ms,
            "steal_ms": steal_during(steal0, steal_s()),
            "realtime": {"applied": rt.applied, "refused": rt.warnings,
                         "box_thread_demotions": rt.demotions},
            "chain": {k: v for k, v in chain.stats.__dict__.items() if k != "extra"},
            "ok": not failures, "failures": failures}
    # the report for people (the root prints ``data`` instead under --json)
    from hil.output.tables import table

    d = st.as_dict()
    rows = [
        ["cycles (1 ms each)", st.cycles],
        ["wall time", f"{st.wall_s:.3f} s"],
        ["real-time factor (simulated / wall)", f"{d['real_time_factor']:.4f}"],
        ["compute speed (x real time)", f"{d['compute_speed_factor']:.1f}"],
        ["load (busy / wall)", f"{100 * d['load']:.1f}%"],
        ["cycle compute mean / worst", f"{d['mean_advance_ms']:.3f} / "
         f"{d['worst_advance_ms']:.3f} ms"],
        ["deadline overruns", f"{st.overruns} ({100 * d['overrun_fraction']:.2f}%, "
         f"allowed {args.max_overrun_percent:g}%) in {st.stalls} stalls"],
        ["worst lateness", f"{d['worst_late_ms']:.3f} ms"],
        ["slipped cycles", st.slipped_cycles],
        ["lag of simulated behind wall time, max", f"{d['lag_max_ms']:.2f} ms "
         f"(allowed {args.max_lag_ms:g} ms)"],
        ["frames received / served", f"{st.frames_received} / {st.frames_served}"],
        ["reply p50 / p99 / p99.9 / max", reply_times.line(data["reply_us"])],
        [f"replies later than {args.late_us:g} us", f"{server.replies.late} "
         f"(allowed {args.max_late_percent:g}%)"],
        ["bad / stale frames", f"{st.bad_frames} / {st.stale_frames}"],
        ["transport CRC / framing / oversize", f"{transport['crc_errors']} / "
         f"{transport['framing_errors']} / {transport['oversize']}"],
        ["master cycles missed / incomplete", f"{st.missed_cycles} / "
         f"{st.incomplete_cycles}"],
        ["master sessions", st.sessions],
        ["time the hypervisor stole from each CPU", _steal(data["steal_ms"])],
        ["real time", ", ".join(rt.applied) or "off"],
    ]
    lines = [f"serve {where}: {topo.name}, {model} model", table(["", "value"], rows)]
    if cap is not None:
        lines.append(f"capture: {args.capture}, {cap.frames} frames")
    if log is not None:
        lines.append(f"log: {args.log} (eha-hil log info {args.log}; eha-hil replay "
                     f"{args.log})")
    lines.append("ok" if not failures else "FAILED: " + "; ".join(failures))
    return Outcome("\n".join(lines), data, EXIT_OK if not failures else EXIT_FAILED)


def cmd_serve_ethercat(args: argparse.Namespace, cfg, topo) -> Outcome:
    """``--transport ethercat``: the ESC slaves (:mod:`hil.fieldbus.esc.serve`) on a raw
    Ethernet interface for a real master (docs/ethercat-slaves.md)."""
    from hil.transports.rawether import RawEthernet

    if not args.interface:
        raise _usage("--interface: required with --transport ethercat")
    for opt, hint in (("capture", "capture the interface with tshark"),
                      ("foxglove", "not offered for the ESC chain"),
                      ("port", "the interface is --interface")):
        if vars(args)[opt] is not None:
            raise _usage(f"--{opt}: not with --transport ethercat ({hint})")
    bad = [b for b in args.stack_boxes if not 0 <= b < len(topo.boxes)]
    if bad:
        raise _usage(f"--stack-box {bad[0]}: {topo.name} has boxes 0..{len(topo.boxes) - 1}")
    dc = _dc_line(args, topo)
    model = args.model or "echo"
    if args.log and model == "echo" and not args.stack_boxes:
        raise _usage("--log records the MCU's words: use --model stack or robot, or "
                     "--stack-box N (the echo model has no MCU)")
    from hil.cli import outputs

    with outputs.streaming({"log": args.log}, {"log": "log"}, _LOG_CHECK) as tmp:
        try:
            link = RawEthernet(args.interface)
        except TransportError as exc:
            raise _usage(str(exc)) from None
        return _serve_ethercat(args, cfg, topo, link, model, tmp.get("log"), dc)


def _serve_ethercat(args: argparse.Namespace, cfg, topo, link, model: str,  # noqa: ANN001
                    log_path: str | None, dc) -> Outcome:  # noqa: ANN001
    import threading

    from hil.fieldbus import reply_times
    from hil.fieldbus.chain import CYCLE_TICKS
    from hil.fieldbus.esc.serve import ServedChain, serve, warm_up
    from hil.sim.realtime import RealtimePlan

    rt = RealtimePlan(args.realtime)
    log = recs = None
    try:
        chain = ServedChain(topo, cfg, model, tuple(args.stack_boxes), coe=args.coe, dc=dc)
        if log_path is not None:
            from hil.replay.record import attach_recorders

            log = _open_log(args, log_path, "stack")
            recs = attach_recorders(chain, cfg, log, None, args.level, background=True)
            for m in chain.mailboxes.each:  # the slaves' CoE side reads the new boxes
                if m is not None:
                    m.box = chain.boxes[m.i]
            chain.publish_inputs()  # (the recording boxes' own, equal to the replaced)
        _compute_workers(chain.engine, rt)
        # (compiling on a cold cache: a signal still ends the command, and at the ordinary
        # priority: under --realtime's SCHED_FIFO it would hold a CPU for minutes)
        warm_up(chain)
        rt.process()

        def ready() -> None:
            print(f"eha-hil serve: ready on {args.interface} (EtherType 0x88a4); {topo.name}, "
                  f"{len(topo.boxes)} slaves, {model} model"
                  + (f", full stack behind box(es) {args.stack_boxes}" if args.stack_boxes
                     else "") + _realtime_note(rt), file=sys.stderr, flush=True)
            _realtime_warnings(rt)

        stopping = []
        wake = threading.Event()

        def on_signal(signum, frame) -> None:
            stopping.append(signum)
            wake.set()

        old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            st, hist = serve(chain, link, args.seconds, stop=lambda: bool(stopping),
                             wake=wake, ready=ready, late_us=args.late_us,
                             frame_setup=rt.frame_thread, box_setup=rt.box_thread,
                             box_behind=rt.box_behind)
        finally:
            for s, h in old.items():
                signal.signal(s, h)
    finally:
        link.close()
        if log is not None:
            _close_log(log, recs, topo, cfg, chain, model,
                       chain.engine.tick // CYCLE_TICKS if chain.engine is not None
                       else chain.boxes[0].tick // CYCLE_TICKS)
    reply = reply_times.summary(hist, st.reply_max_us)
    failures = ethercat_failures(st, args)
    data = {"transport": "ethercat", "interface": args.interface, "topology": topo.name,
            "model": model, "stack_boxes": list(args.stack_boxes), **st.as_dict(),
            "mailbox": chain.mailboxes.stats(),
            "simulated_s": st.cycles * PERIOD_S,
            "frames_per_s": st.frames_answered / st.wall_s if st.wall_s > 0 else 0.0,
            "overrun_percent": 100 * st.overruns / st.cycles if st.cycles else 0.0,
            "late_percent": (100 * st.frames_late / st.frames_answered
                             if st.frames_answered else 0.0),
            "reply_us": reply,
            "reply_histogram_us": reply_times.decades(hist),
            "realtime": {"applied": rt.applied, "refused": rt.warnings,
                         "box_thread_demotions": rt.demotions},
            "thresholds": {"max_overrun_percent": args.max_overrun_percent,
                           "max_late_percent": args.max_late_percent,
                           "max_lag_ms": args.max_lag_ms, "late_us": args.late_us},
            "slaves": chain.watchdog_report(), "dc": chain.dc_report(),
            "ok": not failures, "failures": failures}
    text = ethercat_table(data) + "\n" + ("ok" if not failures else
                                           "FAILED: " + "; ".join(failures))
    if log is not None:
        text += f"\nlog: {args.log} (eha-hil log info {args.log}; eha-hil replay {args.log})"
    return Outcome(text, data, EXIT_OK if not failures else EXIT_FAILED)


def _dc_line(args: argparse.Namespace, topo):  # noqa: ANN202 - list[DcParams]
    """The slaves' clocks from --dc-drift-ppm / --dc-hop-ns (one line naming the mistake)."""
    from firmware_model.esc.dc import dc_line

    n = len(topo.boxes)
    drift = args.dc_drift_ppm if len(args.dc_drift_ppm) > 1 else args.dc_drift_ppm[0]
    try:
        return dc_line(n, drift, args.dc_hop_ns)
    except ValueError as exc:
        raise _usage(f"--dc-drift-ppm: {exc} ({topo.name})") from None


def _ppm_list(text: str) -> list[float]:
    try:
        out = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number or a comma-separated "
                                         "list of numbers") from None
    if not all(math.isfinite(v) and abs(v) <= 500 for v in out):
        raise argparse.ArgumentTypeError(f"{text!r}: each drift must be within +-500 ppm")
    return out


def _timing_failures(late: int, answered: int, lag_max_ms: float,
                     args: argparse.Namespace) -> list[str]:
    """Late replies and lag past their documented thresholds (every transport)."""
    out = []
    if answered and 100 * late / answered > args.max_late_percent:
        out.append(f"{late} of {answered} replies later than {args.late_us:g} us "
                   f"(> {args.max_late_percent:g}%)")
    if lag_max_ms > args.max_lag_ms:
        out.append(f"simulated time fell {lag_max_ms:.1f} ms behind wall time "
                   f"(> {args.max_lag_ms:g} ms)")
    return out


def ethercat_failures(st, args: argparse.Namespace) -> list[str]:
    """What exceeded a documented threshold (docs/ethercat-slaves.md, 'Timing')."""
    out = []
    if not st.frames_answered:
        out.append("no EtherCAT frame arrived from a master")
    if st.cycles and 100 * st.overruns / st.cycles > args.max_overrun_percent:
        out.append(f"{st.overruns} of {st.cycles} box cycles overran "
                   f"(> {args.max_overrun_percent:g}%)")
    out += _timing_failures(st.frames_late, st.frames_answered, st.lag_max_ms, args)
    if st.dropped_frames:
        out.append(f"{st.dropped_frames} EtherCAT frames did not decode (dropped)")
    if st.send_errors:
        out.append(f"{st.send_errors} replies could not be sent")
    return out


def ethercat_table(d: dict) -> str:
    from hil.fieldbus import reply_times
    from hil.output.tables import table

    rows = [
        ["wall time / simulated time", f"{d['wall_s']:.2f} s / {d['simulated_s']:.3f} s"],
        ["box cycles (1 ms each)", d["cycles"]],
        ["box cycle compute worst", f"{d['worst_cycle_ms']:.2f} ms"],
        ["overruns", f"{d['overruns']} ({d['overrun_percent']:.2f}%, allowed "
         f"{d['thresholds']['max_overrun_percent']:g}%)"],
        ["slipped cycles", d["slipped_cycles"]],
        ["lag of simulated behind wall time, max",
         f"{d['lag_max_ms']:.2f} ms (allowed {d['thresholds']['max_lag_ms']:g} ms)"],
        ["frames received / answered", f"{d['frames_received']} / {d['frames_answered']}"
         f" ({d['frames_per_s']:.0f} per s; the boxes take the newest outputs once per "
         "1 ms cycle)"],
        ["reply p50 / p99 / p99.9 / max", reply_times.line(d["reply_us"])],
        [f"replies later than {d['late_us']:g} us", f"{d['frames_late']} "
         f"({d['late_percent']:.3f}%, allowed {d['thresholds']['max_late_percent']:g}%)"],
        ["frames dropped (bad) / not EtherCAT", f"{d['dropped_frames']} / "
         f"{d['other_frames']}"],
        ["frame thread: longest absence past its 1 ms poll / longest work",
         f"{d['frame_gap_max_us']:.0f} / {d['frame_work_max_us']:.0f} us"],
        ["time the hypervisor stole from each CPU", _steal(d["steal_ms"])],
        ["real time", ", ".join(d["realtime"]["applied"]) or "off"],
    ]
    dc = d.get("dc")
    if dc and any(s["offset_set"] or s["sync0"] for s in dc["slaves"]):
        spread = dc["spread_ns"]
        rows.append(["distributed clocks", f"SYNC0 on {sum(s['sync0'] for s in dc['slaves'])} "
                     f"of {len(dc['slaves'])} slaves; box cycles at SYNC0 {d['sync0_cycles']}; "
                     f"system-time spread, last {dc['spread_window_ms']:g} ms "
                     f"{next((v for v in reversed(spread) if v >= 0), 0)} ns; out-of-order writes "
                     f"{sum(s['out_of_order_writes'] for s in dc['slaves'])}"])
    hist = ", ".join(f"{k}: {v}" for k, v in d["reply_histogram_us"].items() if v)
    late = sorted(d["late_replies"], key=lambda e: -e["reply_us"])[:5]
    return (f"serve {d['interface']}: {d['topology']}, {d['model']} model\n"
            + table(["", "value"], rows) + f"\nreply times: {hist or 'none'}"
            + ("\nlate replies, worst: " + "; ".join(
                f"at {e['at_s']:.3f} s {e['reply_us']:.0f} us (woke {e['wake_us']:.0f} us "
                f"after the frame arrived, then {e['work_us']:.0f} us to its send)"
                for e in late) if late else ""))


def _steal(per_cpu: dict | None) -> str:
    """Stolen time per CPU [ms] (a virtual machine's CPU not run by its host: every
    thread here stops, whatever its priority)."""
    if per_cpu is None:
        return "unknown (no /proc/stat)"
    return ", ".join(f"{c} {v:.0f} ms" for c, v in per_cpu.items())


def add_parser(sub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``eha-hil serve``."""
    p = sub.add_parser(
        "serve", parents=[common(plot=False)],
        help="serve the simulated robot (chain of boxes) on a serial port or UDP, paced to "
        "the wall clock, for a real master to close the loop",
        epilog="Example: eha-hil serve --transport serial --port pty --seconds 10 "
        "(docs/fieldbus.md, 'Serving the simulated robot to real hardware').")
    p.add_argument("--transport", default="serial", choices=[*serve_backends(), "ethercat"],
                   help="serial (COBS + CRC-32 frames), udp, or ethercat (raw Ethernet "
                   "frames, EtherType 0x88A4, ESC slaves for a real master: --interface)")
    p.add_argument("--interface", help="ethercat: network interface (e.g. eth1, veth0)")
    p.add_argument("--stack-box", dest="stack_boxes", type=int_range(0, 255), action="append",
                   default=[], metavar="N",
                   help="ethercat: box N runs the full stack (repeatable; others: --model)")
    p.add_argument("--dc-drift-ppm", type=_ppm_list, default=[50.0], metavar="PPM",
                   help="ethercat: crystal error of each slave's distributed clock: one "
                   "value X for +X, -X, +X, ... along the line (default 50), or one per "
                   "slave, comma-separated; within +-500")
    p.add_argument("--dc-hop-ns", type=int_range(0, 100_000, unit="ns"), default=500,
                   metavar="NS", help="ethercat: simulated propagation delay from one "
                   "slave to the next, each way, 0..100000 (default 500)")
    p.add_argument("--no-coe", dest="coe", action="store_false",
                   help="ethercat: slaves without a mailbox (no CoE; a master maps the "
                   "process data from the SII alone)")
    p.add_argument("--port",
                   help="serial (required): device path or pyserial URL, or 'pty' for a new "
                   "pseudo-terminal whose path is printed; udp: local port number (default "
                   "34980, EtherCAT's; 0: any)")
    p.add_argument("--host", default="127.0.0.1",
                   help="udp: local address to bind (0.0.0.0 for all)")
    p.add_argument("--baudrate", type=int_range(50, 100_000_000), default=3_000_000,
                   help="serial line speed, 50..100000000 (ignored by ptys)")
    p.add_argument("--topology", default="bench_one_box",
                   help="shipped topology name or TOML file")
    p.add_argument("--model", choices=("stack", "robot", "echo"),
                   help="box model; default stack for <= 5 actuators, echo otherwise")
    p.add_argument("--seconds", type=float_range(1e-3, 1e7, unit="s"),
                   help="wall seconds to serve, in [0.001, 1e7] (default: until Ctrl-C / "
                   "SIGTERM)")
    p.add_argument("--max-overrun-percent", type=float_range(0.0, 100.0, unit="%"),
                   default=DEFAULT_MAX_OVERRUN_PERCENT, metavar="P",
                   help="exit 1 if more than P%% of the cycles overran their deadline, "
                   "P in [0, 100]")
    p.add_argument("--max-late-percent", type=float_range(0.0, 100.0, unit="%"),
                   default=DEFAULT_MAX_LATE_PERCENT, metavar="P",
                   help="exit 1 if more than P%% of the replies left later than --late-us "
                   "after their frame arrived")
    p.add_argument("--late-us", type=float_range(1.0, 1e6, unit="us"), default=1000.0,
                   metavar="US", help="a reply later than this is late "
                   "(default 1000 us, one cycle)")
    p.add_argument("--max-lag-ms", type=float_range(0.0, 1e7, unit="ms"),
                   default=DEFAULT_MAX_LAG_MS, metavar="MS",
                   help="exit 1 if the boxes' simulated time fell more than MS behind "
                   "the wall clock")
    p.add_argument("--realtime", action="store_true",
                   help="real-time hygiene (root or CAP_SYS_NICE/CAP_IPC_LOCK): frames at "
                   "SCHED_FIFO 50 on the last CPU, boxes at SCHED_FIFO 20 on the others "
                   "while on schedule, memory locked (docs/ethercat-slaves.md, 'Timing')")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no status line on stderr (the ready line is still printed)")
    from hil.cli.bus import add_wire_options

    add_wire_options(p)
    p.add_argument("--log", metavar="FILE.mcap", type=output_file((".mcap",)),
                   help="log what every MCU took in and gave out, and the decoded signals "
                   "(docs/framelog.md); --model stack or robot")
    p.add_argument("--level", default="mcu", choices=("bus", "mcu", "full"),
                   help="--log: level of detail (full: the driver boards' traces too)")
    p.add_argument("--log-compression", default="zstd", choices=("zstd", "lz4", "none"),
                   help="--log: compression of the log's chunks")
    p.add_argument("--foxglove", nargs="?", const="", metavar="HOST:PORT",
                   help="stream the boxes' decoded signals to Foxglove Studio (WebSocket; "
                   "default 127.0.0.1:8765, loopback)")
    _scope_options(p)
    command(p, run_serve)


def _scope_options(p: argparse.ArgumentParser) -> None:
    """Each transport's own options, refused with another (hil.cli.args.only_with)."""
    from hil.cli.args import only_with

    # (--capture and --foxglove with ethercat are refused by cmd_serve_ethercat, with hints)
    stream = tuple(serve_backends())
    scopes = {"baudrate": ("serial",), "host": ("udp",), "port": stream,
              "interface": ("ethercat",), "stack_boxes": ("ethercat",),
              "dc_drift_ppm": ("ethercat",), "dc_hop_ns": ("ethercat",)}
    for action in p._actions:
        if action.dest in scopes:
            only_with(action, "transport", *scopes[action.dest])
