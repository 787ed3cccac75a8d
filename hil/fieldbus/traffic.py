"""Fieldbus traffic read back from files other tools write and open: Wireshark captures
(pcapng and classic pcap, read with dpkt) and CAN logs (BLF, ASC, candump ``.log``, read
with ``can.LogReader``).

Both become a list of :class:`BusFrame`: the EtherCAT PDU of each frame with its time and
direction (``tx``: master -> chain, ``rx``: chain -> master), for ``eha-hil log info``
(:func:`summary`) and ``eha-hil replay`` (:mod:`hil.fieldbus.traffic_replay`).

Captures: Ethernet link type; EtherCAT directly over Ethernet (EtherType 0x88A4) or over
UDP/IPv4. A UDP datagram is taken as EtherCAT when either port is 34980 or its payload
decodes as an EtherCAT PDU. The UDP checksum is checked where it can be and reported, but
not required: a capture taken on the sending host (``dumpcap -i lo``) holds datagrams whose
checksum was left to the NIC (checksum offload), as Wireshark notes, and a zero checksum
means none was computed (RFC 768). After the PDU a UDP payload may hold the fieldbus CRC-32
trailer (``--crc-trailer``), which is checked. Direction of raw Ethernet frames, from the
frames themselves (:func:`_ethernet_directions`): frames from the chain's MAC
(:data:`hil.fieldbus.capture.CHAIN_MAC`, our captures) are replies; else, when a source MAC
comes back with bit 1 of its first octet set (what an ESC does to the frames it returns),
those are the replies and the master's own MAC the requests; else a frame is paired with
the one before it that carries the same datagrams (command, index, offset, length: a
reply's working counter and data differ from its request's, auto-increment addresses too),
and a frame left without a partner is of unknown direction. Over UDP, datagrams to the
chain's port (34980, or the port common to every datagram) are requests.

CAN logs: the segments on the master's CAN ID (``base_id``, default 0x100) and the
chain's (``base_id + 1``) are reassembled (:func:`hil.transports.canlog.reassemble`); a
frame's CRC-32 trailer, if it has one, is checked.
"""

from __future__ import annotations

import json
import os
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from hil.fieldbus.capture import CHAIN_MAC
from hil.fieldbus.wire import FCS_BYTES
from protocols import ethercat as ec
from protocols.errors import CodecError, CrcError

CAPTURE_SUFFIXES = (".pcapng", ".pcap")
CAN_LOG_SUFFIXES = (".blf", ".asc", ".log")
#: Every file name ending this module reads.
TRAFFIC_SUFFIXES = CAPTURE_SUFFIXES + CAN_LOG_SUFFIXES
_PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
_PCAP_MAGICS = {bytes.fromhex(m) for m in ("d4c3b2a1", "a1b2c3d4", "4d3cb2a1", "a1b23c4d")}
_LINKTYPE_ETHERNET = 1


class TrafficError(Exception):
    """A capture or CAN log that cannot be read (one line, naming the file)."""


def is_traffic_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a capture or CAN log (by its ending)."""
    return Path(path).suffix.lower() in TRAFFIC_SUFFIXES


@dataclass(frozen=True)
class BusFrame:
    """One fieldbus frame of a capture or CAN log."""

    ts_ns: int
    direction: str | None          # "tx", "rx", or None when it cannot be told
    pdu: bytes | None              # the EtherCAT PDU (header + datagrams), None if malformed
    datagrams: tuple[ec.Datagram, ...] = ()
    carrier: str = "ethernet"      # "ethernet", "udp" or "can"
    crc_trailer: bool = False      # the frame carried the fieldbus CRC-32 trailer (good)
    udp_checksum: str | None = None  # "good", "none" (zero), "offloaded" (not filled in)
    error: str | None = None       # why the frame is malformed


@dataclass
class Traffic:
    """What a file held: its frames and what was not a fieldbus frame."""

    path: str
    kind: str                      # "pcapng", "pcap", "blf", "asc", "log"
    frames: list[BusFrame] = field(default_factory=list)
    other_packets: int = 0         # packets / CAN messages that are no fieldbus frame
    packets: int = 0               # packets or CAN messages in the file
    notes: list[str] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)  # from a pcapng comment
    can_errors: dict[str, int] = field(default_factory=dict)
    #: why the file ends early (cut by a killed writer, a full disk, a copy), None if whole;
    #: reported by :func:`hil.cli.cutfiles.line` with how far it was read
    cut: str | None = None

    @property
    def read_until_s(self) -> float | None:
        """Time of the last frame read from the first (for a cut file: how far it reads),
        s: captures of ``bus run`` count from the run's start, CAN logs in wall time."""
        if not self.frames:
            return None
        times = [f.ts_ns for f in self.frames]
        return (max(times) - min(times)) / 1e9


