"""Logging a fieldbus run at the MCU boundary (MCAP, :mod:`hil.framelog`).

Channels per box ``b`` (blocks of fixed-width frames, times in ns of simulated time):

* ``/mcu/b/outputs``  uint8 x out_bytes: the box's fieldbus output record, each cycle;
* ``/mcu/b/inputs``   uint8 x in_bytes: the input record the box gave back, each cycle;
* ``/lvds/b.k/up``    uint16 x 34: board k's upstream memory (the link's 32 words) + the MCU side's
  upstream CRC-error count (a u32 in the last two), before each MCU step (logs before
  that: uint32 x 33; :func:`hil.framelog.formats.split_mcu_up` reads either);
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

The whole-robot engine (``--model robot``) writes the same channels, frame for frame, through
:class:`hil.replay.robot_record.RobotRecorder`; :func:`attach_recorders` picks the recorder
for a chain (``bus run``, ``serve``). A box without an output record has no outputs
channels; decoded signals leave out what is not measured and flag torn piston reads
(:mod:`hil.replay.signals`, docs/framelog.md).

Beside these raw channels, the decoded signals of :mod:`hil.replay.signals` (protobuf, SI
units, one message per sample) go to the log and/or a live view (:class:`SignalOut`):
``/signals/actuator/b.k`` each fieldbus cycle (each MCU step at level "full"),
``/signals/box/b/outputs`` and ``/signals/box/b/inputs`` and ``/signals/bus`` each cycle.
Every raw channel has a schema of encoding ``eha-hil/layout`` (JSON, :mod:`hil.framelog.layout`)
that names its fields and their byte offsets.
"""

from __future__ import annotations

import json
import operator
from collections.abc import Callable
from pathlib import Path

import numpy as np

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from firmware_model.lvds import link as LK
from firmware_model.mcu import dpram
from hil.fieldbus.boxes import StackBox
from hil.fieldbus.chain import CYCLE_TICKS
from hil.fieldbus.master import Master
from hil.fieldbus.system import BusRecord, BusSystem
from hil.fieldbus.topology import Topology
from hil.framelog import FrameLogWriter
from hil.framelog.formats import MCU_UP_WIDTH
from hil.framelog.layout import SCHEMA_ENCODING as LAYOUT_ENCODING
from hil.framelog.layout import Layout
from hil.replay import layouts as LY
from hil.replay import signals as SG
from hil.replay.signal_out import SignalOut
from hil.sim.actuator import TRACE_WIDTH, TRACE_WORDS
from plant.config import Config

UP_WIDTH = MCU_UP_WIDTH  # uint16 elements of an upstream frame (32 words, the count in 2)
ENC_MCU_UP = LY.ENC_MCU_UP
ENC_MCU_DOWN = LY.ENC_MCU_DOWN
ENC_RECORD = LY.ENC_RECORD
ENC_FIELDBUS = "eha-hil/ethercat-fcs"  # an EtherCAT PDU + FCS (hil.fieldbus.wire)
#: Cycles per block: every raw channel gets one message per block, the decoded signals and
#: the fieldbus frames are written a block at a time, and the log's chunk is closed after
#: each (``flush_every_ns``: what a killed run loses). 200 ms of simulated time: half the
#: writes of 100 ms blocks for the same frames, which cut a logged ``hydra_full`` run's
#: extra CPU by ~10 % (the writer's and the recorder's work per call, per message array,
#: per chunk); level "full" keeps :data:`FULL_FLUSH_CYCLES` (its traces, ~640 bytes per
#: actuator tick, would double what an export holds between blocks).
FLUSH_CYCLES = 200
FULL_FLUSH_CYCLES = 100


def flush_cycles(level: str) -> int:
    """Cycles per block of a log at ``level`` (:data:`FLUSH_CYCLES`)."""
    return FULL_FLUSH_CYCLES if level == "full" else FLUSH_CYCLES


def signal_topics(box: int, board: int | None = None) -> dict[str, str]:
    """Decoded-signal topics of box ``box`` (and of its board ``board``)."""
    t = {"outputs": f"/signals/box/{box}/outputs", "inputs": f"/signals/box/{box}/inputs"}
    if board is not None:
        t["actuator"] = f"/signals/actuator/{box}.{board}"
    return t


