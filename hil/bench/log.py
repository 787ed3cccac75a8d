"""What logging costs a ``bus run``, and what the decoded-signal encoding costs.

``eha-hil bench log``:

* **Overhead**: the same run (topology, cycles, force sine) without a log and with
  ``--log`` at a level, in pairs (the order alternating), in this process after a warm-up
  of both (numba's compiled code loaded, a block of the log written). Per pair the ratio
  logged / bare of CPU time (``time.process_time``: what this process used, every thread
  of it, the figure that holds on a shared machine) and of wall time; the median of the
  pairs is reported with the least and most, each pair's in the order run, and the
  ratio of the fastest runs' CPU times (other processes can only make a run slower, so
  the minima are the least disturbed). Each run pays for collecting its own garbage and
  for no other run's (:func:`hil.bench.log_parts.settled`: a logged run leaves ~10 MB in
  reference cycles, whose full collection used to fall in a later run, often a bare
  one); beside the times, each kind's minor page faults per run (memory the run touched
  fresh). The target: at most 1.20 at the default level (1.25 for the
  whole-robot engine). Beside the ratios: what the logging costs in CPU per simulated
  second (logged minus bare, per pair), with the median, least and most over the pairs,
  and what it may cost for the target at this bare run; and (``parts``) one more,
  instrumented pair split into the file side, the producer side, the engine's compiled
  calls, the timers and the rest (:mod:`hil.bench.log_parts`).
* **Encoding**: one actuator's decoded signals (:data:`hil.replay.signals.ACTUATOR`,
  ``n`` samples of random values, so compression is a worst case) encoded as protobuf
  (our block encoder) and as JSON (one ``json.dumps`` per sample, as a JSON channel
  needs), each written to an MCAP file (zstd): bytes per message, file size, CPU time per
  message for encoding and for encoding + writing.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.framelog.writer import FrameLogWriter
from hil.replay.signals import ACTUATOR

#: The targets of logged / bare CPU: (stack model, robot engine).
TARGET = (1.20, 1.25)


@dataclass(frozen=True)
class Overhead:
    level: str
    topology: str
    seconds: float
    pairs: int
    cpu_ratio: float        # median over pairs of logged / bare CPU time
    wall_ratio: float
    cpu_ratio_min: float    # fastest logged / fastest bare: what contention inflates least
    bare_cpu_s: float       # medians of the single runs
    bare_wall_s: float
    logged_cpu_s: float
    logged_wall_s: float
    log_bytes: int
    cpu_ratios: tuple[float, ...] = ()      # each pair's, in the order run
    wall_ratios: tuple[float, ...] = ()
    #: each pair's logged minus bare CPU, ms per simulated second
    extra_ms: tuple[float, ...] = ()
    #: ms per simulated second of one more pair, instrumented: file, producer, in_kernel,
    #: timers, rest, total (:meth:`hil.bench.log_parts.Parts.split`); None: not measured
    parts: dict[str, float] | None = None
    #: medians of the minor page faults per run, bare and logged
    bare_faults: int = 0
    logged_faults: int = 0

    @property
    def target(self) -> float:
        return TARGET[self.topology.endswith("robot model")]

    @property
    def extra_budget_ms(self) -> float:
        """The logging's CPU per simulated second that the target allows at this bare run."""
        return (self.target - 1.0) * self.bare_cpu_s / self.seconds * 1e3


@dataclass(frozen=True)
class EncodingCost:
    encoding: str
    messages: int
    message_bytes: float    # mean
    file_bytes: int
    encode_us: float        # CPU per message
    encode_write_us: float  # CPU per message, encoding and writing to MCAP


def _timed(fn) -> tuple[float, float]:  # noqa: ANN001
    c0, w0 = time.process_time(), time.perf_counter()
    fn()
    return time.process_time() - c0, time.perf_counter() - w0


def bench_overhead(cfg, seconds: float = 1.0, level: str = "mcu", pairs: int = 3,  # noqa: ANN001
                   topology: str | None = None, model: str = "stack",
                   compression: str = "zstd", parts: bool = False) -> Overhead:
    """Paired bare and logged runs of ``seconds`` simulated seconds with the box model
    ``model`` (stack or robot; see the module doc). ``topology`` None: ``bench_one_box``
    for the stack model, ``hydra_full`` for the robot engine. ``parts``: then one more
    pair, instrumented, split into the logging's parts (not in the ratios)."""
    if topology is None:
        topology = "hydra_full" if model == "robot" else "bench_one_box"
    from hil.bench.log_parts import WARM_CYCLES, Run, run_cpu, run_pair, settled
    from hil.fieldbus.topology import load_topology

    topo = load_topology(topology)
    cycles = max(int(round(seconds * 1000)), 1)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bench.mcap"

        bare, logged = run_pair(topo, cfg, cycles, path, level, model, compression)
        bare(WARM_CYCLES)
        logged(WARM_CYCLES)  # warm-up: compiled code loaded, imports done, a block written
        runs: list[tuple[Run, Run]] = []
        with settled():
            for i in range(pairs):
                if i % 2:
                    lg = run_cpu(logged)
                    b = run_cpu(bare)
                else:
                    b = run_cpu(bare)
                    lg = run_cpu(logged)
                runs.append((b, lg))
        size = path.stat().st_size
    split = None
    if parts:
        from hil.bench.log_parts import measure

        split = measure(cycles / 1000, topology, level, compression, warm=False,
                        model=model, cfg=cfg).split()
    med = statistics.median
    sim = cycles / 1000
    return Overhead(level, f"{topology}, {compression}, {model} model", sim, pairs,
                    med(lg.cpu / b.cpu for b, lg in runs), med(lg.wall / b.wall for b, lg in runs),
                    min(lg.cpu for _, lg in runs) / min(b.cpu for b, _ in runs),
                    med(b.cpu for b, _ in runs), med(b.wall for b, _ in runs),
                    med(lg.cpu for _, lg in runs), med(lg.wall for _, lg in runs), size,
                    tuple(lg.cpu / b.cpu for b, lg in runs),
                    tuple(lg.wall / b.wall for b, lg in runs),
                    tuple((lg.cpu - b.cpu) / sim * 1e3 for b, lg in runs), split,
                    int(med(b.faults for b, _ in runs)), int(med(lg.faults for _, lg in runs)))


