"""Classic libpcap capture files: records <-> bytes, plus thin file helpers.

Format (pcap-savefile(5), also IETF draft-ietf-opsawg-pcap): a 24-byte global header —
magic 0xA1B2C3D4 (microsecond timestamps) or 0xA1B23C4D (nanosecond), version 2.4,
thiszone 0, sigfigs 0, snaplen, link type (1 = Ethernet) — then per packet a 16-byte record
header (ts_sec, ts_usec/ts_nsec, incl_len, orig_len) and ``incl_len`` bytes of data. The
writer emits little-endian files (what a reader detects from the magic's byte order); the
reader accepts both byte orders and both resolutions.

:func:`build_pcap` / :func:`parse_pcap` are pure; :func:`write_pcap` / :func:`read_pcap`
only move those bytes to or from a path or binary file object.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from typing import BinaryIO

from protocols.errors import FrameError, RangeError, as_bytes, as_int, as_iterable

MAGIC_USEC = 0xA1B2C3D4
MAGIC_NSEC = 0xA1B23C4D
VERSION = (2, 4)
LINKTYPE_ETHERNET = 1
DEFAULT_SNAPLEN = 65535

_GLOBAL_FIELDS = (
    "magic",
    "version_major",
    "version_minor",
    "thiszone",
    "sigfigs",
    "snaplen",
    "linktype",
)
_GLOBAL_CODES = "IHHiIII"
_RECORD_FIELDS = ("ts_sec", "ts_frac", "incl_len", "orig_len")
_RECORD_CODES = "IIII"


def _structs(order: str) -> tuple[struct.Struct, struct.Struct]:
    return struct.Struct(order + _GLOBAL_CODES), struct.Struct(order + _RECORD_CODES)


GLOBAL_HEADER_LEN = struct.calcsize("<" + _GLOBAL_CODES)  # 24
RECORD_HEADER_LEN = struct.calcsize("<" + _RECORD_CODES)  # 16


@dataclass(frozen=True)
class PcapRecord:
    """One captured packet: timestamp in integer nanoseconds since the epoch, the bytes
    captured, and the original length on the wire (``None`` = same as captured)."""

    ts_ns: int
    data: bytes
    orig_len: int | None = None


@dataclass(frozen=True)
class PcapFile:
    """A parsed capture."""

    linktype: int
    snaplen: int
    nanosecond: bool
    records: list[PcapRecord]


def build_pcap(
    records: Iterable[PcapRecord],
    linktype: int = LINKTYPE_ETHERNET,
    snaplen: int = DEFAULT_SNAPLEN,
    nanosecond: bool = False,
) -> bytes:
    """Bytes of a capture file holding ``records``.

    Microsecond files floor the timestamp to whole microseconds. Raises
    :class:`RangeError` for a negative or too-large timestamp, data longer than
    ``snaplen`` or an ``orig_len`` smaller than the data.
    """
    g, r = _structs("<")
    records = as_iterable(records, "pcap records", RangeError)
    snaplen = as_int(snaplen, "snaplen", 0, 0xFFFFFFFF)
    magic = MAGIC_NSEC if nanosecond else MAGIC_USEC
    try:
        out = bytearray(g.pack(magic, *VERSION, 0, 0, snaplen, linktype))
    except struct.error as exc:
        raise RangeError(f"global header field out of range: {exc}") from exc
    per_sec = 1_000_000_000 if nanosecond else 1_000_000
    div = 1 if nanosecond else 1000
    for i, rec in enumerate(records):
        if not isinstance(rec, PcapRecord):
            raise RangeError(f"pcap records[{i}]: {type(rec).__name__} is not a PcapRecord")
        data = as_bytes(rec.data, f"pcap records[{i}].data", RangeError)
        if len(data) > snaplen:
            raise RangeError(f"record of {len(data)} bytes exceeds snaplen {snaplen}")
        orig = len(data) if rec.orig_len is None else as_int(rec.orig_len, "orig_len")
        if orig < len(data):
            raise RangeError("orig_len smaller than the captured data")
        ts_ns = as_int(rec.ts_ns, f"pcap records[{i}].ts_ns")
        if ts_ns < 0:
            raise RangeError("negative timestamp")
        sec, frac = divmod(ts_ns // div, per_sec)
        try:
            out += r.pack(sec, frac, len(data), orig)
        except struct.error as exc:
            raise RangeError(f"record header field out of range: {exc}") from exc
        out += data
    return bytes(out)


def parse_pcap(buf: bytes) -> PcapFile:
    """Parse capture-file bytes.

    Raises :class:`FrameError` for an unknown magic, an unsupported version, a truncated
    header or record, a sub-second field out of range, ``incl_len`` above the snaplen, or
    ``orig_len`` below ``incl_len``, and for a ``buf`` that is not bytes-like.
    """
    buf = as_bytes(buf, "pcap data")
    if len(buf) < GLOBAL_HEADER_LEN:
        raise FrameError(f"pcap global header needs 24 bytes, have {len(buf)}")
    for order in ("<", ">"):
        (magic,) = struct.unpack_from(order + "I", buf)
        if magic in (MAGIC_USEC, MAGIC_NSEC):
            break
    else:
        raise FrameError(f"not a classic pcap file (magic {buf[:4].hex()})")
    g, r = _structs(order)
    hdr = dict(zip(_GLOBAL_FIELDS, g.unpack_from(buf), strict=True))
    if (hdr["version_major"], hdr["version_minor"]) != VERSION:
        raise FrameError(f"pcap version {hdr['version_major']}.{hdr['version_minor']} unsupported")
    nanosecond = magic == MAGIC_NSEC
    per_sec = 1_000_000_000 if nanosecond else 1_000_000
    mult = 1 if nanosecond else 1000
    snaplen = hdr["snaplen"]
    records: list[PcapRecord] = []
    pos = GLOBAL_HEADER_LEN
    while pos < len(buf):
        if len(buf) - pos < RECORD_HEADER_LEN:
            raise FrameError("truncated record header")
        rec = dict(zip(_RECORD_FIELDS, r.unpack_from(buf, pos), strict=True))
        pos += RECORD_HEADER_LEN
        n = rec["incl_len"]
        if rec["ts_frac"] >= per_sec:
            raise FrameError(f"sub-second field {rec['ts_frac']} out of range")
        if snaplen and n > snaplen:
            raise FrameError(f"incl_len {n} exceeds snaplen {snaplen}")
        if rec["orig_len"] < n:
            raise FrameError("orig_len smaller than incl_len")
        if len(buf) - pos < n:
            raise FrameError(f"record needs {n} bytes, have {len(buf) - pos}")
        ts_ns = (rec["ts_sec"] * per_sec + rec["ts_frac"]) * mult
        orig = None if rec["orig_len"] == n else rec["orig_len"]
        records.append(PcapRecord(ts_ns, buf[pos : pos + n], orig))
        pos += n
    return PcapFile(hdr["linktype"], snaplen, nanosecond, records)


def write_pcap(
    target: str | os.PathLike[str] | BinaryIO,
    records: Iterable[PcapRecord],
    linktype: int = LINKTYPE_ETHERNET,
    snaplen: int = DEFAULT_SNAPLEN,
    nanosecond: bool = False,
) -> int:
    """Write a capture to a path or binary file object; returns the bytes written."""
    data = build_pcap(records, linktype, snaplen, nanosecond)
    if isinstance(target, str | os.PathLike):
        with open(target, "wb") as fh:
            fh.write(data)
    else:
        target.write(data)
    return len(data)


def read_pcap(source: str | os.PathLike[str] | BinaryIO) -> PcapFile:
    """Read and parse a capture from a path or binary file object (OSError from the file
    system, :class:`FrameError` for anything else that is not a capture)."""
    if isinstance(source, str | os.PathLike):
        with open(source, "rb") as fh:
            return parse_pcap(fh.read())
    read = getattr(source, "read", None)
    if not callable(read):
        raise FrameError(f"pcap source: {type(source).__name__} is neither a path nor a "
                         "binary file")
    return parse_pcap(read())