def _pdu(payload: bytes, exact: bool) -> tuple[bytes, list[ec.Datagram], int]:
    """(PDU, datagrams, bytes after it); ``exact``: padding is not allowed (UDP, CAN)."""
    dgs = ec.decode_pdu(payload, allow_trailing=True)
    end = 2 + sum(d.size for d in dgs)
    return payload[:end], dgs, (len(payload) - end if exact else 0)


def _with_trailer(payload: bytes) -> tuple[bytes, list[ec.Datagram], bool]:
    """Decode a payload that is a bare PDU or a PDU plus a good CRC-32 trailer."""
    pdu, dgs, extra = _pdu(payload, exact=True)
    if extra == 0:
        return pdu, dgs, False
    if extra == FCS_BYTES:
        if (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") == payload[len(pdu):]:
            return pdu, dgs, True
        raise CodecError("CRC-32 trailer wrong")
    raise CodecError(f"{extra} bytes after the EtherCAT PDU")


# --- captures --------------------------------------------------------------------------------
def _open_capture(path: str, fh):
    import dpkt

    head = fh.read(4)
    fh.seek(0)
    try:
        if head == _PCAPNG_MAGIC:
            return "pcapng", dpkt.pcapng.Reader(fh)
        if head in _PCAP_MAGICS:
            return "pcap", dpkt.pcap.Reader(fh)
    except (ValueError, dpkt.dpkt.Error, EOFError) as exc:
        raise TrafficError(f"{path}: damaged capture header: {exc}") from None
    raise TrafficError(f"{path}: not a pcap or pcapng capture (starts {head.hex() or 'empty'})")


def _pcapng_comment(path: str) -> dict[str, str]:
    """The eha-hil metadata a :class:`~hil.fieldbus.capture.CaptureWriter` put in the
    section header's comment (JSON), or {}."""
    import dpkt

    with open(path, "rb") as fh:
        head = fh.read(8)
        if len(head) < 8 or head[:4] != _PCAPNG_MAGIC:
            return {}
        size = int.from_bytes(head[4:8], "little")
        head += fh.read(max(0, size - 8))
    try:
        shb = dpkt.pcapng.SectionHeaderBlockLE(head)
    except (dpkt.dpkt.Error, ValueError):
        return {}
    for opt in getattr(shb, "opts", []):
        if opt.code == dpkt.pcapng.PCAPNG_OPT_COMMENT:
            try:
                data = json.loads(opt.text)
            except (ValueError, TypeError):
                continue
            if isinstance(data, dict) and "eha-hil" in data:
                return {str(k): str(v) for k, v in data.items()}
    return {}


def _classify_ip(eth: ec.EthernetFrame, ts_ns: int) -> tuple[ec.UdpDatagram | None, BusFrame]:
    try:
        udp = ec.decode_ipv4_udp(eth.payload, allow_trailing=True)
        checksum = "good"
    except CrcError:
        # The IPv4 header checksum is always filled in; a wrong UDP one is offload.
        udp = ec.decode_ipv4_udp(eth.payload, allow_trailing=True, check_udp_checksum=False)
        checksum = "offloaded"
    ihl = (eth.payload[0] & 0x0F) * 4
    if eth.payload[ihl + 6:ihl + 8] == b"\x00\x00":
        checksum = "none"
    try:
        pdu, dgs, trailer = _with_trailer(udp.payload)
        return udp, BusFrame(ts_ns, None, pdu, tuple(dgs), "udp", trailer, checksum)
    except CodecError as exc:
        return udp, BusFrame(ts_ns, None, None, (), "udp", False, checksum, str(exc))


def read_capture(path: str | os.PathLike[str]) -> Traffic:
    """The fieldbus frames of a pcap or pcapng file."""
    import dpkt

    path = str(path)
    try:
        fh = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise TrafficError(f"{path}: {exc.strerror or exc}") from None
    with fh:
        kind, reader = _open_capture(path, fh)
        out = Traffic(path, kind)
        if reader.datalink() != _LINKTYPE_ETHERNET:
            raise TrafficError(f"{path}: link type {reader.datalink()} is not Ethernet (1); "
                               "capture on an Ethernet or loopback interface")
        udp_frames: list[tuple[int, ec.UdpDatagram]] = []
        eth_frames: list[tuple[int, bytes]] = []
        try:
            for ts, buf in reader:
                out.packets += 1
                ts_ns = int(round(float(ts) * 1e6)) * 1000
                frame = _read_packet(bytes(buf), ts_ns, out, udp_frames, eth_frames)
                if frame is not None:
                    out.frames.append(frame)
        except (dpkt.dpkt.Error, ValueError, EOFError, IndexError) as exc:
            size = os.path.getsize(path)
            why = "the file ends inside a block" if isinstance(
                exc, dpkt.dpkt.NeedData) else f"{type(exc).__name__} {exc}".strip()
            out.cut = f"{why} after packet {out.packets} ({size} bytes)"
        else:
            # dpkt stops quietly at a cut block header and skips a cut block of a kind it
            # does not read: the file's own framing says whether it is whole
            end = _framing_end(path, kind)
            size = os.path.getsize(path)
            if end < size:
                out.cut = (f"the file ends inside a block at byte {end} of {size} (after "
                           f"packet {out.packets})")
    if kind == "pcapng":
        out.metadata = _pcapng_comment(path)
    _udp_directions(out, udp_frames)
    _ethernet_directions(out, eth_frames)
    return out


def _framing_end(path: str, kind: str) -> int:
    """Where the last whole block (pcapng: length at +4, repeated at its end) or record
    (pcap: 16-byte header with the captured length at +8) of a capture ends."""
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(24)
        little = head[:4] in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1") or (
            kind == "pcapng" and head[8:12] == b"\x4d\x3c\x2b\x1a")
        order = "little" if little else "big"
        pos = 0 if kind == "pcapng" else 24
        while pos < size:
            fh.seek(pos)
            hdr = fh.read(16 if kind == "pcap" else 8)
            if kind == "pcap":
                if len(hdr) < 16:
                    return pos
                step = 16 + int.from_bytes(hdr[8:12], order)
            else:
                if len(hdr) < 8:
                    return pos
                step = int.from_bytes(hdr[4:8], order)
                if step < 12 or pos + step > size:
                    return pos
                fh.seek(pos + step - 4)
                if int.from_bytes(fh.read(4), order) != step:
                    return pos
            if pos + step > size:
                return pos
            pos += step
    return pos


