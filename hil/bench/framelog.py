"""Micro benchmark of the frame log: MCU-level traffic written and read back.

One simulated second at the MCU level per board: 5000 upstream LVDS snapshots (31 x u16)
and 5000 x 3 downstream register writes (3 bytes each); plus 1000 fieldbus frames of
1600 bytes. Logged either one frame per MCAP message ("single") or in blocks of
``block_frames`` frames ("block"; the fieldbus stays one message per frame in both, its
frames vary in length in real runs).

Run: ``python -m hil.bench.framelog [seconds_of_sim] [compression]``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.framelog.formats import (
    ENC_ETHERCAT,
    ENC_LVDS_DOWN,
    ENC_LVDS_UP,
    FIELDBUS_TOPIC,
    lvds_topic,
)
from hil.framelog.reader import FrameLogReader
from hil.framelog.writer import Compression, FrameLogWriter

MCU_TICK_NS = 200_000  # 5 kHz
FIELDBUS_PERIOD_NS = 1_000_000  # 1 kHz
UP_WORDS = 31
DOWN_WRITES_PER_TICK = 3
FIELDBUS_BYTES = 1600


@dataclass(frozen=True)
class BenchResult:
    """Throughput of one mode; rates in frames (records) per wall second."""

    mode: str
    seconds_of_sim: float
    frames: int
    messages: int
    file_bytes: int
    write_s: float
    read_blocks_s: float
    read_frames_s: float

    @property
    def write_rate(self) -> float:
        return self.frames / self.write_s

    @property
    def read_blocks_rate(self) -> float:
        return self.frames / self.read_blocks_s

    @property
    def read_frames_rate(self) -> float:
        return self.frames / self.read_frames_s

    def line(self) -> str:
        sim = self.seconds_of_sim
        return (f"{self.mode:6s} {self.frames:8d} frames in {self.messages:7d} messages, "
                f"{self.file_bytes / 1e6:6.2f} MB | write {self.write_rate / 1e3:7.0f} k/s "
                f"({sim / self.write_s:6.1f}x RT) | read blocks() "
                f"{self.read_blocks_rate / 1e3:7.0f} k/s ({sim / self.read_blocks_s:6.1f}x RT)"
                f" | read frames() {self.read_frames_rate / 1e3:6.0f} k/s "
                f"({sim / self.read_frames_s:5.1f}x RT)")


def _traffic(seconds: float, boards: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    n_tick = int(round(seconds * 1e9 / MCU_TICK_NS))
    n_bus = int(round(seconds * 1e9 / FIELDBUS_PERIOD_NS))
    t_tick = np.arange(n_tick, dtype=np.int64) * MCU_TICK_NS
    up = [rng.integers(0, 1 << 16, (n_tick, UP_WORDS), dtype=np.uint16) for _ in range(boards)]
    t_down = np.repeat(t_tick, DOWN_WRITES_PER_TICK)
    down = [rng.integers(0, 256, (n_tick * DOWN_WRITES_PER_TICK, 3), dtype=np.uint8)
            for _ in range(boards)]
    t_bus = np.arange(n_bus, dtype=np.int64) * FIELDBUS_PERIOD_NS
    bus = [rng.integers(0, 256, FIELDBUS_BYTES, dtype=np.uint8).tobytes() for _ in range(8)]
    return t_tick, up, t_down, down, t_bus, bus


def _write(path: Path, mode: str, traffic, block_frames: int, compression: Compression
           ) -> None:
    t_tick, up, t_down, down, t_bus, bus = traffic
    boards = len(up)
    with FrameLogWriter(path, level="mcu", compression=compression) as w:
        fb = w.add_channel(FIELDBUS_TOPIC, ENC_ETHERCAT, schema_name="")
        if mode == "block":
            cu = [w.add_block_channel(lvds_topic(b, "up"), ENC_LVDS_UP, dtype=np.uint16,
                                      width=UP_WORDS) for b in range(boards)]
            cd = [w.add_block_channel(lvds_topic(b, "down"), ENC_LVDS_DOWN, dtype=np.uint8,
                                      width=3) for b in range(boards)]
            n = t_tick.shape[0]
            bus_i = 0
            # Interleave as a simulation would: a block per board per block_frames ticks,
            # the fieldbus frames of that span in between.
            for s in range(0, n, block_frames):
                e = min(n, s + block_frames)
                t_end = t_tick[e - 1]
                while bus_i < t_bus.shape[0] and t_bus[bus_i] <= t_end:
                    w.write(fb, int(t_bus[bus_i]), bus[bus_i % len(bus)])
                    bus_i += 1
                ds, de = s * DOWN_WRITES_PER_TICK, e * DOWN_WRITES_PER_TICK
                for b in range(boards):
                    w.write_block(cu[b], t_tick[s:e], up[b][s:e])
                    w.write_block(cd[b], t_down[ds:de], down[b][ds:de])
        else:
            cu = [w.add_channel(lvds_topic(b, "up"), ENC_LVDS_UP, schema_name="")
                  for b in range(boards)]
            cd = [w.add_channel(lvds_topic(b, "down"), ENC_LVDS_DOWN, schema_name="")
                  for b in range(boards)]
            up_b = [[row.tobytes() for row in u] for u in up]
            down_b = [[row.tobytes() for row in d] for d in down]
            tt = t_tick.tolist()
            per = FIELDBUS_PERIOD_NS // MCU_TICK_NS
            for i, t in enumerate(tt):
                if i % per == 0:
                    w.write(fb, t, bus[(i // per) % len(bus)])
                for b in range(boards):
                    w.write(cu[b], t, up_b[b][i])
                    for k in range(DOWN_WRITES_PER_TICK):
                        w.write(cd[b], t, down_b[b][i * DOWN_WRITES_PER_TICK + k])


def bench_write_read(seconds_of_sim: float = 1.0, boards: int = 2, block_frames: int = 100,
                     compression: Compression = "zstd") -> list[BenchResult]:
    """Write and read ``seconds_of_sim`` of MCU-level traffic in both modes; wall times."""
    traffic = _traffic(seconds_of_sim, boards)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("single", "block"):
            path = Path(tmp) / f"{mode}.mcap"
            t0 = time.perf_counter()
            _write(path, mode, traffic, block_frames, compression)
            t1 = time.perf_counter()
            reader = FrameLogReader(path)
            info = reader.info()
            t2 = time.perf_counter()
            # What a replay does: every LVDS channel as arrays, the fieldbus frame by frame.
            reader.blocks_many(c.topic for c in info.channels if c.topic != FIELDBUS_TOPIC)
            fb = sum(1 for _ in reader.frames([FIELDBUS_TOPIC], order="file"))
            t3 = time.perf_counter()
            n = sum(1 for _ in reader.frames(order="time"))
            t4 = time.perf_counter()
            assert n == info.frame_count and fb == traffic[4].shape[0]
            out.append(BenchResult(mode, seconds_of_sim, info.frame_count,
                                   info.message_count, path.stat().st_size, t1 - t0,
                                   t3 - t2, t4 - t3))
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    seconds = float(argv[0]) if argv else 1.0
    compression: Compression = argv[1] if len(argv) > 1 else "zstd"  # type: ignore[assignment]
    print(f"frame log, MCU level, 2 boards, {seconds:g} s simulated, {compression}:")
    for r in bench_write_read(seconds, compression=compression):
        print(r.line())
    return 0


if __name__ == "__main__":
    sys.exit(main())
