"""A pcap tap for the bus system: every frame the master sends and reads, as EtherCAT over
Ethernet (EtherType 0x88A4), for Wireshark or tshark.

::

    cap = PcapTap()
    with BusSystem(topo, cfg, "inproc", tap=cap) as bs:
        bs.run(20, pc)
    cap.write("bus.pcap")      # tshark -r bus.pcap -T fields -e ecat.cmd -e ecat.cnt

The transports carry ``pdu || FCS`` (:mod:`hil.fieldbus.wire`); the capture holds the PDU
in an Ethernet II frame without FCS (as a NIC hands frames to libpcap), padded to the
60-byte minimum. Timestamps are simulated time: the cycle's tick times 50 us (the tick of
the configuration), from ``t0_ns`` (default 0, the epoch). Requests go from the master's
MAC to broadcast; replies come back with source :data:`CHAIN_MAC`. Frames the tap sees
after a fault (a corrupted reply) are written as they are: their PDU may be malformed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from hil.fieldbus.wire import FCS_BYTES
from protocols import ethercat as ec
from protocols.pcap import PcapRecord, build_pcap, write_pcap

#: Source MAC of the replies (the last box sends the frame back); locally administered.
CHAIN_MAC = bytes.fromhex("020000000002")


@dataclass(frozen=True)
class Captured:
    cycle: int
    tick: int
    direction: str  # "tx" (master -> chain) or "rx" (chain -> master)
    frame: bytes    # as on the transport: PDU + FCS


class PcapTap:
    """Use as ``BusSystem(..., tap=PcapTap())``; collects frames, writes a pcap.

    ``max_frames`` bounds the memory: frames beyond it are counted in :attr:`dropped`,
    not kept.
    """

    def __init__(self, tick_ns: int = 50_000, t0_ns: int = 0,
                 max_frames: int | None = None) -> None:
        self.tick_ns = tick_ns
        self.t0_ns = t0_ns
        self.max_frames = max_frames
        self.frames: list[Captured] = []
        self.dropped = 0

    def __call__(self, cycle: int, tick: int, frame: bytes, direction: str) -> None:
        if self.max_frames is not None and len(self.frames) >= self.max_frames:
            self.dropped += 1
            return
        self.frames.append(Captured(cycle, tick, direction, bytes(frame)))

    def ethernet(self, c: Captured) -> bytes:
        """The captured frame as an Ethernet II frame (FCS stripped)."""
        pdu = c.frame[:-FCS_BYTES] if len(c.frame) > FCS_BYTES else c.frame
        if c.direction == "tx":
            return ec.encode_ethernet(pdu, ec.BROADCAST_MAC, ec.DEFAULT_MASTER_MAC,
                                      ec.ETHERTYPE_ETHERCAT)
        return ec.encode_ethernet(pdu, ec.BROADCAST_MAC, CHAIN_MAC, ec.ETHERTYPE_ETHERCAT)

    def records(self) -> list[PcapRecord]:
        return [PcapRecord(self.t0_ns + c.tick * self.tick_ns, self.ethernet(c))
                for c in self.frames]

    def pcap_bytes(self) -> bytes:
        return build_pcap(self.records(), nanosecond=True)

    def write(self, path: str | os.PathLike[str]) -> int:
        """Write the capture (nanosecond pcap); returns the bytes written."""
        return write_pcap(path, self.records(), nanosecond=True)

    def clear(self) -> None:
        self.frames.clear()
        self.dropped = 0