def _read_packet(buf: bytes, ts_ns: int, out: Traffic,
                 udp_frames: list[tuple[int, ec.UdpDatagram]],
                 eth_frames: list[tuple[int, bytes]]) -> BusFrame | None:
    try:
        eth = ec.decode_ethernet(buf)
    except CodecError:
        out.other_packets += 1
        return None
    if eth.ethertype == ec.ETHERTYPE_ETHERCAT:
        direction = None  # set by _ethernet_directions once every frame is read
        eth_frames.append((len(out.frames), bytes(eth.src)))
        try:
            pdu, dgs, _ = _pdu(eth.payload, exact=False)  # Ethernet pads short frames
            return BusFrame(ts_ns, direction, pdu, tuple(dgs))
        except CodecError as exc:
            return BusFrame(ts_ns, direction, None, error=str(exc))
    if eth.ethertype != ec.ETHERTYPE_IPV4:
        out.other_packets += 1
        return None
    try:
        udp, frame = _classify_ip(eth, ts_ns)
    except CodecError:
        out.other_packets += 1  # not UDP, or a broken IP header
        return None
    ecat_port = ec.UDP_PORT_ETHERCAT in (udp.src_port, udp.dst_port)
    if frame.error is not None and not ecat_port:
        out.other_packets += 1  # some other UDP traffic
        return None
    udp_frames.append((len(out.frames), udp))
    return frame