BUS_SIGNAL_TOPIC = "/signals/bus"


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

    def __init__(self, box, cfg: Config, log: FrameLogWriter | None,  # noqa: ANN001
                 out: SignalOut | None = None) -> None:
        super().__init__(box, cfg)
        self.log = log
        self.tick_ns = cfg.get("sim.tick_ns")
        self.traced = log is not None and log.level == "full"
        self.flush_cycles = flush_cycles(log.level if log is not None else "mcu")
        self.ch_up, self.ch_down = [], []
        self.ch_trace, self.ch_words, self.ch_raw = [], [], []
        if log is not None:
            self._add_raw_channels(log, box)
        # decoded signals
        self.out = out if out is not None else SignalOut(log)
        self.cal = calibration(cfg)
        self.period_ticks = cfg.get("mcu.period_ticks")
        # actuator signals each MCU step at level full, else each fieldbus cycle (its last
        # MCU step): a fifth of the messages, what keeps the default level's cost low
        full = log is not None and log.level == "full"
        self.every = 1 if full else CYCLE_TICKS // self.period_ticks
        self.sig_rec, self.sig_act = add_signal_channels(self.out, box, cfg)
        self.carry = [SG.PistonCarry.start(1) for _ in self.stacks]
        self._last_out = (np.zeros(0, np.int64),
                          np.zeros((0, max(self.out_dtype.itemsize, 1)), np.uint8))
        self._reset_buffers()

    def _add_raw_channels(self, log: FrameLogWriter, box) -> None:  # noqa: ANN001
        b = box.id
        tp = topics(b)

        def block(topic: str, lay: Layout, dtype: type, width: int) -> int:
            return log.add_block_channel(topic, lay.encoding, dtype=dtype, width=width,
                                         schema_name=lay.encoding,
                                         schema_encoding=LAYOUT_ENCODING,
                                         schema_data=lay.schema())

        # a box without outputs (sensor boxes) has no outputs channel, not an empty one
        self.ch_out = (block(tp["outputs"], LY.process_record(box, "outputs"), np.uint8,
                             self.out_dtype.itemsize) if self.out_dtype.itemsize else None)
        self.ch_in = block(tp["inputs"], LY.process_record(box, "inputs"), np.uint8,
                           self.in_dtype.itemsize)
        for k in range(len(self.stacks)):
            tk = topics(b, k)
            self.ch_up.append(block(tk["up"], LY.mcu_up(), np.uint16, UP_WIDTH))
            self.ch_down.append(block(tk["down"], LY.mcu_down(), np.uint16, B.DOWN_WORDS))
            if self.traced:
                self.ch_trace.append(block(tk["trace"], LY.fpga_trace(), np.int64,
                                           TRACE_WIDTH))
                self.ch_words.append(tuple(block(f"/lvds/{b}.{k}/{d}_words", LY.lvds_word(),
                                                 np.uint64, 1) for d in ("down", "up")))
                self.ch_raw.append(block(f"/sensors/{b}.{k}/raw", LY.sensor_raw(), np.uint32,
                                         B.N_RAW))

    def _reset_buffers(self) -> None:
        self.buf_trace: list[list[tuple[int, np.ndarray]]] = [[] for _ in self.stacks]
        self.buf_out: list[tuple[int, bytes]] = []
        self.buf_in: list[tuple[int, bytes]] = []
        # per MCU step (preallocated: this runs at 5 kHz): the MCU board's dual-port memory
        # after the step, i.e. each board's upstream block as the MCU read it and downstream
        # block as it wrote it, in one copy; and each link's CRC-error count
        if not hasattr(self, "ram_rows"):
            cap = self.flush_cycles * CYCLE_TICKS // self.period_ticks + 8
            # the blocks of the boards in use (they come first), in the memory's dtype: one
            # plain copy up to the last board's upstream block
            self.ram_words = (dpram.up_base(len(self.stacks) - 1) + B.UP_WORDS
                              if self.board else 0)
            dtype = np.int64 if self.board is None else self.board.ram.words.dtype
            self.ram_rows = np.zeros((cap, self.ram_words), dtype)
        self.t_steps: list[int] = []
        self.crc_rows: list[list[int]] = []
        self.n_steps = 0

    def apply(self, data: bytes) -> None:
        self.buf_out.append((self.tick, bytes(data)))
        super().apply(data)

    def _mcu_step(self, tick: int) -> None:
        i = self.n_steps
        if i == len(self.ram_rows):  # more steps than a flush holds: grow
            self.ram_rows = np.concatenate([self.ram_rows, np.zeros_like(self.ram_rows)])
        super()._mcu_step(tick)
        self.t_steps.append(tick)
        self.ram_rows[i] = self.board.ram.words[:self.ram_words]
        self.crc_rows.append([s.mcu_link.up_crc_errors for s in self.stacks])
        self.n_steps = i + 1

    def _up_down(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Board ``k``'s upstream frames (n, 34: 32 words + CRC-error count as a u32,
        uint16) and downstream registers (n, 16, uint16) of the buffered MCU steps."""
        n = self.n_steps
        u, d = dpram.up_base(k), dpram.down_base(k)
        up = np.empty((n, UP_WIDTH), np.uint16)
        up[:, :B.UP_WORDS] = self.ram_rows[:n, u:u + B.UP_WORDS]
        crc = np.array([r[k] for r in self.crc_rows], np.uint32)
        up[:, B.UP_WORDS] = crc & 0xFFFF  # the count as a u32, low half first
        up[:, B.UP_WORDS + 1] = crc >> 16
        return up, self.ram_rows[:n, d:d + B.DOWN_WORDS].astype(np.uint16)

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
        if len(self.buf_in) >= self.flush_cycles:
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames as one block per channel, and their decoded signals."""
        ns = self.tick_ns

        def put(ch: int, rows: list) -> None:
            if rows and self.log is not None:
                t = np.array([r[0] for r in rows], dtype=np.int64)
                f = np.frombuffer(b"".join(r[1] for r in rows), dtype=np.uint8).reshape(
                    len(rows), -1)
                self.log.write_block(ch, t * ns, f)

        if self.log is not None:
            if self.ch_out is not None:
                put(self.ch_out, self.buf_out)
            put(self.ch_in, self.buf_in)
        n = self.n_steps
        t_steps = np.array(self.t_steps, dtype=np.int64) * ns
        for k in range(len(self.stacks)):
            if self.log is not None and n:
                up, down = self._up_down(k)
                self.log.write_block(self.ch_up[k], t_steps, up)
                self.log.write_block(self.ch_down[k], t_steps, down)
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
        self._write_signals()
        self._reset_buffers()

    def _write_signals(self) -> None:
        ns = self.tick_ns
        n = self.n_steps
        t_steps = np.array(self.t_steps, dtype=np.int64)
        # the steps first: their reads' validity is the box reports' piston flags
        steps = []
        for k in range(len(self.act)):
            up, down = self._up_down(k)
            steps.append(SG.actuator_block(self.cal, up[None], down[None], self.every,
                                           self.period_ticks * ns * 1e-9, self.carry[k]))
        out_t = out_f = None
        for d, rows in (("outputs", self.buf_out), ("inputs", self.buf_in)):
            if not rows or (d == "outputs" and not self.out_dtype.itemsize):
                continue
            t = np.array([r[0] for r in rows], dtype=np.int64)
            f = np.frombuffer(b"".join(r[1] for r in rows), dtype=np.uint8).reshape(
                len(rows), -1)
            if d == "outputs":
                out_t, out_f = t, f
            if self.sig_rec.get(d) is not None:
                piston = None
                if d == "inputs":
                    flags = [SG.report_flags(c, t_steps, t) for c in self.carry]
                    piston = (np.concatenate([x for x, _ in flags]),
                              np.concatenate([v for _, v in flags]))
                self.out.write(self.sig_rec[d], t * ns,
                               SG.record_columns(self.box, d, f, piston))
        if out_t is None:  # no output record this block: the last one still stands
            out_t, out_f = self._last_out
        else:
            self._last_out = (out_t[-1:], out_f[-1:])
        for k, slot in enumerate(self.act):
            keep, cols = steps[k]
            if not len(keep) or not n:
                continue
            t = t_steps[keep]
            cols.update(SG.pc_command_columns(out_t, out_f, self.box, slot, t))
            self.out.write(self.sig_act[k], t * ns, cols)


