"""Where the CPU of a logged whole-robot run goes: the logging's parts, per simulated second.

``eha-hil bench log`` gives the whole cost (logged / bare CPU); this splits the logged run's
extra CPU into the functions that make it. Each function below is wrapped for one run:
its *own* CPU (``time.thread_time`` of the thread that runs it, less the wrapped functions
it calls) is summed, so the parts add up without double counting; zstd is timed inside the
chunk closing (``hil.framelog.chunk``). The file side (``hil/framelog``: building records,
compressing and writing chunks) and the producer side (``hil/replay``: copies of the
engine's images, decoding the signals) are listed apart.

Run: ``python -m hil.bench.log_parts [seconds] [topology]`` (default 2 s of ``hydra_full``
at level ``mcu``, zstd), after a warm-up run of 50 cycles. The figures grow with the
machine's load (memory bandwidth is shared): quote them with ``uptime``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

#: (module, attribute path, side) of every wrapped function.
PARTS: tuple[tuple[str, str, str], ...] = (
    ("hil.framelog.chunk", "_finalize", "file"),
    ("hil.framelog.batch", "records", "file"),
    ("hil.framelog.batch", "add_records", "file"),
    ("hil.framelog.batch", "add_messages", "file"),
    ("hil.framelog.rawpb", "pack_blocks", "file"),
    ("hil.framelog.rawpb", "wrap_many", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_blocks", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_block", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages_many", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages_filled", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write_messages", "file"),
    ("hil.framelog.writer", "FrameLogWriter.write", "file"),
    ("hil.framelog.protobuf", "MessageType.encode_array", "producer"),
    ("hil.replay.signals", "actuator_block", "producer"),
    ("hil.replay.signals", "record_columns", "producer"),
    ("hil.replay.signals", "pc_command_block", "producer"),
    ("hil.replay.signals", "report_flags", "producer"),
    ("hil.replay.robot_record", "RobotRecorder.took_outputs", "producer"),
    ("hil.replay.robot_record", "RobotRecorder.finished", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write_records", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write_steps", "producer"),
    ("hil.replay.robot_record", "RobotRecorder._write", "producer"),
    ("hil.replay.signal_kernel", "ActuatorEncoder.encode", "producer"),
    ("hil.replay.signal_out", "SignalOut.write_split", "producer"),
    ("hil.replay.signal_out", "SignalOut.write_filled", "producer"),
    ("hil.replay.record", "BusSignals.end_cycle", "producer"),
    ("hil.replay.record", "BusSignals.flush", "producer"),
)


class _Timer:
    """Own thread CPU per label of the functions wrapped with :meth:`wrap`."""

    def __init__(self) -> None:
        self.own: Counter[str] = Counter()
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
                if self._inner:
                    self._inner[-1] += dt
        return timed


def _install(timer: _Timer) -> list[tuple[object, str, object]]:
    """Wrap every function of :data:`PARTS` and zstd; the originals, to put back."""
    import importlib

    from hil.framelog import chunk

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
    return undo


def measure(seconds: float = 2.0, topology: str = "hydra_full", level: str = "mcu",
            ) -> tuple[float, Counter[str], int]:
    """(process CPU of the logged run, own CPU per part, log bytes) of ``seconds`` of
    ``topology`` with the whole-robot engine."""
    from hil.fieldbus.topology import load_topology
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc
    from plant.config import load_config

    cfg = load_config(None, [])
    topo = load_topology(topology)
    timer = _Timer()
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "parts.mcap"
        run_logged(topo, cfg, 50, demo_pc(), path, level=level, model="robot")  # warm-up
        undo = _install(timer)
        try:
            c0 = time.process_time()
            run_logged(topo, cfg, max(int(round(seconds * 1000)), 1), demo_pc(), path,
                       level=level, model="robot")
            cpu = time.process_time() - c0
        finally:
            for owner, name, fn in reversed(undo):
                setattr(owner, name, fn)
        size = path.stat().st_size
    return cpu, timer.own, size


def format_parts(seconds: float, cpu: float, own: Counter[str], size: int) -> str:
    lines = [f"logged run: {cpu:.3f} s CPU for {seconds:g} s simulated, "
             f"{size / seconds / 1e6:.1f} MB of log per simulated second",
             "own CPU per simulated second (ms):"]
    for side in ("file", "producer"):
        parts = sorted(((v, k) for k, v in own.items() if k.startswith(side)), reverse=True)
        total = sum(v for v, _ in parts)
        lines.append(f"  {side} side: {total / seconds * 1e3:.1f}")
        lines += [f"    {v / seconds * 1e3:6.1f}  {k.split(': ', 1)[1]}" for v, k in parts]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    seconds = float(args[0]) if args else 2.0
    topology = args[1] if len(args) > 1 else "hydra_full"
    cpu, own, size = measure(seconds, topology)
    print(format_parts(seconds, cpu, own, size))
    return 0


if __name__ == "__main__":
    sys.exit(main())