def _udp_directions(out: Traffic, udp_frames: list[tuple[int, ec.UdpDatagram]]) -> None:
    """Requests go to the chain's port: 34980 if every datagram has it, else the one port
    every datagram shares (the first datagram's destination if both do: a master speaks
    first)."""
    if not udp_frames:
        return
    ports = [{u.src_port, u.dst_port} for _, u in udp_frames]
    common = set.intersection(*ports)
    if ec.UDP_PORT_ETHERCAT in common:
        chain = ec.UDP_PORT_ETHERCAT
    elif len(common) == 1:
        chain = next(iter(common))
    elif udp_frames[0][1].dst_port in common:
        chain = udp_frames[0][1].dst_port
    else:
        chain = None
    if chain is None:
        out.notes.append("UDP: no port common to every datagram, directions unknown")
        return
    for i, u in udp_frames:
        f = out.frames[i]
        direction = "tx" if u.dst_port == chain else "rx"
        out.frames[i] = BusFrame(f.ts_ns, direction, f.pdu, f.datagrams, f.carrier,
                                 f.crc_trailer, f.udp_checksum, f.error)


def _ethernet_directions(out: Traffic, eth_frames: list[tuple[int, bytes]]) -> None:
    """Directions of the raw Ethernet EtherCAT frames (see the module docstring)."""
    if not eth_frames:
        return
    macs = {src for _, src in eth_frames}
    direction: dict[int, str | None] = {}
    if CHAIN_MAC in macs:  # our own capture: the chain's MAC replies, all else asks
        direction = {i: "rx" if src == CHAIN_MAC else "tx" for i, src in eth_frames}
    else:
        returned = {m for m in macs if m[0] & 0x02 and bytes([m[0] & ~0x02]) + m[1:] in macs}
        senders = {bytes([m[0] & ~0x02]) + m[1:] for m in returned}
        rest = []
        for i, src in eth_frames:
            if src in returned:
                direction[i] = "rx"
            elif src in senders:
                direction[i] = "tx"
            else:
                rest.append(i)
        direction.update(_paired_directions(out.frames, rest))
    unpaired = sum(1 for d in direction.values() if d is None)
    for i, _ in eth_frames:
        f = out.frames[i]
        out.frames[i] = BusFrame(f.ts_ns, direction.get(i), f.pdu, f.datagrams, f.carrier,
                                 f.crc_trailer, f.udp_checksum, f.error)
    if unpaired:
        out.notes.append(f"{unpaired} EtherCAT frame(s) without a request/reply partner: "
                         "direction unknown")


def _paired_directions(frames: list[BusFrame], indexes: list[int]) -> dict[int, str | None]:
    """Request/reply by pairing: a frame whose datagrams (command, index, register offset,
    data length) are those of an earlier frame still waiting is that frame's reply."""
    waiting: dict[tuple, list[int]] = {}
    out: dict[int, str | None] = {}
    for i in indexes:
        f = frames[i]
        if f.pdu is None:
            out[i] = None
            continue
        sig = tuple((d.cmd, d.idx, d.ado, len(d.data)) for d in f.datagrams)
        queue = waiting.setdefault(sig, [])
        if queue:
            out[queue.pop(0)] = "tx"
            out[i] = "rx"
        else:
            queue.append(i)
    for queue in waiting.values():
        for i in queue:
            out[i] = None
    return out


# --- CAN logs --------------------------------------------------------------------------------
def read_can_traffic(path: str | os.PathLike[str], base_id: int = 0x100) -> Traffic:
    """The fieldbus frames of a CAN log: segments on ``base_id`` (master -> chain) and
    ``base_id + 1`` reassembled."""
    from hil.transports.canlog import CanLogError, read_can_log, read_sidecar, reassemble

    path = str(path)
    try:
        messages = read_can_log(path)
        meta = read_sidecar(path)
    except CanLogError as exc:
        raise TrafficError(str(exc)) from None
    from hil.transports.canlog import cut_reason

    out = Traffic(path, Path(path).suffix.lower().lstrip("."), packets=len(messages),
                  cut=cut_reason(path, len(messages)), metadata=meta)
    ids = (base_id, base_id + 1)
    out.other_packets = sum(1 for m in messages if m.arbitration_id not in ids)
    stats: dict = {}
    for lf in reassemble(messages, ids, stats=stats):
        direction = "tx" if lf.arbitration_id == base_id else "rx"
        ts_ns = int(round(lf.timestamp * 1e6)) * 1000
        try:
            pdu, dgs, trailer = _with_trailer(lf.frame)
            out.frames.append(BusFrame(ts_ns, direction, pdu, tuple(dgs), "can", trailer))
        except CodecError as exc:
            out.frames.append(BusFrame(ts_ns, direction, None, carrier="can", error=str(exc)))
    for can_id, st in stats.items():
        for key in ("crc_errors", "framing_errors", "oversize"):
            n = getattr(st, key)
            if n:
                out.can_errors[f"{can_id:#x} {key}"] = n
    return out


