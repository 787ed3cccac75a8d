"""Where the CPU of a logged whole-robot run goes: the logging's parts, per simulated second,
adding up to what the logged run costs more than the bare one.

``eha-hil bench log`` gives the whole cost (logged / bare CPU); this splits the logged run's
extra CPU (logged minus bare, both measured here) into:

* **file side** (``hil/framelog``: building records, compressing and writing chunks,
  opening and closing the file) and **producer side** (``hil/replay``: the engine's hooks
  per cycle, the fieldbus tap per cycle, decoding and encoding the signals, set-up): each
  function of :data:`PARTS` is wrapped for the run and its *own* CPU (``time.thread_time``
  of the thread that runs it, less the wrapped functions it calls) summed, so the parts
  add up without double counting; zstd is timed inside the chunk closing
  (``hil.framelog.chunk``); the fieldbus tap (the closure of
  ``hil.replay.record.BusSignals.tap`` the bus system calls each cycle) as it is made;
* **in the engine's compiled calls**: the CPU of the cycle's compiled calls in every
  compute thread (the calling thread's share, :meth:`RobotEngine._compute`, and the helper
  threads' whole CPU, by their POSIX thread clocks) of the logged run less the bare run's:
  the kernel's copies of each MCU step's words (``_log_words``) and whatever else the
  logging costs the kernel (its data evicted from the caches by the file side's work);
* **timers**: what the wrappers themselves cost (calls counted, each at the cost of one
  wrapped call of an empty function, measured here; what a wrapper counts inside the
  function it times is taken off that function's own CPU);
* **rest**: the difference less all of the above: ``run_logged``'s glue (the PC callback's
  wrapper, the tap's lists), and the bare run's own work done slower beside the logging
  (caches, memory bandwidth), plus the two runs' noise.

Run: ``python -m hil.bench.log_parts [seconds] [topology] [pairs]`` (default 2 s of
``hydra_full`` at level ``mcu``, zstd, one pair), after a warm-up of both runs; with
several pairs (the order alternating) the figures are their sums. The figures grow with
the machine's load (caches and memory bandwidth are shared): quote them with ``uptime``.
"""

from __future__ import annotations

import contextlib
import gc
import resource
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

