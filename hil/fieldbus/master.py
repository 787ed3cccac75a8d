"""The fieldbus master (PC side): one cyclic logical read-write per millisecond.

The master keeps the process image (outputs it writes, inputs it read), builds the cycle's
frames from the :class:`~hil.fieldbus.chain.CyclePlan` (one LRW datagram per frame, the
cycle number mod 256 in ``idx``), and checks every reply: a frame with a bad FCS, from
another cycle, or with a working counter other than the plan's is counted and its inputs
are NOT applied (the previous cycle's stay, marked stale). A frame that does not come back
within the timeout is counted as lost.
"""

from __future__ import annotations

import struct
from dataclasses import asdict, dataclass

import numpy as np

from hil.fieldbus import lrw, pdo, wire
from hil.fieldbus.chain import CyclePlan
from hil.fieldbus.pdo_compiled import put_commands
from hil.fieldbus.topology import Topology
from protocols import ethercat as ec

#: The actuator output record as one struct (the same bytes as pdo.ACTUATOR_OUT_DTYPE).
_OUT = struct.Struct("<" + "".join({"u1": "B", "u2": "H", "i2": "h", "i4": "i"}[f.dtype]
                                   for f in pdo.ACTUATOR_OUT))
assert _OUT.size == pdo.ACTUATOR_OUT_DTYPE.itemsize