def read_traffic(path: str | os.PathLike[str]) -> Traffic:
    """A capture or a CAN log, by the file name's ending."""
    suffix = Path(path).suffix.lower()
    if not Path(path).is_file():
        raise TrafficError(f"{path}: no such file")
    if suffix in CAPTURE_SUFFIXES:
        return read_capture(path)
    if suffix in CAN_LOG_SUFFIXES:
        return read_can_traffic(path)
    raise TrafficError(f"{path}: not a capture (.pcapng, .pcap) or CAN log (.blf, .asc, .log)")


# --- summary ---------------------------------------------------------------------------------
def summary(t: Traffic) -> dict:
    """Counts for ``eha-hil log info``: frames per direction and carrier, malformed ones,
    datagrams per command, working counters of the replies, time range."""
    good = [f for f in t.frames if f.error is None]
    cmds = Counter(ec.Command(d.cmd).name for f in good for d in f.datagrams)
    times = [f.ts_ns for f in t.frames]
    return {
        "file": t.path, "format": t.kind, "packets": t.packets,
        "fieldbus_frames": len(t.frames),
        "requests": sum(f.direction == "tx" for f in t.frames),
        "replies": sum(f.direction == "rx" for f in t.frames),
        "direction_unknown": sum(f.direction is None for f in t.frames),
        "malformed": len(t.frames) - len(good),
        "first_error": next((f.error for f in t.frames if f.error), None),
        "carriers": dict(Counter(f.carrier for f in t.frames)),
        "crc_trailers": sum(f.crc_trailer for f in good),
        "udp_checksums": dict(Counter(f.udp_checksum for f in t.frames
                                      if f.udp_checksum is not None)),
        "datagrams": dict(cmds),
        "reply_wkc": dict(Counter(str(d.wkc) for f in good if f.direction == "rx"
                                  for d in f.datagrams)),
        "other_packets": t.other_packets,
        "can_reassembly_errors": t.can_errors,
        "first_s": min(times) / 1e9 if times else None,
        "last_s": max(times) / 1e9 if times else None,
        "metadata": {k: (v if len(v) <= 80 else f"<{len(v)} bytes>")
                     for k, v in t.metadata.items()},
        "notes": t.notes,
        "truncated": t.cut is not None, "stop_reason": t.cut,
        "read_until_s": t.read_until_s,
    }


def _wall(t_s: float) -> str:
    import datetime

    return datetime.datetime.fromtimestamp(t_s, datetime.UTC).strftime(
        "%Y-%m-%d %H:%M:%S.%f UTC")


def summary_text(s: dict) -> str:
    lines = [f"{s['file']}: {s['format']}, {s['packets']} packets/messages, "
             f"{s['fieldbus_frames']} EtherCAT frames ({s['requests']} requests, "
             f"{s['replies']} replies"
             + (f", {s['direction_unknown']} of unknown direction" if s["direction_unknown"]
                else "") + f"), {s['malformed']} malformed"]
    if s["first_s"] is not None:
        # relative to the file's first frame (a CAN log or a foreign capture stamps wall
        # time: epoch seconds say nothing at a glance); where that start is, once
        lines.append(f"time: 0 .. {s['last_s'] - s['first_s']:.6f} s from the first frame"
                     + (f" ({_wall(s['first_s'])})" if s["first_s"] > 1e8 else ""))
    rows = [("carriers", s["carriers"]), ("datagrams", s["datagrams"]),
            ("reply working counters", s["reply_wkc"]),
            ("CRC-32 trailers (good)", s["crc_trailers"]),
            ("UDP checksums", s["udp_checksums"]), ("other packets", s["other_packets"]),
            ("CAN reassembly errors", s["can_reassembly_errors"]),
            ("first malformed", s["first_error"]), ("metadata", s["metadata"])]
    for name, value in rows:
        if value or value == 0 and name == "other packets":
            if isinstance(value, dict):
                value = ", ".join(f"{k} {v}" for k, v in value.items())
            lines.append(f"{name}: {value}")
    lines += [f"note: {n}" for n in s["notes"]]
    return "\n".join(lines)
