"""Logging a fieldbus run at the MCU boundary (MCAP, :mod:`hil.framelog`).

Channels per box ``b`` (blocks of fixed-width frames, times in ns of simulated time):

* ``/mcu/b/outputs``  uint8 x out_bytes: the box's fieldbus output record, each cycle;
* ``/mcu/b/inputs``   uint8 x in_bytes: the input record the box gave back, each cycle;
* ``/lvds/b.k/up``    uint32 x 33: board k's upstream memory (the link's 32 words) + the MCU side's
  upstream CRC-error count, before each MCU step;
* ``/lvds/b.k/down``  uint16 x 13: board k's downstream registers after each MCU step;
* ``/fieldbus/frames`` (level "bus" and up): every frame as sent/received, single messages;
* ``/fpga/b.k/trace`` (level "full"): int64 x TRACE_WIDTH per tick: board k's raw sensor
  words and received downstream memory (its inputs) and its upstream memory, PWM on and
  compare counts (its outputs), for the FPGA replay (:mod:`hil.replay.fpga_replay`);
* ``/lvds/b.k/down_words``, ``/lvds/b.k/up_words`` (level "full"): every LVDS word that
  reached the receiver, as its 45-bit line word (``eha-hil/lvds-word``, uint64), stamped
  with the tick in which its last bit arrived; a word that failed its CRC is logged with
  the bit error it carried, a dropped word (no start bit) is not on the receiver's wire;
* ``/sensors/b.k/raw`` (level "full"): the sensor frames of every tick as the board's
  masters decoded them (``eha-hil/sensor-raw``: the raw words of
  ``firmware_model.fpga.layout.RAW_NAMES``, uint32; a log of an older layout has fewer).

The Metadata record holds the configuration (JSON), the topology, the box model and each
board's calibrated angle offset, so a replay needs nothing but the file.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.lvds import link as LK
from hil.actuator import TRACE_WIDTH, TRACE_WORDS
from hil.fieldbus.boxes import StackBox
from hil.fieldbus.chain import CYCLE_TICKS
from hil.fieldbus.master import Master
from hil.fieldbus.system import BusRecord, BusSystem
from hil.fieldbus.topology import Topology
from hil.framelog import FrameLogWriter
from plant.config import Config

UP_WIDTH = B.UP_WORDS + 1
ENC_MCU_UP = "eha-hil/mcu-up"        # the link's upstream words + CRC-error count, uint32
ENC_MCU_DOWN = "eha-hil/lvds-down-registers"  # 13 downstream registers, uint16
ENC_RECORD = "eha-hil/process-record"  # a box's fieldbus record, bytes
FLUSH_CYCLES = 100  # one block per channel per 100 ms of simulated time


def topics(box: int, board: int | None = None) -> dict[str, str]:
    """Topic names of box ``box`` (and of its board ``board``)."""
    t = {"outputs": f"/mcu/{box}/outputs", "inputs": f"/mcu/{box}/inputs"}
    if board is not None:
        t["up"] = f"/lvds/{box}.{board}/up"
        t["down"] = f"/lvds/{box}.{board}/down"
        t["trace"] = f"/fpga/{box}.{board}/trace"
    return t


class RecordingStackBox(StackBox):
    """A :class:`StackBox` that logs the MCU's inputs and outputs."""

    def __init__(self, box, cfg: Config, log: FrameLogWriter) -> None:  # noqa: ANN001
        super().__init__(box, cfg)
        self.log = log
        self.tick_ns = cfg.get("sim.tick_ns")
        b = box.id
        tp = topics(b)
        self.ch_out = log.add_block_channel(tp["outputs"], ENC_RECORD, dtype=np.uint8,
                                            width=max(self.out_dtype.itemsize, 1))
        self.ch_in = log.add_block_channel(tp["inputs"], ENC_RECORD, dtype=np.uint8,
                                           width=self.in_dtype.itemsize)
        self.ch_up, self.ch_down = [], []
        for k in range(len(self.stacks)):
            tk = topics(b, k)
            self.ch_up.append(log.add_block_channel(tk["up"], ENC_MCU_UP, dtype=np.uint32,
                                                    width=UP_WIDTH))
            self.ch_down.append(log.add_block_channel(tk["down"], ENC_MCU_DOWN,
                                                      dtype=np.uint16, width=B.DOWN_WORDS))
        self.traced = log.level == "full"
        self.ch_trace = [log.add_block_channel(topics(b, k)["trace"], "eha-hil/fpga-trace",
                                               dtype=np.int64, width=TRACE_WIDTH)
                         for k in range(len(self.stacks))] if self.traced else []
        self.ch_words = [tuple(log.add_block_channel(f"/lvds/{b}.{k}/{d}_words",
                                                     "eha-hil/lvds-word", dtype=np.uint64,
                                                     width=1) for d in ("down", "up"))
                         for k in range(len(self.stacks))] if self.traced else []
        self.ch_raw = [log.add_block_channel(f"/sensors/{b}.{k}/raw", "eha-hil/sensor-raw",
                                             dtype=np.uint32, width=B.N_RAW)
                       for k in range(len(self.stacks))] if self.traced else []
        self._reset_buffers()

    def _reset_buffers(self) -> None:
        self.buf_trace: list[list[tuple[int, np.ndarray]]] = [[] for _ in self.stacks]
        self.buf_out: list[tuple[int, bytes]] = []
        self.buf_in: list[tuple[int, bytes]] = []
        self.buf_up: list[list[tuple[int, np.ndarray]]] = [[] for _ in self.stacks]
        self.buf_down: list[list[tuple[int, np.ndarray]]] = [[] for _ in self.stacks]

    def apply(self, data: bytes) -> None:
        self.buf_out.append((self.tick, bytes(data)))
        super().apply(data)

    def _mcu_step(self, tick: int) -> None:
        for k, s in enumerate(self.stacks):
            up = np.empty(UP_WIDTH, dtype=np.uint32)
            up[:-1] = s.mcu_link.up
            up[-1] = s.mcu_link.up_crc_errors
            self.buf_up[k].append((tick, up))
        super()._mcu_step(tick)
        for k, s in enumerate(self.stacks):
            self.buf_down[k].append((tick, s.mcu_link.down.astype(np.uint16)))

    def _advance_stacks(self, n_ticks: int) -> None:
        if not self.traced:
            super()._advance_stacks(n_ticks)
            return
        for k, s in enumerate(self.stacks):
            tr = np.zeros((n_ticks, TRACE_WIDTH), dtype=np.int64)
            s.advance(n_ticks, trace=tr)
            self.buf_trace[k].append((self._group.tick, tr))

    def advance(self, ticks: int) -> None:
        super().advance(ticks)
        self.buf_in.append((self.tick, self.inputs()))
        if len(self.buf_in) >= FLUSH_CYCLES:
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames as one block per channel."""
        ns = self.tick_ns

        def put(ch: int, rows: list, as_bytes: bool) -> None:
            if not rows:
                return
            t = np.array([r[0] for r in rows], dtype=np.int64) * ns
            if as_bytes:
                f = np.frombuffer(b"".join(r[1] for r in rows), dtype=np.uint8).reshape(
                    len(rows), -1)
            else:
                f = np.stack([r[1] for r in rows])
            self.log.write_block(ch, t, f)

        if self.out_dtype.itemsize:
            put(self.ch_out, self.buf_out, True)
        put(self.ch_in, self.buf_in, True)
        for k in range(len(self.stacks)):
            put(self.ch_up[k], self.buf_up[k], False)
            put(self.ch_down[k], self.buf_down[k], False)
            if self.traced and self.buf_trace[k]:
                t = np.concatenate([t0 + np.arange(len(rows), dtype=np.int64)
                                    for t0, rows in self.buf_trace[k]]) * ns
                tr = np.concatenate([r[1] for r in self.buf_trace[k]])
                self.log.write_block(self.ch_trace[k], t, tr)
                self.log.write_block(self.ch_raw[k], t, tr[:, :B.N_RAW])
                for d, ch in enumerate(self.ch_words[k]):
                    tw, words = LK.line_words(tr[:, TRACE_WORDS + d * LK.WORDS_W:], t)
                    if len(tw):
                        self.log.write_block(ch, tw, words[:, None])
        self._reset_buffers()


def run_logged(topo: Topology, cfg: Config, cycles: int, pc: Callable[[int, Master], None],
               log_path: str | Path, level: str = "mcu",
               progress: Callable[[int, int], None] | None = None,
               faults: object = None,
               capture: Callable[[int, int, bytes, str], None] | None = None) -> BusRecord:
    """Run ``cycles`` cycles in-process with the stack model and log them to ``log_path``.

    ``faults``: a fault declaration (:func:`hil.fieldbus.faults.parse_faults`); the log holds
    what the master sent and received and what each MCU took in and gave out, faults and
    all, so the replay reproduces a faulty run too. ``capture``: a further tap that sees
    every fieldbus frame (e.g. :meth:`hil.fieldbus.capture.CaptureWriter.tap`)."""
    with FrameLogWriter(log_path, level=level, flush_every_ns=FLUSH_CYCLES * CYCLE_TICKS
                        * cfg.get("sim.tick_ns")) as log:
        ch_bus = None
        if level in ("bus", "mcu", "full"):
            ch_bus = log.add_channel("/fieldbus/frames", "eha-hil/ethercat-fcs",
                                     schema_name="eha-hil/ethercat-fcs")
        tick_ns = cfg.get("sim.tick_ns")

        def tap(cycle: int, tick: int, frame: bytes, direction: str) -> None:
            if ch_bus is not None:
                log.write(ch_bus, tick * tick_ns + (1 if direction == "rx" else 0), frame)
            if capture is not None:
                capture(cycle, tick, frame, direction)

        use_tap = ch_bus is not None or capture is not None
        with BusSystem(topo, cfg, "inproc", model="stack", tap=tap if use_tap else None) as bs:
            boxes = [RecordingStackBox(b, cfg, log) for b in topo.boxes]
            bs.chain.boxes = boxes
            if faults is not None:
                bs._install_faults(faults)  # after the recording boxes replaced the plain ones
            offsets = {f"{b.box.id}.{k}": int(s.board.calibrated_offset)
                       for b in boxes for k, s in enumerate(b.stacks)}
            log.add_metadata("eha-hil.replay", {
                "config": json.dumps(cfg.data), "topology": topo.source,
                "model": "stack", "offsets": json.dumps(offsets),
                "cycles": str(cycles)})
            step = max(cycles // 20, 1)
            rec = None
            done = 0
            while done < cycles:
                n = min(step, cycles - done)
                part = bs.run(n, pc)
                rec = part if rec is None else BusRecord(
                    np.concatenate([rec.inputs, part.inputs]), part.master, part.chain,
                    part.transport)
                done += n
                if progress:
                    progress(done, cycles)
            for b in boxes:
                b.flush()
        return rec
