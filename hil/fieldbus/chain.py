"""The slave side of the bus: the daisy chain of joint driver boxes (EtherCAT slaves).

Each box owns a window of the logical address space: its outputs, then its inputs
(FMMU-style mapping, offsets in :class:`CyclePlan`). A logical read-write datagram that
covers a window writes the box's outputs from the frame and puts its inputs into the
frame, and the box adds 2 (write) + 1 (read) to the working counter. The chain processes a
frame as it passes through every box and sends it back.

Time: the boxes advance one fieldbus cycle (20 ticks) each time a frame of a newer cycle
arrives (the datagram ``idx`` carries the cycle number mod 256), so the same frames give
the same results whether the chain runs in the master's process or in another one, and a
lost cycle still advances time. A frame from an older cycle (delayed or duplicated) is
discarded and counted.

Paced mode (``Chain(..., paced=True)``, used by ``eha-hil serve``, :mod:`hil.cli.serve`): the
owner advances the boxes by calling :meth:`Chain.advance` once per millisecond of wall time,
and frames never move time; ``idx`` only serves to discard a frame older than the newest
one seen (mod 256, as above). A frame is answered with the inputs as they stand.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.fieldbus import lrw, wire
from hil.fieldbus.boxes import box_engine, make_box
from hil.fieldbus.topology import Topology
from plant.config import Config
from protocols import ethercat as ec

CYCLE_TICKS = 20  # 1 kHz on the 20 kHz clock
#: Largest datagram data per frame (the codec's limit).
MAX_DATAGRAM_DATA = ec.MAX_DATAGRAM_DATA


@dataclass(frozen=True)
class Window:
    box: int
    lad: int
    out_len: int
    in_len: int

    @property
    def end(self) -> int:
        return self.lad + self.out_len + self.in_len

    @property
    def wkc(self) -> int:
        return (2 if self.out_len else 0) + (1 if self.in_len else 0)


@dataclass(frozen=True)
class CyclePlan:
    """Logical windows of the boxes and the frames of one cycle (one LRW datagram per frame,
    split at box boundaries so that no box straddles two frames, as SOEM does)."""

    windows: tuple[Window, ...]
    frames: tuple[tuple[int, int, int], ...]  # (lad, length, expected WKC)

    @classmethod
    def build(cls, topo: Topology, max_data: int = MAX_DATAGRAM_DATA) -> CyclePlan:
        windows, lad = [], 0
        for b in topo.boxes:
            w = Window(b.id, lad, b.out_bytes, b.in_bytes)
            if w.end - w.lad > max_data:
                raise ValueError(f"box {b.id}: {w.end - w.lad} bytes exceed one frame")
            windows.append(w)
            lad = w.end
        frames, start, wkc = [], 0, 0
        for w in windows:
            if w.end - start > max_data:
                frames.append((start, w.lad - start, wkc))
                start, wkc = w.lad, 0
            wkc += w.wkc
        frames.append((start, lad - start, wkc))
        return cls(tuple(windows), tuple(frames))

    @property
    def image_bytes(self) -> int:
        return self.windows[-1].end


@dataclass
class ChainStats:
    frames: int = 0
    bad_frames: int = 0       # CRC trailer or PDU decode failed: discarded
    stale_frames: int = 0     # from an older cycle: discarded
    cycles_advanced: int = 0
    extra: dict = field(default_factory=dict)


class Chain:
    """All boxes of a topology, with their models, answering frames."""

    def __init__(self, topo: Topology, cfg: Config, model: str = "stack",
                 paced: bool = False, crc_trailer: bool = True) -> None:
        self.topology = topo
        #: Frames carry the CRC-32 trailer (:mod:`hil.fieldbus.wire`); replies get one too.
        self.crc_trailer = crc_trailer
        #: True: time moves only by :meth:`advance` (wall-clock pacing), not by frame idx.
        self.paced = paced
        self.last_idx = 0
        self.plan = CyclePlan.build(topo)
        self.boxes = [make_box(model, b, cfg) for b in topo.boxes]
        #: Model "robot": one engine advances every box (None: each box advances itself).
        self.engine = box_engine(model, self.boxes, cfg, overlap=not paced)
        self.cycle = 0
        self.started = False
        self.stats = ChainStats()
        #: Called after every fieldbus cycle the boxes advance (observers of the slaves'
        #: own state, which a lost reply hides from the master; lockstep mode advances
        #: the cycles a lost frame skipped when the next one arrives).
        self.on_advance: Callable[[], None] | None = None
        #: Made from :attr:`plan` (again when it is replaced): its frames as templates
        #: (hil.fieldbus.lrw), read and answered by slices, and what a datagram covering
        #: the logical bytes [lo, hi) does, by (lo, hi).
        self._plan_of_caches: CyclePlan | None = None
        self._boxes_of_caches: list = []
        self._templates: dict = {}
        self._windows_of: dict[tuple[int, int], _Cover] = {}

    def handle(self, frame: bytes) -> bytes | None:
        """Process one frame; the reply, or None if the frame was discarded."""
        if self.plan is not self._plan_of_caches or self.boxes != self._boxes_of_caches:
            self._plan_of_caches, self._boxes_of_caches = self.plan, list(self.boxes)
            self._templates = lrw.templates(self.plan.frames, self.crc_trailer)
            self._windows_of = {}
        known = lrw.find(self._templates, frame)
        if known is not None:  # exactly one of the plan's frames (what a master sends)
            self.stats.frames += 1
            if not self._time(frame[lrw.IDX_AT]):
                return None
            return self._answer(known[1], frame)
        dgs = wire.open_frame(frame, self.crc_trailer)
        if dgs is None:
            self.stats.bad_frames += 1
            return None
        self.stats.frames += 1
        if not self._time(dgs[0].idx):
            return None
        out = [self._process(d) for d in dgs]
        return wire.seal(ec.encode_pdu(out), self.crc_trailer)

    def _time(self, idx: int) -> bool:
        """Time as the frame's ``idx`` says (see the module's docstring); False: the frame
        is from an older cycle, discarded."""
        if self.paced:
            if self.started and (idx - self.last_idx) & 0xFF >= 128:
                self.stats.stale_frames += 1
                return False
            self.last_idx = idx
        elif self.started:
            ahead = (idx - self.cycle) & 0xFF
            if ahead >= 128:
                self.stats.stale_frames += 1
                return False
            for _ in range(ahead):
                self._advance()
        self.started = True
        return True

    def advance(self) -> None:
        """Paced mode: move every box on by one fieldbus cycle (20 ticks)."""
        self._advance()

    def _advance(self) -> None:
        if self.engine is not None:
            self.engine.advance(CYCLE_TICKS)
        else:
            for b in self.boxes:
                b.advance(CYCLE_TICKS)
        self.cycle = (self.cycle + 1) & 0xFF
        self.stats.cycles_advanced += 1
        if self.on_advance is not None:
            self.on_advance()

    def _process(self, d: ec.Datagram) -> ec.Datagram:
        if d.cmd != ec.Command.LRW:
            # Not addressed to any box: passes unchanged (no WKC).
            return d
        data = bytearray(d.data)
        wkc = self._serve(self._cover(d.lad, d.lad + len(data)), data, 0, d.wkc)
        return ec.Datagram(d.cmd, d.idx, d.adp, d.ado, bytes(data), wkc, d.irq,
                           d.circulating)

    def _answer(self, t: lrw.LrwTemplate, frame: bytes) -> bytes:
        """The reply to a frame that is exactly plan frame ``t`` (the general path's bytes:
        the frame with the boxes' inputs and the working counter put in, sealed again)."""
        pdu = bytearray(memoryview(frame)[:t.pdu_size])
        wkc = self._serve(self._cover(t.lad, t.lad + t.n), pdu, lrw.DATA_AT, t.wkc(frame))
        pdu[t.wkc_at:t.wkc_at + 2] = wkc.to_bytes(2, "little")
        return wire.seal(bytes(pdu), self.crc_trailer)

    def _cover(self, lo: int, hi: int) -> _Cover:
        """What an LRW datagram over the logical bytes [lo, hi) does (cached): per box it
        reaches, the outputs it carries whole (to apply) and the inputs it has whole room
        for (to fill), each as an offset in the data; the working counter it adds (2 per
        box with outputs it reaches, 1 per box with inputs, whole or not). The boxes the
        robot engine advances (and that apply and give their records as a StackBox does)
        become index arrays: their records move between the data and the engine's images
        in one array operation each way (:meth:`RobotEngine.applied_image`)."""
        cover = self._windows_of.get((lo, hi))
        if cover is not None:
            return cover
        ops, wkc = [], 0
        eng: dict[str, list] = {"boxes": [], "out_at": [], "out_to": [], "in_at": [],
                                "in_from": []}
        for n_box, w in enumerate(self.plan.windows):
            if w.end <= lo or w.lad >= hi:
                continue
            o = w.lad - lo
            out = in_at = None
            if w.out_len:
                if o >= 0 and w.lad + w.out_len <= hi:
                    out = (o, o + w.out_len)
                wkc += 2
            if w.in_len:
                i0 = w.lad + w.out_len
                if i0 >= lo and w.end <= hi:
                    in_at = (i0 - lo, w.end - lo)
                wkc += 1
            spans = self._engine_spans(self.boxes[n_box], w)
            if spans is None:
                ops.append((n_box, out, in_at))
                continue
            n_eng, (o_lo, o_hi), (i_lo, i_hi) = spans
            if out is not None:
                eng["boxes"].append(n_eng)
                eng["out_at"] += range(*out)
                eng["out_to"] += range(o_lo, o_hi)
            if in_at is not None:
                eng["in_at"] += range(*in_at)
                eng["in_from"] += range(i_lo, i_hi)
        arrays = {k: np.array(v, dtype=np.intp) for k, v in eng.items()}
        cover = self._windows_of[(lo, hi)] = _Cover(tuple(ops), wkc, **arrays)
        return cover

    def _engine_spans(self, box: object, w: Window
                      ) -> tuple[int, tuple[int, int], tuple[int, int]] | None:
        """The robot engine's number of ``box`` and its records' spans in the engine's
        images, if the engine advances it and it is a plain StackBox (no wrapper of its
        apply or inputs: a recording box keeps its own path)."""
        from hil.fieldbus.boxes import StackBox, _BoxBase

        if self.engine is None or getattr(box, "engine", None) is not self.engine:
            return None
        if getattr(getattr(box, "apply", None), "__func__", None) is not StackBox.apply or \
                getattr(getattr(box, "inputs", None), "__func__", None) is not _BoxBase.inputs:
            return None
        spans = self.engine.spans(box)
        if spans is None or spans[1][1] - spans[1][0] != w.out_len or \
                spans[2][1] - spans[2][0] != w.in_len:
            return None
        return spans

    def _serve(self, cover: _Cover, data: bytearray, at: int, wkc: int) -> int:
        """Each box of ``cover`` takes its outputs from and puts its inputs into the
        datagram data at ``data[at:]``, in chain order (the robot engine's boxes first,
        together: no box's inputs depend on another's outputs within a frame); the
        working counter after it."""
        boxes = self.boxes
        if len(boxes) != len(self.plan.windows):
            raise ValueError(f"{len(boxes)} boxes for the plan's {len(self.plan.windows)} "
                             "windows")
        if cover.boxes.size or cover.in_at.size:
            view = np.frombuffer(data, dtype=np.uint8)[at:]
            if cover.boxes.size:
                self.engine.applied_image(view, cover.out_at, cover.out_to, cover.boxes)
        for n_box, out, in_at in cover.ops:
            box = boxes[n_box]
            if out is not None:
                box.apply(bytes(data[at + out[0]:at + out[1]]))
            if in_at is not None:
                data[at + in_at[0]:at + in_at[1]] = box.inputs()
        if cover.in_at.size:
            view[cover.in_at] = self.engine.in_image[cover.in_from]
            del view  # (the bytearray may be resized again)
        return (wkc + cover.wkc) & 0xFFFF


@dataclass(frozen=True, eq=False)
class _Cover:
    """What a datagram over some logical bytes does: per box it reaches (chain order),
    ``(box index, (start, end) of its outputs or None, (start, end) of its inputs or None)``
    in the datagram's data, and the working counter it adds; for the boxes of the robot
    engine instead: their engine numbers (``boxes``, those whose outputs it carries), where
    their outputs are in the data and go in the engine's output image (``out_at``,
    ``out_to``), where their inputs go in the data and come from in its input image
    (``in_at``, ``in_from``)."""

    ops: tuple[tuple[int, tuple[int, int] | None, tuple[int, int] | None], ...]
    wkc: int
    boxes: np.ndarray
    out_at: np.ndarray
    out_to: np.ndarray
    in_at: np.ndarray
    in_from: np.ndarray
