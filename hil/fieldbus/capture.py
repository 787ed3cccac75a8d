"""Captures of the fieldbus for Wireshark or tshark: every frame the master sends and reads.

:class:`CaptureWriter` streams frames to a ``.pcapng`` or ``.pcap`` file (written with
dpkt) as they would look on a wire: EtherCAT over Ethernet (EtherType 0x88A4), or, when the
transport carries the frames as UDP datagrams, EtherCAT over UDP/IPv4 between the real
addresses and ports (the chain on 34980 by default, which Wireshark decodes as EtherCAT
without options). ``eha-hil bus run --capture`` and ``eha-hil serve --capture`` use it::

    with CaptureWriter("bus.pcapng", crc_trailer=True) as cap:
        with BusSystem(topo, cfg, "inproc", tap=cap.tap(tick_ns=50_000)) as bs:
            bs.run(20, pc)
    # tshark -r bus.pcapng -T fields -e ecat.cmd -e ecat.idx -e ecat.lad -e ecat.cnt

:class:`PcapTap` is the in-memory variant (raw Ethernet, nanosecond classic pcap):

::

    cap = PcapTap()
    with BusSystem(topo, cfg, "inproc", tap=cap) as bs:
        bs.run(20, pc)
    cap.write("bus.pcap")      # tshark -r bus.pcap -T fields -e ecat.cmd -e ecat.cnt

The transports carry ``pdu`` or ``pdu || CRC-32`` (:mod:`hil.fieldbus.wire`); the tap holds
the PDU in an Ethernet II frame without FCS (as a NIC hands frames to libpcap), padded to the
60-byte minimum. Timestamps are simulated time: the cycle's tick times 50 us (the tick of
the configuration), from ``t0_ns`` (default 0, the epoch). Requests go from the master's
MAC to broadcast; replies come back with source :data:`CHAIN_MAC`. Frames the tap sees
after a fault (a corrupted reply) are written as they are: their PDU may be malformed.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from hil.fieldbus.wire import strip
from protocols import ethercat as ec
from protocols.pcap import PcapRecord, build_pcap, write_pcap

#: Source MAC of the replies (the last box sends the frame back); locally administered.
CHAIN_MAC = bytes.fromhex("020000000002")
#: File name endings :class:`CaptureWriter` writes, and the format of each.
CAPTURE_SUFFIXES = (".pcapng", ".pcap")
#: (address, port) of an end of a UDP link.
Endpoint = tuple[str, int]
#: The master's and the chain's UDP endpoints, or None for raw Ethernet.
Endpoints = tuple[Endpoint, Endpoint] | None


class CaptureError(Exception):
    """A capture file that cannot be written (one line)."""


def _section_header(metadata: dict[str, str] | None):
    """A little-endian pcapng section header naming eha-hil, with the metadata comment."""
    import json
    from importlib.metadata import PackageNotFoundError, version

    from dpkt import pcapng

    try:
        ours = version("eha-hil")
    except PackageNotFoundError:
        ours = "source"
    opts = [pcapng.PcapngOptionLE(code=pcapng.PCAPNG_OPT_SHB_USERAPPL, text=f"eha-hil {ours}")]
    if metadata is not None:
        opts.append(pcapng.PcapngOptionLE(code=pcapng.PCAPNG_OPT_COMMENT,
                                          text=json.dumps({"eha-hil": ours, **metadata})))
    opts.append(pcapng.PcapngOptionLE(code=pcapng.PCAPNG_OPT_ENDOFOPT))
    return pcapng.SectionHeaderBlockLE(opts=opts)


class CaptureWriter:
    """Fieldbus frames to a pcapng or pcap file, one :meth:`write` per frame.

    ``crc_trailer``: the frames carry the fieldbus CRC-32 trailer (:mod:`hil.fieldbus.wire`).
    On raw Ethernet it is cut off, as a NIC hands frames to libpcap without their FCS; in a
    UDP datagram it is part of the payload and stays. ``endpoints``: a callable giving the
    master's and the chain's (address, port) when the frames travel as UDP datagrams (asked
    per frame: a server learns its master's port from the first frame), or None for raw
    Ethernet. Timestamps are integer nanoseconds since the epoch (simulated time for
    ``bus run``, wall time for ``serve``), stored to the microsecond. ``metadata``
    (pcapng only): written as JSON, with ``"eha-hil"`` = the version, in the section
    header's comment (Wireshark: Statistics > Capture File Properties), so that ``eha-hil
    replay`` finds the topology, box model and configuration of the run.
    """

    def __init__(self, path: str | os.PathLike[str], crc_trailer: bool,
                 endpoints: Callable[[], Endpoints] | None = None,
                 metadata: dict[str, str] | None = None) -> None:
        import dpkt

        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in CAPTURE_SUFFIXES:
            raise CaptureError(f"{path}: a capture file name ends .pcapng or .pcap")
        self.crc_trailer = crc_trailer
        self.endpoints = endpoints or (lambda: None)
        self.frames = 0
        self._ident = 0
        try:
            self._fh: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise CaptureError(f"{path}: cannot write: {exc.strerror or exc}") from None
        if suffix == ".pcapng":
            self._writer = dpkt.pcapng.Writer(self._fh, snaplen=65535,
                                              shb=_section_header(metadata))
        else:
            self._writer = dpkt.pcap.Writer(self._fh, snaplen=65535)

    def packet(self, direction: str, frame: bytes) -> bytes:
        """The frame as it would be captured on a wire (Ethernet II, no FCS)."""
        tx = direction == "tx"
        src_mac = ec.DEFAULT_MASTER_MAC if tx else CHAIN_MAC
        ends = self.endpoints()
        if ends is None:
            return ec.encode_ethernet(strip(frame, self.crc_trailer), ec.BROADCAST_MAC,
                                      src_mac, ec.ETHERTYPE_ETHERCAT)
        master, chain = ends
        (src_ip, src_port), (dst_ip, dst_port) = (master, chain) if tx else (chain, master)
        self._ident = (self._ident + 1) & 0xFFFF
        ip = ec.encode_ipv4_udp(frame, src_ip, dst_ip, src_port, dst_port, ident=self._ident)
        dst_mac = CHAIN_MAC if tx else ec.DEFAULT_MASTER_MAC
        return ec.encode_ethernet(ip, dst_mac, src_mac, ec.ETHERTYPE_IPV4)

    def write(self, ts_ns: int, direction: str, frame: bytes) -> None:
        """Add one frame (``direction`` "tx": master -> chain, "rx": chain -> master)."""
        sec, ns = divmod(int(ts_ns), 1_000_000_000)
        # dpkt takes float seconds; whole seconds + microseconds keep it exact.
        self._writer.writepkt(self.packet(direction, frame), sec + (ns // 1000) / 1e6)
        self.frames += 1

    def tap(self, tick_ns: int, t0_ns: int = 0) -> Callable[[int, int, bytes, str], None]:
        """A ``BusSystem(tap=...)`` callback: frames stamped with the simulated time of
        their cycle (tick x ``tick_ns``, from ``t0_ns``)."""

        def tap(cycle: int, tick: int, frame: bytes, direction: str) -> None:
            self.write(t0_ns + tick * tick_ns, direction, frame)

        return tap

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Captured:
    cycle: int
    tick: int
    direction: str  # "tx" (master -> chain) or "rx" (chain -> master)
    frame: bytes    # as on the transport: the PDU (+ the CRC-32 trailer if the link has it)


class PcapTap:
    """Use as ``BusSystem(..., tap=PcapTap())``; collects frames, writes a pcap.

    ``max_frames`` bounds the memory: frames beyond it are counted in :attr:`dropped`,
    not kept. ``crc_trailer``: the frames carry the CRC-32 trailer (cut off in the
    capture); pass ``BusSystem.crc_trailer`` (False on udp by default).
    """

    def __init__(self, tick_ns: int = 50_000, t0_ns: int = 0,
                 max_frames: int | None = None, crc_trailer: bool = True) -> None:
        self.crc_trailer = crc_trailer
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
        pdu = strip(c.frame, self.crc_trailer)
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
