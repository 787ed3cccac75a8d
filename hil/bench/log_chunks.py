"""What each codec and level makes of a whole-robot log's chunks: size and compression CPU.

``python -m hil.bench.log_chunks [seconds] [topology]`` logs ``seconds`` (default 1) of
``topology`` (default ``hydra_full``) at level ``mcu`` with the whole-robot engine, keeps
every chunk as the writer closes it (uncompressed), then compresses each chunk with each
codec and level the writer offers and reports the log's MB and the compression's CPU per
simulated second (``time.process_time``, best of 3 per chunk, so a loaded machine reads
high rather than noisy; quote ``uptime``). lz4 chunks also carry a CRC-32 of their
uncompressed bytes (zstd's own checksum is in its time), listed apart. Then the decoded
signals' and register words' chunks of each kind the writer gives them
(:data:`hil.framelog.writer.CHUNK_KINDS`: the register words' ``/lvds/``, the actuators'
``/signals/actuator/``, the rest of ``/signals/``) alone, at the levels of
:data:`SIGNAL_CODECS` (best of 5 per chunk).
"""

from __future__ import annotations

import sys
import tempfile
import time
import zlib
from collections.abc import Callable
from pathlib import Path

#: (label, compression, level) of each row.
CODECS = (("zstd 3 (the mcap library's)", "zstd", 3), ("zstd 1", "zstd", 1),
          ("zstd -1 (default)", "zstd", -1), ("zstd -3", "zstd", -3),
          ("zstd -5", "zstd", -5), ("lz4 (its default)", "lz4", None))
#: (label, compression, level) of each row of the decoded signals' chunks (the writer's
#: levels with their tuned match finder, :data:`hil.framelog.chunk.TUNED`).
SIGNAL_CODECS = (("zstd -60, table 2^8 (the writer's, actuators)", "zstd", -60),
                 ("zstd -30, table 2^10 (the writer's, register words)", "zstd", -30),
                 ("zstd -19, table 2^8 (the actuators' before)", "zstd", -19),
                 ("zstd -9, table 2^11 (the writer's, the rest)", "zstd", -9),
                 ("zstd -7, table 2^12", "zstd", -7),
                 ("zstd -1, table 2^12", "zstd", -1))


def capture(seconds: float, topology: str) -> list[bytes]:
    """The uncompressed chunks of a logged run of ``seconds`` of ``topology``."""
    return [c for _, c in capture_kinds(seconds, topology)]


def capture_kinds(seconds: float, topology: str) -> list[tuple[str | None, bytes]]:
    """:func:`capture`, each chunk with the topic prefix of the decoded signals' kind of
    chunk it is (:data:`hil.framelog.writer.CHUNK_KINDS`; None: the other raw channels')."""
    from hil.fieldbus.topology import load_topology
    from hil.framelog import chunk
    from hil.framelog.writer import CHUNK_KINDS
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc
    from plant.config import load_config

    cfg = load_config(None, [])
    topo = load_topology(topology)
    chunks: list[tuple[str | None, bytes]] = []
    make = chunk.compressor
    signals: dict[tuple, str] = {}  # kind -> its topic prefixes
    for prefix, k in CHUNK_KINDS.items():
        signals[k] = f"{signals[k]} + {prefix}" if k in signals else prefix

    def keeping(compression: str, level: int | None) -> Callable[[memoryview], bytes]:
        inner = make(compression, level)
        kind = signals.get((compression, level))

        def compress(view: memoryview) -> bytes:
            chunks.append((kind, bytes(view)))
            return inner(view)
        return compress

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "chunks.mcap"
        run_logged(topo, cfg, 20, demo_pc(), path, level="mcu", model="robot")  # warm-up
        chunk.compressor = keeping
        try:
            run_logged(topo, cfg, max(int(round(seconds * 1000)), 1), demo_pc(), path,
                       level="mcu", model="robot")
        finally:
            chunk.compressor = make
    return chunks


def _cpu(fn: Callable[[bytes], object], data: bytes, tries: int = 3) -> float:
    best = float("inf")
    for _ in range(tries):
        t0 = time.process_time()
        fn(data)
        best = min(best, time.process_time() - t0)
    return best


def measure(chunks: list[bytes], codecs: tuple[tuple[str, str, int | None], ...] = CODECS,
            tries: int = 3) -> list[tuple[str, float, float, float]]:
    """(label, compressed bytes, compression CPU s, CRC-32 CPU s) per codec of
    ``codecs``, summed over ``chunks`` (CPU: the best of ``tries`` per chunk)."""
    from hil.framelog.chunk import compressor

    rows = []
    crc = sum(_cpu(zlib.crc32, c, tries) for c in chunks)
    for label, codec, level in codecs:
        fn = compressor(codec, level)
        size = sum(len(fn(c)) for c in chunks)
        rows.append((label, size, sum(_cpu(fn, c, tries) for c in chunks),
                     crc if codec == "lz4" else 0.0))
    return rows


def _table(rows: list[tuple[str, float, float, float]], seconds: float) -> None:
    print("codec, level | MB per simulated s | compression ms per simulated s (+ CRC-32)")
    for label, size, cpu, crc in rows:
        extra = f" (+ {crc / seconds * 1e3:.1f})" if crc else ""
        print(f"{label} | {size / seconds / 1e6:.2f} | {cpu / seconds * 1e3:.1f}{extra}")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    seconds = float(args[0]) if args else 1.0
    topology = args[1] if len(args) > 1 else "hydra_full"
    kinds = capture_kinds(seconds, topology)
    chunks = [c for _, c in kinds]
    raw = sum(map(len, chunks))
    print(f"{len(chunks)} chunks, {raw / seconds / 1e6:.1f} MB per simulated second "
          "uncompressed")
    _table(measure(chunks), seconds)
    for prefix in dict.fromkeys(k for k, _ in kinds if k is not None):
        signals = [c for k, c in kinds if k == prefix]
        print(f"\nthe chunks of {prefix} (the writer's kind for it), "
              f"{len(signals)}, alone: {sum(map(len, signals)) / seconds / 1e6:.1f} MB per "
              "simulated second uncompressed (best of 5)")
        _table(measure(signals, SIGNAL_CODECS, 5), seconds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
