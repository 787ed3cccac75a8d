"""The frame log of a run of the whole-robot engine (:class:`hil.sim.robot.RobotEngine`):
the same channels, layouts and decoded signals as the per-actuator path's
(:class:`hil.replay.record.RecordingStackBox`, the module doc of :mod:`hil.replay.record`),
so ``eha-hil replay`` and ``log export`` read either.

The engine's compiled kernel copies each MCU step's words (the 32 upstream words and the
CRC-error count the program read, the 16 downstream words it wrote) and, at level
``full``, the driver boards' trace of every tick into block arrays
(:class:`hil.sim.stack_rows.TapRows`, actuator-major) and, at each cycle's end, the cycle's
process images into the rows of :class:`hil.sim.stack_rows.ImageRows`; this recorder is
told when a cycle ends, and every :data:`BLOCK_CYCLES` cycles writes the block: one
message per raw channel, and the decoded signals of all actuators computed and encoded as
whole arrays (:func:`hil.replay.signals.actuator_block`). No Python runs per tick or per
actuator step.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from firmware_model.lvds import link as LK
from hil.framelog import FrameLogWriter
from hil.framelog.layout import SCHEMA_ENCODING as LAYOUT_ENCODING
from hil.framelog.layout import Layout
from hil.replay import layouts as LY
from hil.replay import signals as SG
from hil.replay.record import FLUSH_CYCLES, UP_WIDTH, add_signal_channels, flush_cycles, topics
from hil.replay.signal_kernel import ActuatorEncoder
from hil.replay.signal_out import SignalOut
from hil.replay.signal_records import RecordEncoder
from hil.sim.actuator import TRACE_WIDTH, TRACE_WORDS
from hil.sim.robot import RobotEngine
from hil.sim.stack_rows import ImageRows, TapRows
from plant.config import Config

#: Cycles per written block: the per-actuator path's (:func:`hil.replay.record.flush_cycles`),
#: fewer at level "full", whose traces take ~640 bytes per actuator tick.
BLOCK_CYCLES = {"full": 10}


class RobotRecorder:
    """Logs the run of ``engine`` (whose boxes are ``boxes``, the chain's, in order) to
    ``log`` (None: only the decoded signals, to ``out``'s live view). Attach before the
    run; :meth:`close` after it. ``background``: blocks are written by a thread of their
    own (a chain paced by the wall clock, ``serve``: a cycle must not wait for a block's
    writing; the thread takes the interpreter lock while it encodes)."""

    def __init__(self, engine: RobotEngine, boxes: list, cfg: Config,
                 log: FrameLogWriter | None, out: SignalOut, level: str = "mcu",
                 background: bool = False) -> None:
        self.engine = engine
        if getattr(engine, "lanes", False) and not getattr(engine, "lanes_log_rows", False):
            # a kernel that does not fill the tap would leave the log's words at 0; the
            # scalar kernel gives the same bits per actuator
            engine.lanes = False
        self.log = log
        self.out = out
        self.cfg = cfg
        self.ns = cfg.get("sim.tick_ns")
        self.period = engine.period
        self.cal = calibration(cfg)
        self.full = level == "full"
        per_cycle = engine.cycle_ticks // self.period
        self.every = 1 if self.full else per_cycle
        self.cycles = BLOCK_CYCLES.get(level, flush_cycles(level))
        n, rows = engine.n, self.cycles * per_cycle
        self.tap = TapRows(np.zeros((n, rows, UP_WIDTH), np.uint16),
                           np.zeros((n, rows, B.DOWN_WORDS), np.uint16),
                           np.zeros((n, rows * self.period if self.full else 0, TRACE_WIDTH),
                                    np.int64), np.zeros(1, np.int64))
        self.boxes = boxes
        #: per chain box: its slot layout (boxes of one layout are written together)
        self._layout = [tuple(s.kind for s in b.box.slots) for b in boxes]
        where = {id(b): k for k, b in enumerate(engine.boxes)}
        #: per chain box: its index among the engine's boxes (None: it has no MCU board)
        self.engine_box = [where.get(id(b)) for b in boxes]
        self.out_span = engine._out_span
        lo = np.cumsum([0] + [b.in_dtype.itemsize for b in engine.boxes])
        self.in_span = list(zip(lo[:-1], lo[1:], strict=True))
        self.others = [b for b in boxes if id(b) not in where]
        # one row per cycle of the block
        c = self.cycles
        self.out_rows = np.zeros((c, len(engine.out_image)), np.uint8)
        #: per cycle, per actuator: its box took outputs (the engine's ``_got``, copied
        #: whole: cheaper per cycle than picking the boxes' first actuators, done per block)
        self.out_got_act = np.zeros((c, n), bool)
        self.out_t = np.zeros(c, np.int64)
        self.in_rows = np.zeros((c, len(engine.in_image)), np.uint8)
        self.other_in = [np.zeros((c, b.in_dtype.itemsize), np.uint8) for b in self.others]
        self.in_t = np.zeros(c, np.int64)
        self.n_cycles = 0
        self._take_written: int | None = None  # the tick of a take ahead flush wrote
        #: the engine copies each cycle's images into these rows (its compiled
        #: give_inputs) and moves the tap's row on
        self.images = ImageRows(self.out_rows, self.out_got_act, self.in_rows, self.out_t,
                                self.in_t, np.zeros(1, np.int64))
        self._box_first = np.asarray(engine._first[:-1], np.intp)
        # the copies :meth:`flush` makes of outputs taken ahead, and per cycle (1 kHz) in
        # :meth:`finished` those of the boxes outside the engine: each a memoryview's slice
        # assignment of one row made here (a row of the block and its source, both looked
        # up once), ~0.2 us where a numpy row assignment takes ~0.8 us
        self._out_row, self._got_row = (
            [memoryview(r) for r in a] for a in (self.out_rows, self.out_got_act))
        self._out_src, self._got_src = (memoryview(a) for a in (engine.out_image, engine._got))
        self._out_tv = memoryview(self.out_t)
        self._other_inputs = [([memoryview(row) for row in r], _input_source(b))
                              for r, b in zip(self.other_in, self.others, strict=True)]
        self._rows = 0  # the tap's rows filled (tap.row[0], as a Python int)
        #: the last row at which a cycle's steps still fit the tap
        self._last_row_start = rows - engine.cycle_ticks // self.period
        self.carry = SG.PistonCarry.start(n)
        #: per engine box: the index of its first actuator in the engine's order
        self.first_act = np.cumsum([0] + [len(b.act) for b in engine.boxes])[:-1].tolist()
        self._pool = (ThreadPoolExecutor(1, thread_name_prefix="robot-log")
                      if background else None)
        self._jobs: list[Future] = []
        self._channels(log)
        self._groups: dict[tuple, tuple] = {}  # see _group
        self._encoders: dict[tuple, RecordEncoder] = {}  # per direction and slot layout
        # the actuators' signals (each with the PC's command from its slot of the output
        # image), decoded and encoded by one compiled call per block
        box_of, slot_off = [], []
        for e, b in enumerate(engine.boxes):
            for slot in b.act:
                box_of.append(e)
                slot_off.append(int(self.out_span[e][0])
                                + sum(s.sizes[0] for s in b.box.slots[:slot]))
        self.encoder = (ActuatorEncoder(self.cal, self.out.message(self.sig_act[0]),
                                        self.period * self.ns * 1e-9, self.every, box_of,
                                        slot_off, [tuple(map(int, sp)) for sp in self.out_span],
                                        len(engine.out_image))
                        if self.sig_act else None)
        engine.log_rows = self.tap
        engine.log_images = self.images
        engine.log = self

    # --- channels ------------------------------------------------------------------------
    def _channels(self, log: FrameLogWriter | None) -> None:
        schemas: dict[int, str] = {}  # per layout its schema text, made once per run

        def block(topic: str, lay: Layout, dtype: type, width: int) -> int:
            if id(lay) not in schemas:
                schemas[id(lay)] = lay.schema()
            return log.add_block_channel(topic, lay.encoding, dtype=dtype, width=width,
                                         schema_name=lay.encoding,
                                         schema_encoding=LAYOUT_ENCODING,
                                         schema_data=schemas[id(lay)])

        # the layouts every actuator's channels share (47 actuators: made once, not each)
        up, down = LY.mcu_up(), LY.mcu_down()
        trace, word, raw = ((LY.fpga_trace(), LY.lvds_word(), LY.sensor_raw()) if self.full
                            else (None, None, None))
        act_message = SG.actuator_message(SG.unfitted_inputs(self.cfg.get("sensors")))

        self.ch_out: list[int | None] = []
        self.ch_in: list[int] = []
        self.ch_up, self.ch_down, self.ch_trace, self.ch_raw, self.ch_words = [], [], [], [], []
        self.sig_rec: list[dict] = []
        self.sig_act: list[int] = []
        # a record's layout and message depend on its box's slot kinds only: made once per
        # kinds (hydra_full: 16 boxes, 4 layouts), their schemas' JSON with them
        messages: dict = {}  # the record messages (add_signal_channels)
        records: dict[tuple, Layout] = {}

        def record(box, d: str) -> Layout:  # noqa: ANN001
            key = (tuple(s.kind for s in box.slots), d)
            lay = records.get(key)
            if lay is None:
                lay = records[key] = LY.process_record(box, d)
            return lay

        for b in self.boxes:
            box = b.box
            if log is not None:
                tp = topics(box.id)
                self.ch_out.append(block(tp["outputs"], record(box, "outputs"), np.uint8,
                                         b.out_dtype.itemsize)
                                   if b.out_dtype.itemsize else None)
                self.ch_in.append(block(tp["inputs"], record(box, "inputs"), np.uint8,
                                        b.in_dtype.itemsize))
                for k in range(len(box.actuators)):
                    tk = topics(box.id, k)
                    self.ch_up.append(block(tk["up"], up, np.uint16, UP_WIDTH))
                    self.ch_down.append(block(tk["down"], down, np.uint16, B.DOWN_WORDS))
                    if self.full:
                        self.ch_trace.append(block(tk["trace"], trace, np.int64,
                                                   TRACE_WIDTH))
                        self.ch_words.append(tuple(
                            block(f"/lvds/{box.id}.{k}/{d}_words", word, np.uint64, 1)
                            for d in ("down", "up")))
                        self.ch_raw.append(block(f"/sensors/{box.id}.{k}/raw", raw,
                                                 np.uint32, B.N_RAW))
            rec, act = add_signal_channels(self.out, box, self.cfg, act_message, messages)
            self.sig_rec.append(rec)
            self.sig_act += act

    # --- the engine's hook (hil.sim.robot.EngineLog) --------------------------------------
    # Once per fieldbus cycle: the engine's compiled give_inputs has copied the cycle's
    # images into row ``n_cycles`` (:attr:`images`) and moved the tap's row on; here only
    # the boxes outside the engine (a view's copy each) and the count. Outputs taken for a
    # cycle that never ended (the run's last) are copied by :meth:`flush`.
    def finished(self, tick: int, periods: int) -> None:
        c = self.n_cycles
        for rows, inputs in self._other_inputs:
            rows[c][:] = inputs if type(inputs) is memoryview else inputs()
        self.n_cycles = c = c + 1
        self._rows = r = self._rows + periods
        if c == self.cycles or r > self._last_row_start:
            self.flush()

    # --- writing a block -----------------------------------------------------------------
    def flush(self) -> None:
        """Write the buffered cycles and steps: one block per raw channel, the decoded
        signals of every box and actuator (in the background with ``background``: the
        block is copied and the engine's next cycle does not wait for the writing)."""
        c, r = self.n_cycles, int(self.tap.row[0])
        # the run's last outputs, taken for a cycle never run (at its tick), once
        taken = self.engine.taken_ahead and self._take_written != self.engine.tick
        if taken:
            self._out_row[c][:] = self._out_src
            self._got_row[c][:] = self._got_src
            self._out_tv[c] = self._take_written = self.engine.tick
        c_out = c + taken
        self.n_cycles = 0
        self.tap.row[0] = self._rows = 0
        self.images.at[0] = 0
        if not c_out and not r:
            return
        end = int(self.in_t[c - 1]) if c else self.engine.tick
        tap = self.tap
        block = _Block(c, c_out, end - self.period * np.arange(r, 0, -1, dtype=np.int64),
                       self.out_t[:c_out], self.out_rows[:c_out],
                       self.out_got_act[:c_out, self._box_first],
                       self.in_t[:c], self.in_rows[:c], [o[:c] for o in self.other_in],
                       tap.up[:, :r], tap.down[:, :r], tap.trace[:, :r * self.period])
        if self._pool is None:
            self._write(block)
            return
        block = block.copy()
        self._jobs.append(self._pool.submit(self._write, block))
        while self._jobs and self._jobs[0].done():
            self._jobs.pop(0).result()  # a failed write ends the run here

    def close(self) -> None:
        """The last block written; with ``background``, once every block is."""
        self.flush()
        if self._pool is not None:
            for job in self._jobs:
                job.result()
            self._jobs.clear()
            self._pool.shutdown()

    def _write(self, k: _Block) -> None:
        c = k.cycles
        others = iter(k.other_in)
        # boxes of one slot layout (and, for outputs, the same cycles' records) are
        # written together: one block message array, one decoding and encoding for all
        groups: dict[tuple, list[tuple[int, np.ndarray]]] = {}
        times: dict[tuple, np.ndarray] = {}
        every = k.out_got.all()  # (the usual block: every box took outputs every cycle)
        for n_box, e in enumerate(self.engine_box):
            layout = self._layout[n_box]
            if e is None:
                ins = next(others)
                outs = None
            else:
                lo, hi = self.in_span[e]
                ins = k.in_rows[:, lo:hi]
                olo, ohi = self.out_span[e]
                if every:
                    outs = (k.out_t, k.out_rows[:, olo:ohi])
                else:
                    got = k.out_got[:, e]
                    outs = (k.out_t[got], k.out_rows[got, olo:ohi])
            if c:
                groups.setdefault(("inputs", layout), []).append((n_box, ins))
                times[("inputs", layout)] = k.in_t
            if outs is not None and len(outs[0]):
                key = ("outputs", layout, None if every else outs[0].tobytes())
                groups.setdefault(key, []).append((n_box, outs[1]))
                times[key] = outs[0]
        # the steps first: their reads' validity is the box reports' piston flags
        self._write_steps(k)
        flags = SG.report_flags(self.carry, k.t_steps, k.in_t) if c else None
        # smallest first: the chunk of the boxes' signals closes by its size (the writer's
        # chunk_size) at the block's largest batch, its last, not one batch before the end
        # (which left a small chunk of the last group alone in every block)
        for key in sorted(groups, key=lambda g: sum(r.nbytes for _, r in groups[g])):
            self._write_records(key[0], times[key], groups[key], flags)

    def _write_records(self, d: str, t: np.ndarray, members: list[tuple[int, np.ndarray]],
                       flags: tuple[np.ndarray, np.ndarray] | None) -> None:
        """The ``d`` records (``outputs``/``inputs``) of boxes of one slot layout at the
        same times ``t`` (ticks): ``members`` (chain index, (n, bytes) rows) each;
        ``flags``: every actuator's piston flags of the block's cycles
        (:func:`hil.replay.signals.report_flags`)."""
        rows = np.stack([r for _, r in members])
        chs, sig, pick, enc = self._group(d, tuple(n for n, _ in members))
        t_ns = t * self.ns
        if chs is not None:
            self.log.write_blocks(chs, t_ns, rows)
        if sig is not None:
            # decoded and encoded by one compiled call, into the messages' places
            # (the reference: signals.record_columns + encode_into)
            self.out.write_filled(sig, t_ns, enc.message.size,
                                  lambda out: enc.encode(rows, out, flags, pick))

    def _group(self, d: str, boxes: tuple[int, ...]) -> tuple:
        """For the ``d`` records of the chain boxes ``boxes`` (one slot layout): their log
        channels (None: none), their signal channels (None: none), the rows of their
        actuators' piston flags, (actuators per box, boxes) (None: not an input record of
        engine boxes) and the signals' encoder (:class:`RecordEncoder`, one per slot
        layout and direction); worked out once per group of the run."""
        key = (d, boxes)
        got = self._groups.get(key)
        if got is None:
            chs = None
            if self.log is not None:
                per = self.ch_in if d == "inputs" else self.ch_out
                if per[boxes[0]] is not None:
                    chs = [per[n] for n in boxes]
            sig = [self.sig_rec[n].get(d) for n in boxes]
            pick = None
            if d == "inputs" and self.engine_box[boxes[0]] is not None:
                m = len(self.engine.boxes[self.engine_box[boxes[0]]].act)
                js = [self.first_act[self.engine_box[n]] for n in boxes]
                pick = np.arange(m)[:, None] + np.array(js, np.intp)[None, :]
            enc = None
            if sig[0] is not None:
                box = self.boxes[boxes[0]].box
                at = (d, self._layout[boxes[0]])
                enc = self._encoders.get(at)
                if enc is None:
                    enc = self._encoders[at] = RecordEncoder(box, d, self.out.message(sig[0]))
            got = self._groups[key] = (chs, sig if sig[0] is not None else None, pick, enc)
        return got

    def _write_steps(self, k: _Block) -> None:
        """The block's MCU steps: their raw words (and traces), and every actuator's
        decoded signals, encoded into their places in the log (this moves
        :attr:`carry` on, also when no step of the block is kept)."""
        ns, log, n = self.ns, self.log, self.engine.n
        t_steps, up, down = k.t_steps, k.up, k.down
        r = len(t_steps)
        if log is not None and r:
            t = t_steps * ns
            log.write_blocks(self.ch_up, t, up)  # one record array for every actuator
            log.write_blocks(self.ch_down, t, down)
            if self.full:
                tt = (t_steps[0] + np.arange(r * self.period, dtype=np.int64)) * ns
                for j in range(n):
                    tr = k.trace[j]
                    log.write_block(self.ch_trace[j], tt, tr)
                    log.write_block(self.ch_raw[j], tt, tr[:, :B.N_RAW])
                    for d, ch in enumerate(self.ch_words[j]):
                        tw, words = LK.line_words(tr[:, TRACE_WORDS + d * LK.WORDS_W:], tt)
                        if len(tw):
                            log.write_block(ch, tw, words[:, None])
        enc = self.encoder
        if enc is None:
            return

        def encode(out: np.ndarray | None = None) -> None:
            enc.encode(up, down, self.carry, t_steps, k.out_t, k.out_rows, k.out_got, out)

        keep = enc.kept(r)
        if len(keep):
            self.out.write_filled(self.sig_act, t_steps[keep] * ns, enc.message.size, encode)
        else:
            encode()


def _input_source(box) -> memoryview | Callable[[], bytes]:  # noqa: ANN001
    """Where a box the engine does not advance keeps its input record: a view of its
    buffer, read in place each cycle, where it is the plain box's fixed ``bytearray``
    (:meth:`hil.fieldbus.boxes._BoxBase.inputs` copies it); else its ``inputs``."""
    from hil.fieldbus.boxes import _BoxBase

    buf = getattr(box, "_in_buf", None)
    if type(box).inputs is _BoxBase.inputs and isinstance(buf, bytearray) \
            and len(buf) == box.in_dtype.itemsize:
        return memoryview(buf)
    return box.inputs


@dataclass
class _Block:
    """One block of the run as :meth:`RobotRecorder._write` takes it."""

    cycles: int
    cycles_out: int
    t_steps: np.ndarray
    out_t: np.ndarray
    out_rows: np.ndarray
    out_got: np.ndarray
    in_t: np.ndarray
    in_rows: np.ndarray
    other_in: list[np.ndarray]
    up: np.ndarray
    down: np.ndarray
    trace: np.ndarray

    def copy(self) -> _Block:
        return _Block(self.cycles, self.cycles_out, *(
            [a.copy() for a in v] if isinstance(v, list) else v.copy()
            for v in (self.t_steps, self.out_t, self.out_rows, self.out_got, self.in_t,
                      self.in_rows, self.other_in, self.up, self.down, self.trace)))


def warm_up(cfg: Config) -> None:
    """Compile what a logged run of the whole-robot engine calls for the argument types it
    passes: a full block (the tap's rows whole: C-contiguous arrays), the last, partial one
    (views of them) and the messages written into their places in the chunk (strided
    rows). The kernels' own warm-ups (:func:`hil.replay.signal_kernel.warm_up`) pass
    contiguous arrays only, so a first ``bus run --log`` compiled two more specialisations
    of the actuators' encoder and one of the records' in its first blocks (~10 s of CPU at
    load; the cold first pair of ``bench log``). A run of ``FLUSH_CYCLES + 20`` cycles of
    ``hip_one_box`` (two actuators: with one, a partial block's rows are contiguous too),
    logged to a temporary file, passes exactly those."""
    import tempfile
    from pathlib import Path

    from hil.fieldbus.topology import load_topology
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc

    with tempfile.TemporaryDirectory() as d:
        run_logged(load_topology("hip_one_box"), cfg, FLUSH_CYCLES + 20, demo_pc(),
                   Path(d) / "warm.mcap", model="robot")