def add_signal_channels(out: SignalOut, box, cfg: Config,  # noqa: ANN001
                        act_message: object = None, messages: dict | None = None
                        ) -> tuple[dict, list[int]]:
    """The decoded-signal channels of box ``box``: ({"outputs"/"inputs": channel} for its
    records that have simulated fields, [channel of each actuator]). The actuators'
    message leaves out the analog inputs whose part the configuration says is not fitted
    (:func:`hil.replay.signals.unfitted_inputs`); ``act_message``: that message, made
    already (by a caller that adds many boxes). ``messages``: the record messages made so
    far, per slot kinds and direction (a caller that adds many boxes keeps it: a record's
    message depends on its box's slot kinds only, and ``hydra_full``'s 16 boxes have 4
    layouts; each message costs ~0.2 ms to make)."""
    st = signal_topics(box.id)
    rec = {}
    kinds = tuple(s.kind for s in box.slots)
    for d in ("outputs", "inputs"):
        if messages is None:
            message = SG.record_message(box, d)
        else:
            message = messages.get((kinds, d))
            if message is None:
                message = messages[kinds, d] = SG.record_message(box, d)
        if message.fields:
            rec[d] = out.add(st[d], message)
    act = act_message
    if act is None:
        act = SG.actuator_message(SG.unfitted_inputs(cfg.get("sensors")))
    return rec, [out.add(signal_topics(box.id, k)["actuator"], act)
                 for k in range(len(box.actuators))]


