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

from hil.fieldbus import wire
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

    def handle(self, frame: bytes) -> bytes | None:
        """Process one frame; the reply, or None if the frame was discarded."""
        dgs = wire.open_frame(frame, self.crc_trailer)
        if dgs is None:
            self.stats.bad_frames += 1
            return None
        self.stats.frames += 1
        idx = dgs[0].idx
        if self.paced:
            if self.started and (idx - self.last_idx) & 0xFF >= 128:
                self.stats.stale_frames += 1
                return None
            self.last_idx = idx
        elif self.started:
            ahead = (idx - self.cycle) & 0xFF
            if ahead >= 128:
                self.stats.stale_frames += 1
                return None
            for _ in range(ahead):
                self._advance()
        self.started = True
        out = [self._process(d) for d in dgs]
        return wire.seal(ec.encode_pdu(out), self.crc_trailer)

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
        lo, data = d.lad, bytearray(d.data)
        hi = lo + len(data)
        wkc = d.wkc
        for w, box in zip(self.plan.windows, self.boxes, strict=True):
            if w.end <= lo or w.lad >= hi:
                continue
            o = w.lad - lo
            if w.out_len:
                if o >= 0 and w.lad + w.out_len <= hi:
                    box.apply(bytes(data[o:o + w.out_len]))
                wkc += 2
            if w.in_len:
                i0 = w.lad + w.out_len
                if i0 >= lo and w.end <= hi:
                    data[i0 - lo:w.end - lo] = box.inputs()
                wkc += 1
        return ec.Datagram(d.cmd, d.idx, d.adp, d.ado, bytes(data), wkc & 0xFFFF, d.irq,
                           d.circulating)
