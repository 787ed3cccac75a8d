"""A minimal EtherCAT master over the ESC chain in this process, for tests and the
benchmark: the start-up steps a real master takes (count the slaves, set station
addresses, read the SII through the EEPROM interface, program sync managers and FMMUs
from it, walk INIT -> PREOP -> SAFEOP -> OP) and cyclic LRW frames. Real masters (SOEM
through pysoem) are tested against the chain over a veth pair (tests/fieldbus).

The process image is SOEM's layout: every slave's outputs, then every slave's inputs;
LRW datagrams cover it in pieces of at most :data:`MAX_LRW` bytes, one per frame, cut
at slave boundaries.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from firmware_model.esc import registers as r
from firmware_model.esc import sii
from hil.fieldbus.esc.chain import EscChain
from protocols import ethercat as ec

MAX_LRW = ec.MAX_DATAGRAM_DATA
STATION_BASE = 0x1001


class BringUpError(Exception):
    """A slave refused a step of the start-up; the message names slave and step."""


@dataclass
class SlaveMap:
    station: int
    out_lad: int
    out_len: int
    in_lad: int
    in_len: int


class EscMaster:
    """Frames through ``chain.handle`` (Ethernet frames, as on the wire)."""

    def __init__(self, chain: EscChain) -> None:
        self.chain = chain
        self.idx = 0
        self.slaves: list[SlaveMap] = []
        self.image = bytearray()
        self.pieces: list[tuple[int, int]] = []  # (lad, length) of each cyclic frame
        self.expected_wkc = 0

    def exchange(self, datagrams: list[ec.Datagram]) -> list[ec.Datagram]:
        """One frame out and back; the datagrams as they returned."""
        reply = self.chain.handle(ec.encode_frame(datagrams))
        if reply is None:
            raise BringUpError("frame dropped by the chain")
        return ec.decode_frame(reply)

    def one(self, cmd: int, adp: int, ado: int, data: bytes) -> ec.Datagram:
        self.idx = (self.idx + 1) & 0xFF
        return self.exchange([ec.Datagram(cmd, self.idx, adp, ado, data)])[0]

    def _eeprom(self, station: int, start: int, words: int) -> bytes:
        out = bytearray()
        for a in range(start, start + words, 4):
            self.one(ec.Command.FPWR, station, r.EEP_CONTROL,
                     struct.pack("<HI", r.EEP_CMD_READ, a))
            out += self.one(ec.Command.FPRD, station, r.EEP_DATA, bytes(8)).data
        return bytes(out)

    def _read_sii(self, station: int) -> bytes:
        """The SII image, read 0x40 words at a time until the categories' end marker."""
        image = bytearray()
        while len(image) < 0x4000:
            image += self._eeprom(station, len(image) // 2, 0x40)
            p = 0x80
            while p + 4 <= len(image):
                kind, size = struct.unpack_from("<HH", image, p)
                if kind == sii.CAT_END:
                    return bytes(image)
                p += 4 + 2 * size
        raise BringUpError(f"station {station:#06x}: SII has no end marker")

    def set_state(self, station: int, state: int) -> tuple[int, int]:
        """Request ``state``; (AL status, AL status code) after the request."""
        self.one(ec.Command.FPWR, station, r.AL_CONTROL, struct.pack("<H", state))
        st = self.one(ec.Command.FPRD, station, r.AL_STATUS, bytes(6)).data
        return struct.unpack_from("<H", st)[0], struct.unpack_from("<H", st, 4)[0]

    def bring_up(self, to_op: bool = True) -> None:
        self.one(ec.Command.BWR, 0, r.AL_CONTROL, struct.pack("<H", 0x11))
        n = self.one(ec.Command.BRD, 0, r.TYPE, bytes(2)).wkc
        sizes = []
        for k in range(n):
            station = STATION_BASE + k
            self.one(ec.Command.APWR, (-k) & 0xFFFF, r.STATION_ADDRESS,
                     struct.pack("<H", station))
            image = self._read_sii(station)
            cats = sii.categories(image)
            syncm = cats[sii.CAT_SYNCM]
            self.one(ec.Command.FPWR, station, r.SM0, syncm[:8 * r.N_SM])
            sizes.append((station, sii.pdo_bits(image, sii.CAT_RXPDO) // 8,
                          sii.pdo_bits(image, sii.CAT_TXPDO) // 8, syncm))
            self.set_state(station, r.AlState.PREOP)
        lad = 0
        outs = []
        for _station, nout, _nin, _ in sizes:
            outs.append(lad)
            lad += nout
        for (station, nout, nin, syncm), out_lad in zip(sizes, outs, strict=True):
            # the process data's sync managers: SyncM entries of type 3 (outputs), 4 (inputs)
            kinds = [syncm[8 * k + 7] for k in range(len(syncm) // 8)]
            o_k = kinds.index(sii.SM_OUTPUTS) if sii.SM_OUTPUTS in kinds else 0
            i_k = kinds.index(sii.SM_INPUTS) if sii.SM_INPUTS in kinds else 1
            o_phys = struct.unpack_from("<H", syncm, 8 * o_k)[0]
            i_phys = struct.unpack_from("<H", syncm, 8 * i_k)[0]
            fmmus = struct.pack("<IHBBHBBB3x", out_lad, nout, 0, 7, o_phys, 0,
                                r.FMMU_WRITE, 1 if nout else 0)
            fmmus += struct.pack("<IHBBHBBB3x", lad, nin, 0, 7, i_phys, 0, r.FMMU_READ, 1)
            self.one(ec.Command.FPWR, station, r.FMMU0, fmmus)
            self.slaves.append(SlaveMap(station, out_lad, nout, lad, nin))
            self.expected_wkc += (2 if nout else 0) + (1 if nin else 0)
            lad += nin
        self.image = bytearray(lad)
        # Frames split at slave boundaries (as SOEM's segments): no slave in two frames.
        ends = sorted({s.out_lad + s.out_len for s in self.slaves}
                      | {s.in_lad + s.in_len for s in self.slaves})
        start = prev = 0
        for end in ends:
            if end - start > MAX_LRW:
                self.pieces.append((start, prev - start))
                start = prev
            prev = end
        self.pieces.append((start, lad - start))
        if not to_op:
            return
        for state in (r.AlState.SAFEOP, r.AlState.OP):
            for s in self.slaves:
                status, code = self.set_state(s.station, state)
                if status != state:
                    raise BringUpError(f"station {s.station:#06x}: {state.name} refused, "
                                       f"AL status {status:#06x} code {code:#06x}")

    def cycle(self) -> int:
        """One cyclic exchange (every LRW piece); the summed working counter."""
        wkc = 0
        for lad, n in self.pieces:
            self.idx = (self.idx + 1) & 0xFF
            d = self.exchange([ec.Datagram.logical(ec.Command.LRW, lad,
                                                   bytes(self.image[lad:lad + n]), self.idx)])[0]
            wkc += d.wkc
            for s in self.slaves:  # take the inputs back
                lo, hi = max(s.in_lad, lad), min(s.in_lad + s.in_len, lad + n)
                if lo < hi:
                    self.image[lo:hi] = d.data[lo - lad:hi - lad]
        return wkc