def signal_boxes(chain, cfg: Config, live: object) -> list:  # noqa: ANN001
    """Make the boxes of ``chain`` (before it runs) send their decoded signals to ``live``
    (no log); call ``close()`` (or ``flush()``) of each returned recorder at the end."""
    return attach_recorders(chain, cfg, None, live)


def attach_recorders(chain, cfg: Config, log: FrameLogWriter | None, live: object = None,  # noqa: ANN001
                     level: str = "mcu", background: bool = False) -> list:
    """Log the MCU boundary of ``chain``'s boxes (a :class:`~hil.fieldbus.chain.Chain` or
    anything with ``boxes`` and ``engine``, before it runs) to ``log`` and/or send their
    decoded signals to ``live``: the whole-robot engine's :class:`RobotRecorder`
    (``background``: written by a thread of its own), else each stack box replaced by a
    :class:`RecordingStackBox`. Echo boxes have no MCU to log. Returns the recorders: call
    ``close()`` (a RobotRecorder) or ``flush()`` of each at the end."""
    out = SignalOut(log, live)
    engine = getattr(chain, "engine", None)
    if engine is not None:
        from hil.replay.robot_record import RobotRecorder

        return [RobotRecorder(engine, chain.boxes, cfg, log, out, level, background)]
    recs = []
    for i, b in enumerate(chain.boxes):
        if isinstance(b, StackBox):
            chain.boxes[i] = RecordingStackBox(b.box, cfg, log, out)
            recs.append(chain.boxes[i])
    return recs


def replay_metadata(topo: Topology, cfg: Config, boxes: list, model: str,
                    cycles: int) -> dict[str, str]:
    """The ``eha-hil.replay`` Metadata record of a log of ``boxes`` (what a replay needs)."""
    offsets = {f"{b.box.id}.{k}": int(s.board.calibrated_offset)
               for b in boxes for k, s in enumerate(getattr(b, "stacks", ()))}
    return {"config": json.dumps(cfg.data), "topology": topo.source, "model": model,
            "offsets": json.dumps(offsets), "cycles": str(cycles)}