@dataclass
class MasterStats:
    cycles: int = 0
    frames_sent: int = 0
    frames_ok: int = 0
    wkc_errors: int = 0      # reply with the wrong working counter: inputs not applied
    bad_frames: int = 0      # CRC trailer/PDU failure: discarded
    stale_frames: int = 0    # reply from another cycle (delayed/duplicated): discarded
    lost_frames: int = 0     # no reply of this cycle came back for the frame (or only bad ones)

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class Master:
    """Process image and frame handling; no I/O of its own (the bus system moves frames)."""

    def __init__(self, topo: Topology, crc_trailer: bool = True) -> None:
        self.topology = topo
        #: Frames carry the CRC-32 trailer (:mod:`hil.fieldbus.wire`); replies must too.
        self.crc_trailer = crc_trailer
        self.plan = CyclePlan.build(topo)
        self.image = bytearray(self.plan.image_bytes)
        self.stats = MasterStats()
        self.cycle = 0
        #: Per actuator (chain order): (output offset, input offset) in the image.
        self.act_offsets: list[tuple[int, int]] = []
        self.names = topo.actuator_names()
        for w, box in zip(self.plan.windows, topo.boxes, strict=True):
            o, i = w.lad, w.lad + w.out_len
            for s in box.slots:
                so, si = s.sizes
                if s.kind == "actuator":
                    self.act_offsets.append((o, i))
                o += so
                i += si
        self._out_starts: np.ndarray | None = None  # image byte of each output record
        self._image_u8: np.ndarray | None = None
        #: Per frame of the plan: did its inputs arrive this cycle?
        self.fresh = [False] * len(self.plan.frames)
        self._answered = [False] * len(self.plan.frames)
        self._frame_of_actuator = [self._frame_index(i) for _, i in self.act_offsets]
        #: The plan's frames as templates (hil.fieldbus.lrw): built and read by slices.
        self._templates = lrw.templates(self.plan.frames, crc_trailer)
        self._built = [t for k, t in sorted(
            (kt for kts in self._templates.values() for kt in kts), key=lambda kt: kt[0])]
        #: Per frame of the plan: the input windows it carries whole, as (image start,
        #: image end, start in the datagram's data).
        self._inputs_of = [[(w.lad + w.out_len, w.end, w.lad + w.out_len - lad)
                            for w in self.plan.windows
                            if lad <= w.lad + w.out_len and w.end <= lad + n and w.in_len]
                           for lad, n, _ in self.plan.frames]

    def _frame_index(self, offset: int) -> int:
        for k, (lad, n, _) in enumerate(self.plan.frames):
            if lad <= offset < lad + n:
                return k
        raise AssertionError(offset)

    # --- outputs -------------------------------------------------------------------------
    def set_actuator(self, j: int, mode: str, value: float, enable: bool = True,
                     clear_fault: bool = False, kp_position: float = 0.0,
                     kp_force: float = 0.0) -> None:
        """Output record of actuator ``j``: mode "off"/"force" (N)/"position" (m)."""
        if mode not in pdo.MODE_CODES:
            raise ValueError(f"unknown mode {mode!r}")
        lsb = pdo.POSITION_CMD_LSB if mode == "position" else pdo.FORCE_CMD_LSB
        # One struct pack (the PC loop sets every actuator every cycle).
        _OUT.pack_into(self.image, self.act_offsets[j][0], pdo.MODE_CODES[mode],
                       (pdo.FLAG_ENABLE if enable else 0)
                       | (pdo.FLAG_CLEAR_FAULT if clear_fault else 0),
                       pdo.to_counts(value, lsb, "i4"),
                       pdo.to_counts(kp_position, 10.0, "u2") if kp_position else 0,
                       pdo.to_counts(kp_force, 1e-3, "u2") if kp_force else 0)

    def set_actuators(self, mode: str, values: np.ndarray, enable: bool = True) -> None:
        """Output records of every actuator at once, as :meth:`set_actuator` writes each
        (``values[j]`` for actuator ``j``, same rounding and saturation; no gains sent):
        one compiled call instead of a Python call per actuator, for PC loops that
        command the whole robot every cycle."""
        if mode not in pdo.MODE_CODES:
            raise ValueError(f"unknown mode {mode!r}")
        values = np.asarray(values, dtype=np.float64)
        n = len(self.act_offsets)
        if values.shape != (n,):
            raise ValueError(f"values: expected {n} actuator commands, got shape {values.shape}")
        if self._out_starts is None:
            self._out_starts = np.array([o for o, _ in self.act_offsets], dtype=np.intp)
            self._image_u8 = np.frombuffer(self.image, dtype=np.uint8)  # (never resized)
        lsb = pdo.POSITION_CMD_LSB if mode == "position" else pdo.FORCE_CMD_LSB
        lo, hi = pdo.I4_BOUNDS
        # one compiled call: pdo.to_counts of each value, the record's bytes in the image
        if not put_commands(self._image_u8, self._out_starts, pdo.MODE_CODES[mode],
                            pdo.FLAG_ENABLE if enable else 0, values, lsb, lo, hi):
            raise ValueError("values: a command is not finite")

    # --- inputs ---------------------------------------------------------------------------
    def actuator_inputs(self, j: int) -> dict[str, float]:
        """Latest inputs of actuator ``j`` in SI units (plus ``fresh``: this cycle's?)."""
        i = self.act_offsets[j][1]
        rec = np.frombuffer(bytes(self.image[i:i + pdo.ACTUATOR_IN_DTYPE.itemsize]),
                            dtype=pdo.ACTUATOR_IN_DTYPE)[0]
        out = {f.name: float(rec[f.name]) * (f.lsb if f.lsb else 1.0) for f in pdo.ACTUATOR_IN}
        for f in ("status", "err_link_down", "err_link_up"):
            out[f] = int(rec[f])
        out["fresh"] = self.fresh[self._frame_of_actuator[j]]
        return out

    # --- frames ---------------------------------------------------------------------------
    def frames(self) -> list[bytes]:
        """This cycle's sealed frames (call once per cycle, then :meth:`receive` replies)."""
        self.fresh = [False] * len(self.plan.frames)
        self._answered = [False] * len(self.plan.frames)
        idx = self.cycle & 0xFF
        # the bytes of wire.seal(ec.encode_pdu([ec.Datagram.logical(LRW, lad, data, idx)]))
        out = [t.build(idx, self.image) for t in self._built]
        self.stats.frames_sent += len(out)
        return out

    def receive(self, frame: bytes) -> bool:
        """Check one reply; apply its inputs if it is good. True if applied."""
        known = lrw.find(self._templates, frame)
        if known is not None:  # exactly one of the plan's frames: read it by slices
            k, t = known
            if frame[lrw.IDX_AT] != self.cycle & 0xFF:
                self.stats.stale_frames += 1
                return False
            return self._apply_reply(k, t.wkc(frame), frame, lrw.DATA_AT)
        dgs = wire.open_frame(frame, self.crc_trailer)
        if dgs is None or len(dgs) != 1 or dgs[0].cmd != ec.Command.LRW:
            self.stats.bad_frames += 1
            return False
        d = dgs[0]
        if d.idx != self.cycle & 0xFF:
            self.stats.stale_frames += 1
            return False
        for k, (lad, n, wkc) in enumerate(self.plan.frames):  # noqa: B007 (used after break)
            if d.lad == lad and len(d.data) == n:
                break
        else:
            self.stats.bad_frames += 1
            return False
        return self._apply_reply(k, d.wkc, d.data, 0)

    def _apply_reply(self, k: int, wkc: int, buf: bytes, at: int) -> bool:
        """The reply to plan frame ``k`` of this cycle (its working counter ``wkc``, its
        data at ``buf[at:]``): counted, and its inputs applied if it is the first and its
        working counter is the plan's."""
        if self._answered[k]:
            self.stats.stale_frames += 1  # a duplicate of a reply already seen
            return False
        self._answered[k] = True
        if wkc != self.plan.frames[k][2]:
            self.stats.wkc_errors += 1
            return False
        image = self.image
        for i0, end, o in self._inputs_of[k]:
            image[i0:end] = buf[at + o:at + o + end - i0]
        self.fresh[k] = True
        self.stats.frames_ok += 1
        return True

    def end_cycle(self) -> None:
        """Count the frames that did not come back and move to the next cycle."""
        self.stats.lost_frames += self._answered.count(False)
        self.stats.cycles += 1
        self.cycle += 1

    def input_image(self) -> bytes:
        """The input part of the image (all windows' inputs, concatenated), for records."""
        return b"".join(bytes(self.image[w.lad + w.out_len:w.end]) for w in self.plan.windows)