def _columns(n: int, seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols = {}
    for f in ACTUATOR.fields:
        if f.kind in ("double", "float"):
            cols[f.name] = rng.normal(0.0, 1e5 if f.unit == "Pa" else 10.0, n)
        elif f.kind == "bool":
            cols[f.name] = rng.integers(0, 2, n)
        else:
            cols[f.name] = rng.integers(0, 8, n)
    return cols


def bench_encodings(n: int = 5000) -> list[EncodingCost]:
    """Protobuf against JSON for ``n`` samples of :data:`ACTUATOR`."""
    cols = _columns(n)
    t = np.arange(n, dtype=np.int64) * 200_000
    out = []
    with tempfile.TemporaryDirectory() as d:
        for enc in ("protobuf", "json"):
            path = Path(d) / f"{enc}.mcap"
            encode = ACTUATOR.encode if enc == "protobuf" else ACTUATOR.encode_json
            c_enc, _ = _timed(lambda encode=encode: encode(cols, n))
            msgs = encode(cols, n)

            def write(enc: str = enc, path: Path = path, encode=encode) -> None:  # noqa: ANN001
                with FrameLogWriter(path, level="bus") as w:
                    if enc == "protobuf":
                        ch = w.add_protobuf_channel("/a", ACTUATOR)
                    else:
                        ch = w.add_channel("/a", "json", schema_name=ACTUATOR.full_name,
                                           schema_encoding="jsonschema",
                                           schema_data=ACTUATOR.json_schema)
                    w.write_messages(ch, t, encode(cols, n))

            c_all, _ = _timed(write)
            out.append(EncodingCost(enc, n, sum(map(len, msgs)) / n, path.stat().st_size,
                                    c_enc / n * 1e6, c_all / n * 1e6))
    return out


def _spread(values: tuple[float, ...], fmt: str) -> str:
    """``(least, most)`` of ``values`` (their median is printed before it), or ""."""
    if len(values) < 2:
        return ""
    return f" ({min(values):{fmt}}-{max(values):{fmt}})"


def format_report(ov: Overhead | None, enc: list[EncodingCost]) -> str:
    lines = []
    if ov is not None:
        lines += [
            f"bus run --log at level {ov.level} ({ov.topology}, {ov.seconds:g} s simulated, "
            f"{ov.pairs} pairs; medians, (least-most) over the pairs):",
            f"  bare:   CPU {ov.bare_cpu_s:.3f} s, wall {ov.bare_wall_s:.3f} s",
            f"  logged: CPU {ov.logged_cpu_s:.3f} s, wall {ov.logged_wall_s:.3f} s, "
            f"log {ov.log_bytes / 1e3:.0f} kB ({ov.log_bytes / ov.seconds / 1e6:.1f} MB per "
            "simulated second)",
            f"  logged / bare: CPU {ov.cpu_ratio:.3f}{_spread(ov.cpu_ratios, '.3f')}, wall "
            f"{ov.wall_ratio:.3f}{_spread(ov.wall_ratios, '.3f')} (target <= "
            f"{ov.target:.2f}); fastest logged / fastest bare, CPU {ov.cpu_ratio_min:.3f}",
        ]
        if len(ov.cpu_ratios) > 1:
            # in the order run: the bare run first in the 1st, 3rd, ... pair
            each = ", ".join(f"{r:.3f}{'' if i % 2 else '*'}"
                             for i, r in enumerate(ov.cpu_ratios))
            lines.append(f"  each pair's CPU ratio, in order (*: bare run first): {each}; "
                         f"minor page faults per run: bare {ov.bare_faults}, logged "
                         f"{ov.logged_faults}")
        if ov.extra_ms:
            lines.append(
                f"  the logging: {statistics.median(ov.extra_ms):.0f} ms CPU per simulated "
                f"second{_spread(ov.extra_ms, '.0f')}; the target allows "
                f"{ov.extra_budget_ms:.0f} at this bare run")
        if ov.parts is not None:
            p = ov.parts
            kernel = (f"engine's compiled calls {p['in_kernel']:.0f}, "
                      if ov.topology.endswith("robot model") else "")  # (no engine: none)
            lines.append(
                f"  its parts (one more pair, instrumented; ms CPU per simulated second): "
                f"file side {p['file']:.0f}, producer {p['producer']:.0f}, {kernel}timers "
                f"{p['timers']:.0f}, rest {p['rest']:.0f} (sum {p['total']:.0f}; python -m "
                "hil.bench.log_parts for each function)")
    if not enc:
        return "\n".join(lines)
    lines.append(f"decoded signals of one actuator ({enc[0].messages} samples, "
                 f"{len(ACTUATOR.fields)} fields, random values), CPU per message:")
    for e in enc:
        lines.append(f"  {e.encoding:8s}: {e.message_bytes:6.1f} B/message, MCAP (zstd) "
                     f"{e.file_bytes / 1e3:7.1f} kB, encode {e.encode_us:6.2f} us, "
                     f"encode + write {e.encode_write_us:6.2f} us")
    return "\n".join(lines)