class BusSignals:
    """``/signals/bus``: the master's counters and the WKC of each cycle, from what the
    run's tap keeps for the log (:meth:`tap`, called once per cycle: the cycle's frames
    appended to :attr:`frames` and its row to :attr:`cycles`), counted a block at a time
    in :meth:`flush`."""

    #: Values per cycle in :attr:`cycles`.
    WIDTH = 3 + len(SG.MASTER_COUNTERS)

    def __init__(self, out: SignalOut, master: Master, tick_ns: int) -> None:
        self.out = out
        self.master = master
        self.tick_ns = tick_ns
        self.ch = out.add(BUS_SIGNAL_TOPIC, SG.BUS)
        self.wkc_expected = sum(w for _, _, w in master.plan.frames)
        #: per cycle of the block, :attr:`WIDTH` values one after the other (flat: one
        #: array of the block is made ~4x faster from it than from a tuple per cycle): its
        #: first tick, frames sent, frames received, the master's counters once it ended
        #: (:data:`~hil.replay.signals.MASTER_COUNTERS`)
        self.cycles: list[int] = []
        #: the block's frames, as the tap saw them (sent, then received, per cycle)
        self.frames: list[bytes] = []
        self._rows: np.ndarray | None = None  # :attr:`cycles` as rows, made once per block

    def tap(self, every: int, flush: Callable[[], None]
            ) -> Callable[[int, int, list[bytes], list[bytes]], None]:
        """The bus system's per-cycle call (:data:`hil.fieldbus.system.CycleTapFn`: the
        cycle's number and first tick, the frames sent and received), once the master has
        ended the cycle: its frames and its row, one tuple, and ``flush()`` after every
        ``every``-th cycle; no other call per cycle."""
        add, count = self.frames.extend, self.cycles.extend
        counters, stats = operator.attrgetter(*SG.MASTER_COUNTERS), self.master.stats

        def cycle(number: int, tick: int, sent: list[bytes], received: list[bytes]) -> None:
            add(sent)  # (bytes: the master's sealed frames, what the transport returns)
            add(received)
            # two extends: ~0.25 us less than one of a tuple unpacking the counters' tuple
            count((tick, len(sent), len(received)))
            count(counters(stats))
            if (number + 1) % every == 0:
                flush()
        return cycle

    def rows(self) -> np.ndarray:
        """The block's cycles, (cycles, :attr:`WIDTH`) int64 (made once per block)."""
        if self._rows is None:
            self._rows = np.array(self.cycles, dtype=np.int64).reshape(-1, self.WIDTH)
        return self._rows

    def frame_times(self) -> np.ndarray:
        """Each of :attr:`frames`' time (ns): its cycle's first tick, a reply 1 ns after
        it (as in the log)."""
        a = self.rows()
        t0 = a[:, 0] * self.tick_ns
        return np.repeat(np.stack([t0, t0 + 1], axis=1).ravel(), a[:, 1:3].ravel())

    def flush(self, t: np.ndarray) -> None:
        """Write the block's cycles and forget them and their frames (``t``: the frames'
        :meth:`frame_times`)."""
        if self.cycles:
            a = self.rows()
            n_frames, wkc = _frames_and_wkc(self.frames, t % self.tick_ns != 0,
                                            np.cumsum(a[:, 1] + a[:, 2]))
            cycle = a[:, 0] // CYCLE_TICKS
            cols = {"cycle": cycle, "frames": n_frames, "wkc": wkc,
                    "wkc_expected": self.wkc_expected,
                    **{name: a[:, 3 + i] for i, name in enumerate(SG.MASTER_COUNTERS)}}
            # stamped at the end of the cycle (when its replies are in)
            self.out.write(self.ch, (cycle + 1) * CYCLE_TICKS * self.tick_ns - 1, cols)
            self.cycles.clear()
        self._rows = None
        self.frames.clear()


