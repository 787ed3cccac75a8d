"""The cyclic frame of one plan frame, built and recognised without the general codec.

Every cycle the master sends, and the chain answers, the same few frames: one LRW datagram
per frame at a fixed logical address and length (:class:`~hil.fieldbus.chain.CyclePlan`).
Such a frame differs from the next cycle's only in the datagram's ``idx``, its data, its
working counter (and the IRQ word a slave may set) and the CRC-32 trailer. An
:class:`LrwTemplate` holds the bytes that never change, encoded once by the codec
(:func:`protocols.ethercat.encode_pdu`), and:

* :meth:`LrwTemplate.build` writes a frame by putting ``idx`` and the data into them: the
  bytes ``encode_pdu`` gives for that datagram (tested equal);
* :meth:`LrwTemplate.match` says whether a received frame is exactly such a frame (length,
  every fixed byte, the trailer's CRC): then ``decode_pdu`` would give one LRW datagram at
  the template's address and length, with no error, so the caller may read ``idx``, data
  and working counter at their fixed offsets. Anything else (another address, a second
  datagram, a reserved bit, a circulating frame, a bad trailer) is left to the general
  codec, which classifies it as before.

A few slice operations per frame instead of the codec's field-by-field packing: the per-cycle
path of a whole-robot run (docs/robot-engine.md, "Where the time goes").
"""

from __future__ import annotations

import zlib

from hil.fieldbus import wire
from protocols import ethercat as ec

#: Offsets in the PDU: the datagram's idx, the start of its data (after the 2-byte EtherCAT
#: header and the 10-byte datagram header).
IDX_AT = ec.ECAT_HEADER.size + 1
DATA_AT = ec.ECAT_HEADER.size + ec.DATAGRAM_HEADER.size


class LrwTemplate:
    """Frames of one LRW datagram at logical address ``lad`` with ``n`` data bytes."""

    __slots__ = ("lad", "n", "crc_trailer", "size", "pdu_size", "_head", "_addr", "_buf",
                 "wkc_at")

    def __init__(self, lad: int, n: int, crc_trailer: bool = True) -> None:
        self.lad, self.n, self.crc_trailer = lad, n, crc_trailer
        pdu = ec.encode_pdu([ec.Datagram.logical(ec.Command.LRW, lad, bytes(n))])
        assert len(pdu) == DATA_AT + n + ec.DATAGRAM_TRAILER.size
        self.pdu_size = len(pdu)
        self.size = len(wire.seal(pdu, crc_trailer))
        #: The EtherCAT header and the command byte; the address and length word (the
        #: length word also holds the reserved, circulating and more bits, all 0 here).
        self._head = pdu[:IDX_AT]
        self._addr = pdu[IDX_AT + 1:IDX_AT + 7]
        self.wkc_at = DATA_AT + n
        self._buf = bytearray(pdu)  # the frame being built (IRQ and working counter 0)

    def build(self, idx: int, image: bytes | bytearray, wkc: int = 0) -> bytes:
        """The sealed frame of the datagram (``idx``, ``image[lad:lad + n]``, ``wkc``; IRQ
        0), as ``wire.seal(encode_pdu([Datagram.logical(LRW, lad, data, idx, wkc)]))``."""
        buf = self._buf
        buf[IDX_AT] = idx
        buf[DATA_AT:self.wkc_at] = image[self.lad:self.lad + self.n]
        buf[self.wkc_at:self.wkc_at + 2] = wkc.to_bytes(2, "little")
        return wire.seal(bytes(buf), self.crc_trailer)

    def match(self, frame: bytes) -> bool:
        """True if ``frame`` is this template's datagram, whole and undamaged (see the
        module's docstring); False: let the general codec read it."""
        if len(frame) != self.size or frame[:IDX_AT] != self._head \
                or frame[IDX_AT + 1:IDX_AT + 7] != self._addr:
            return False
        if self.crc_trailer:
            p = self.pdu_size
            return zlib.crc32(memoryview(frame)[:p]) == int.from_bytes(frame[p:], "little")
        return True

    def wkc(self, frame: bytes) -> int:
        """The working counter of a matched frame."""
        return int.from_bytes(frame[self.wkc_at:self.wkc_at + 2], "little")


def templates(frames: tuple[tuple[int, int, int], ...], crc_trailer: bool
              ) -> dict[int, list[tuple[int, LrwTemplate]]]:
    """The templates of a plan's frames (``(lad, length, wkc)``), by frame size:
    ``{size: [(index in the plan, template), ...]}``."""
    out: dict[int, list[tuple[int, LrwTemplate]]] = {}
    for k, (lad, n, _) in enumerate(frames):
        t = LrwTemplate(lad, n, crc_trailer)
        out.setdefault(t.size, []).append((k, t))
    return out


def find(by_size: dict[int, list[tuple[int, LrwTemplate]]], frame: bytes
         ) -> tuple[int, LrwTemplate] | None:
    """(plan index, template) of the plan frame ``frame`` is exactly, or None."""
    for k, t in by_size.get(len(frame), ()):
        if t.match(frame):
            return k, t
    return None