#: (module, attribute path, side) of every wrapped function.
PARTS: tuple[tuple[str, str, str], ...] = (
    ("hil.framelog.chunk", "_finalize", "file"),
    ("hil.framelog.batch", "records", "file"),
    ("hil.framelog.batch", "add_records", "file"),
    ("hil.framelog.batch", "add_messages", "file"),
    ("hil.framelog.rawpb", "pack_blocks", "file"),
    ("hil.framelog.rawpb", "wrap_many", "file"),
    ("hil.framelog.writer", "FrameLogWriter.__init__", "file"),
    ("hil.framelog.writer", "FrameLogWriter.close", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_blocks", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_block", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages_many", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages_filled", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write", "file"),
    # the channels' and schemas' records, made as the recorders set up (~200 channels of
    # hydra_full: most of RobotRecorder.__init__'s CPU, counted there before)
    ("hil.framelog.writer", "FrameLogWriter.add_channel", "file"),
    ("hil.framelog.writer", "FrameLogWriter.add_block_channel", "file"),
    ("hil.framelog.writer", "FrameLogWriter.add_protobuf_channel", "file"),
    ("hil.framelog.writer", "FrameLogWriter.add_metadata", "file"),
    ("hil.framelog.protobuf", "MessageType.encode_array", "producer"),
    ("hil.replay.signals", "actuator_block", "producer"),
    ("hil.replay.signals", "record_columns", "producer"),
    ("hil.replay.signals", "pc_command_block", "producer"),
    ("hil.replay.signals", "report_flags", "producer"),
    ("hil.replay.robot_record", "RobotRecorder.__init__", "producer"),
    ("hil.replay.robot_record", "RobotRecorder.finished", "producer"),
    ("hil.replay.robot_record", "RobotRecorder.flush", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write_records", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write_steps", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write", "producer"),
    ("hil.replay.signal_kernel", "ActuatorEncoder.encode", "producer"),
    ("hil.replay.signal_records", "RecordEncoder.encode", "producer"),
    ("hil.replay.signal_out", "SignalOut.write_split", "producer"),
    ("hil.replay.signal_out", "SignalOut.write_filled", "producer"),
    ("hil.replay.record", "RecordingStackBox.flush", "producer"),  # (--model stack)
    ("hil.replay.record", "RecordingStackBox._write_signals", "producer"),
    ("hil.replay.record", "BusSignals.flush", "producer"),
)
SIDES = ("file", "producer")
#: The label of the fieldbus tap's own CPU (the closure :meth:`BusSignals.tap
#: <hil.replay.record.BusSignals.tap>` makes for the bus system, wrapped as it is made).
TAP = "producer: fieldbus tap (per cycle)"


class _Timer:
    """Own thread CPU and calls per label of the functions wrapped with :meth:`wrap`."""

    def __init__(self) -> None:
        self.own: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()
        self._inner: list[float] = []

    def wrap(self, fn: Callable, label: str) -> Callable:
        def timed(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            t0 = time.thread_time()
            self._inner.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                dt = time.thread_time() - t0
                self.own[label] += dt - self._inner.pop()
                self.calls[label] += 1
                if self._inner:
                    self._inner[-1] += dt
        return timed


def timer_cost(n: int = 20000) -> tuple[float, float]:
    """CPU seconds one wrapped call adds (the wrapper's own work, thread CPU: two reads of
    the thread clock, each a system call), and of that what the wrapper counts as the
    wrapped function's own CPU (measured on an empty function: the least of 3 tries)."""
    def nothing() -> None:
        return None

    best = (float("inf"), float("inf"))
    for _ in range(3):
        timer = _Timer()
        wrapped = timer.wrap(nothing, "x")
        t0 = time.thread_time()
        for _ in range(n):
            wrapped()
        t1 = time.thread_time()
        for _ in range(n):
            nothing()
        t2 = time.thread_time()
        best = min(best, (((t1 - t0) - (t2 - t1)) / n, timer.own["x"] / n))
    return max(best[0], 0.0), min(max(best[1], 0.0), max(best[0], 0.0))


class _Compute:
    """CPU of the robot engine's compiled calls: the calling thread's share
    (:meth:`RobotEngine._compute`) and the helper threads' whole CPU (read from their
    thread clocks when they are closed)."""

    def __init__(self) -> None:
        self.cpu = 0.0
        self.calls = 0

    def install(self) -> list[tuple[object, str, object]]:
        from hil.sim import compute_threads, robot

        compute, close = robot.RobotEngine._compute, compute_threads.ComputeThreads.close

        def timed_compute(engine, ticks):  # noqa: ANN001, ANN202
            t0 = time.thread_time()
            try:
                return compute(engine, ticks)
            finally:
                self.cpu += time.thread_time() - t0
                self.calls += 1

        def closing(threads):  # noqa: ANN001, ANN202
            threads.join()  # (what close does first: the helpers' last cycle counted)
            self.cpu += sum(_thread_cpu(t) for t in threads.threads)
            return close(threads)

        robot.RobotEngine._compute = timed_compute
        compute_threads.ComputeThreads.close = closing
        return [(robot.RobotEngine, "_compute", compute),
                (compute_threads.ComputeThreads, "close", close)]


def _thread_cpu(t: threading.Thread) -> float:
    """CPU seconds thread ``t`` (alive) has used."""
    if t.ident is None or not t.is_alive():
        return 0.0
    return time.clock_gettime(time.pthread_getcpuclockid(t.ident))


def _install(timer: _Timer) -> list[tuple[object, str, object]]:
    """Wrap every function of :data:`PARTS`, zstd and the fieldbus tap; the originals, to
    put back."""
    import importlib

    from hil.framelog import chunk
    from hil.replay import record

    undo = []
    for module, path, side in PARTS:
        owner = importlib.import_module(module)
        *outer, name = path.split(".")
        for part in outer:
            owner = getattr(owner, part)
        fn = getattr(owner, name, None)
        if fn is None:
            continue  # not in this version of the code
        undo.append((owner, name, fn))
        setattr(owner, name, timer.wrap(fn, f"{side}: {path}"))
    make = chunk.compressor
    undo.append((chunk, "compressor", make))
    chunk.compressor = lambda c, lvl: timer.wrap(make(c, lvl), "file: zstd (in _finalize)")
    tap = record.BusSignals.tap

    def bus_tap(signals, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        return timer.wrap(tap(signals, *args, **kwargs), TAP)

    undo.append((record.BusSignals, "tap", tap))
    record.BusSignals.tap = bus_tap
    return undo


@dataclass
class Parts:
    """``pairs`` bare and logged runs of ``seconds / pairs`` simulated seconds each (CPU in
    seconds, summed over the pairs; :attr:`extras`: each pair's logged minus bare)."""

    seconds: float
    bare_cpu: float
    logged_cpu: float
    bare_compute: float        # the engine's compiled calls, every thread
    logged_compute: float
    own: Counter[str]          # own CPU per wrapped part of the logged run
    calls: Counter[str] = field(default_factory=Counter)
    timer_s: float = 0.0       # the wrappers' own cost in the logged run (estimate)
    log_bytes: int = 0
    extras: list[float] = field(default_factory=list)

    @property
    def extra(self) -> float:
        """What logging costs: logged minus bare CPU."""
        return self.logged_cpu - self.bare_cpu

    @property
    def in_kernel(self) -> float:
        return self.logged_compute - self.bare_compute

    def side(self, side: str) -> float:
        return sum(v for k, v in self.own.items() if k.startswith(side))

    @property
    def rest(self) -> float:
        return self.extra - self.side("file") - self.side("producer") - self.in_kernel \
            - self.timer_s

    def split(self) -> dict[str, float]:
        """ms per simulated second of each part of :attr:`extra` (they add up to it)."""
        per = 1e3 / self.seconds
        return {"file": self.side("file") * per, "producer": self.side("producer") * per,
                "in_kernel": self.in_kernel * per, "timers": self.timer_s * per,
                "rest": self.rest * per, "total": self.extra * per}


#: Cycles of the warm-up runs before the timed ones: more than two blocks of the log
#: (:data:`hil.replay.record.FLUSH_CYCLES`), so that every compiled call and import of a
#: block's writing is done before the timing starts. Two: the first block of a run ends a
#: few MCU steps short (the engine's first cycle), so its raw blocks are views of the tap's
#: rows, and only the second is the whole (contiguous) rows, which numba compiles apart;
#: loading each such kernel from the cache costs ~6-9 ms at its first call, which with one
#: block of warm-up fell into the first timed logged run.
WARM_CYCLES = 420


@contextlib.contextmanager
def settled() -> Iterator[None]:
    """Timed runs without each other's garbage: what exists before them (imports, compiled
    code, the warm-up's leftovers) collected and then frozen out of the garbage
    collector's way (``gc.freeze``) until the block ends; with :func:`run_cpu`, which
    collects what each run leaves, every run pays for its own garbage and for none of
    another's.

    Why: a logged run leaves ~3,000 objects in reference cycles holding ~10 MB (the
    writer, the recorder and the engine point at each other), freed only by a full
    collection. Without this, the process grew by that much per logged run, every logged
    run touched fresh pages (2,400-3,800 page faults against a bare run's ~500), and the
    full collection (~60 ms, most of it walking the ~130,000 long-lived objects of numba
    and the imports) fell in whichever run came after enough of them, often a bare one:
    a pair's ratio moved by ~0.05-0.1 with it."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@dataclass(frozen=True)
class Run:
    """One timed run: CPU seconds of the whole process (``time.process_time``: every
    thread, the engine's helpers included), wall seconds, minor page faults."""

    cpu: float
    wall: float
    faults: int


def run_cpu(fn: Callable[[], object]) -> Run:
    """``fn()`` timed, with the collection of the cyclic garbage it left (see
    :func:`settled`: inside it, only this run's own objects are walked)."""
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    c0, w0 = time.process_time(), time.perf_counter()
    fn()
    gc.collect()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return Run(cpu, wall, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)


def run_pair(topo, cfg, cycles: int, path: Path, level: str, model: str,  # noqa: ANN001
             compression: str) -> tuple[Callable[..., None], Callable[..., None]]:
    """The bare and the logged run of the logging benches (``n`` cycles each, ``cycles`` by
    default): the same bus, PC and engine, the logged one writing ``path``."""
    from hil.fieldbus.system import BusSystem
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc

    def bare(n: int = cycles) -> None:
        with BusSystem(topo, cfg, "inproc", model=model) as bs:
            bs.run(n, demo_pc(), keep=1)

    def logged(n: int = cycles) -> None:
        # a new file, as a user's run writes: rewriting the last run's file would have
        # ext4 truncate it (~10 ms per 130 MB) and flush it at close (its "replace by
        # truncate" heuristic, ~10 ms more), a cost of the bench's reuse of one path only
        path.unlink(missing_ok=True)
        run_logged(topo, cfg, n, demo_pc(), path, level=level, model=model,
                   compression=compression)

    return bare, logged


def measure(seconds: float = 2.0, topology: str = "hydra_full", level: str = "mcu",
            compression: str = "zstd", warm: bool = True, pairs: int = 1,
            model: str = "robot", cfg: object = None) -> Parts:
    """``pairs`` bare and logged runs of ``seconds`` each of ``topology`` with the
    whole-robot engine (the order alternating), the logged ones with their parts timed
    (see the module doc); the figures summed over the pairs. ``model`` "stack": the same
    without the engine (no compiled calls to compare)."""
    from hil.fieldbus.topology import load_topology
    from plant.config import load_config

    cfg = load_config(None, []) if cfg is None else cfg
    topo = load_topology(topology)
    cycles = max(int(round(seconds * 1000)), 1)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "parts.mcap"

        bare, logged = run_pair(topo, cfg, cycles, path, level, model, compression)
        if warm:  # compiled code loaded, imports done, a block written
            bare(WARM_CYCLES)
            logged(WARM_CYCLES)
        compute = _Compute()
        timer = _Timer()
        cpu = {"bare": 0.0, "logged": 0.0}
        held = {"bare": 0.0, "logged": 0.0}  # the compiled calls' CPU
        extras = []
        with settled():
            for i in range(pairs):
                one = {}
                for kind in ("logged", "bare") if i % 2 else ("bare", "logged"):
                    undo = compute.install()
                    if kind == "logged":
                        undo += _install(timer)
                    try:
                        compute.cpu = 0.0
                        one[kind] = run_cpu(logged if kind == "logged" else bare).cpu
                    finally:
                        for owner, name, fn in reversed(undo):
                            setattr(owner, name, fn)
                    cpu[kind] += one[kind]
                    held[kind] += compute.cpu
                extras.append(one["logged"] - one["bare"])
        size = path.stat().st_size
    per_call, inside = timer_cost()
    # each part less what its wrapper counted in it; the wrappers' whole cost apart
    own = Counter({k: v - inside * timer.calls[k] for k, v in timer.own.items()})
    return Parts(cycles / 1000 * pairs, cpu["bare"], cpu["logged"], held["bare"],
                 held["logged"], own, timer.calls, per_call * sum(timer.calls.values()),
                 size, extras)


def format_parts(p: Parts, detail: bool = True) -> str:
    """The split of :attr:`Parts.extra` (ms per simulated second); ``detail``: each
    wrapped function's own CPU too."""
    s = p.seconds
    sp = p.split()
    n = max(len(p.extras), 1)
    each = ", ".join(f"{e / s * n * 1e3:.0f}" for e in p.extras)
    lines = [f"bare {p.bare_cpu:.3f} s CPU, logged {p.logged_cpu:.3f} s CPU for {s / n:g} s "
             f"simulated each ({n} pair{'s' * (n > 1)}; a log of "
             f"{p.log_bytes / (s / n) / 1e6:.1f} MB per simulated second): the logging "
             f"costs {sp['total']:.1f} ms CPU per simulated second"
             + (f" (the pairs: {each})" if n > 1 else ""),
             "  made of (ms per simulated second):"]
    for side in SIDES:
        lines.append(f"    {sp[side]:6.1f}  {side} side")
        if detail:
            parts = sorted(((v, k) for k, v in p.own.items() if k.startswith(side)),
                           reverse=True)
            lines += [f"      {v / s * 1e3:6.1f}  {k.split(': ', 1)[1]}"
                      f" ({p.calls[k] / s:g} calls)" for v, k in parts]
    lines += [f"    {sp['in_kernel']:6.1f}  in the engine's compiled calls (logged "
              f"{p.logged_compute / s * 1e3:.1f}, bare {p.bare_compute / s * 1e3:.1f}: every "
              "compute thread)",
              f"    {sp['timers']:6.1f}  the timers of this breakdown (estimate: "
              f"{sum(p.calls.values()) / s:.0f} wrapped calls)",
              f"    {sp['rest']:6.1f}  rest: run_logged's glue, the bare run's work slowed "
              "beside the logging, noise"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    seconds = float(args[0]) if args else 2.0
    topology = args[1] if len(args) > 1 else "hydra_full"
    pairs = int(args[2]) if len(args) > 2 else 1
    print(format_parts(measure(seconds, topology, pairs=pairs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