def _frames_and_wkc(frames: list[bytes], rx: np.ndarray | list[bool], ends: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Per cycle (its frames end at index ``ends[i]`` of ``frames``): the frames sent, and
    the sum of its replies' working counters, the 2 bytes before the FCS (the master
    sends one datagram per frame)."""
    n = len(frames)
    cycle = np.searchsorted(ends, np.arange(n), side="right")  # each frame's cycle
    is_rx = np.array(rx, dtype=bool)
    lens = np.fromiter(map(len, frames), np.int64, n)
    buf = np.frombuffer(b"".join(frames), np.uint8)
    at = np.cumsum(lens) - 6  # the working counter's first byte, if it has one
    has = is_rx & (lens >= 6)
    w = buf[at[has]].astype(np.int64) | (buf[at[has] + 1].astype(np.int64) << 8)
    c = len(ends)
    return (np.bincount(cycle[~is_rx], minlength=c)[:c],
            np.bincount(cycle[has], weights=w, minlength=c)[:c].astype(np.int64))


def run_logged(topo: Topology, cfg: Config, cycles: int, pc: Callable[[int, Master], None],
               log_path: str | Path | None, level: str = "mcu",
               progress: Callable[[int, int], None] | None = None,
               faults: object = None, live: object = None,
               capture: Callable[[int, int, bytes, str], None] | None = None,
               model: str = "stack", compression: str = "zstd", keep: int | None = 1
               ) -> BusRecord:
    """Run ``cycles`` cycles in-process with the box model ``model`` (``stack``: each box
    on its own, :class:`RecordingStackBox`; ``robot``: every box in the whole-robot engine,
    :class:`hil.replay.robot_record.RobotRecorder`: the same channels) and log them to
    ``log_path``.

    ``faults``: a fault declaration (:func:`hil.fieldbus.faults.parse_faults`); the log holds
    what the master sent and received and what each MCU took in and gave out, faults and
    all, so the replay reproduces a faulty run too. ``live``: a live view the decoded
    signals also go to (:class:`SignalOut`); ``log_path`` None: only there. ``capture``: a
    further tap that sees every fieldbus frame (e.g.
    :meth:`hil.fieldbus.capture.CaptureWriter.tap`). ``compression``: of the log's chunks
    (zstd, lz4 or none; :class:`~hil.framelog.writer.FrameLogWriter`). ``keep``: the
    returned record holds the input images of the last ``keep`` cycles (None: every
    cycle's; the log holds them all anyway): by default the last one, so that the memory
    of a long run does not grow with it (an hour of the whole robot: 4 GB of images)."""
    if keep is not None and keep < 0:
        raise ValueError(f"keep = {keep}: expected >= 0 cycles")
    import contextlib

    tick_ns = cfg.get("sim.tick_ns")
    block = flush_cycles(level)
    with contextlib.ExitStack() as stack:
        log = None
        if log_path is not None:
            log = stack.enter_context(FrameLogWriter(
                log_path, level=level, flush_every_ns=block * CYCLE_TICKS * tick_ns,
                compression=compression))
        out = SignalOut(log, live)
        ch_bus = None
        if log is not None:
            lay = Layout(ENC_FIELDBUS, 0, ())  # frames vary in length: no fixed layout
            ch_bus = log.add_channel("/fieldbus/frames", ENC_FIELDBUS,
                                     schema_name=ENC_FIELDBUS, schema_encoding=LAYOUT_ENCODING,
                                     schema_data=lay.schema())
        bus_sig: BusSignals | None = None

        def flush_block() -> None:
            t = bus_sig.frame_times()
            if bus_sig.frames and ch_bus is not None:
                log.write_messages(ch_bus, t, bus_sig.frames)
            bus_sig.flush(t)

        with BusSystem(topo, cfg, "inproc", model=model, tap=capture) as bs:
            bus_sig = BusSignals(out, bs.master, tick_ns)
            # the frames of the last cycles, kept for /signals/bus and the log and written
            # once per block (a message at a time costs ~9 us, see hil.framelog.batch),
            # taken a cycle at a time (the bus system's tap_cycle, at the end of each
            # cycle: one call, not one per frame, the cycle's /signals/bus row with it)
            bs.tap_cycle = bus_sig.tap(block, flush_block)
            engine = bs.chain.engine
            if engine is None:
                boxes = [RecordingStackBox(b, cfg, log, out) for b in topo.boxes]
                bs.chain.boxes = boxes
                flushers = boxes
            else:
                from hil.replay.robot_record import RobotRecorder

                boxes = bs.chain.boxes
                flushers = [RobotRecorder(engine, boxes, cfg, log, out, level)]
            if faults is not None:
                bs._install_faults(faults)  # after the recording boxes replaced the plain ones
            if log is not None:
                log.add_metadata("eha-hil.replay",
                                 replay_metadata(topo, cfg, boxes, model, cycles))
            step = max(cycles // 20, 1)
            parts: list[BusRecord] = []
            done = 0
            while done < cycles:
                n = min(step, cycles - done)
                parts.append(bs.run(n, pc, keep=keep))
                done += n
                if progress:
                    progress(done, cycles)
            rec = None
            if parts:  # the input images kept of every part, joined once
                last = parts[-1]
                inputs = np.concatenate([p.inputs for p in parts])
                if keep is not None:
                    inputs = inputs[len(inputs) - min(keep, len(inputs)):]
                rec = BusRecord(inputs, last.master, last.chain, last.transport, last.faults,
                                cycles - len(inputs))
            flush_block()
            if engine is not None:
                engine.wait()
            for f in flushers:
                getattr(f, "close", f.flush)()
        return rec
