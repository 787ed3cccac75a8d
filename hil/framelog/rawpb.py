"""Raw frames inside protobuf messages, so that every channel opens in stock tools.

A raw channel carries frames a replay needs bit for bit (register words, process records,
FPGA traces, EtherCAT frames). Their bytes have layouts only this project knows, so they
travel inside protobuf messages whose schema (a ``FileDescriptorSet`` in the file) any
protobuf reader understands -- Foxglove Studio, PlotJuggler, ``mcap-protobuf-support``:

* a **block** of fixed-width frames (``add_block_channel``) is one message
  ``eha_hil.raw.<Encoding>Block``: ``t_ns`` (packed ``sfixed64``, one time per frame),
  ``frames`` (``bytes``: the frames row by row, each element little endian), ``count``,
  ``width`` (``fixed32``) and ``dtype`` (numpy's name of one element, ``uint32``);
* a **single** frame (``add_channel`` with an encoding that is not a stock MCAP message
  encoding) is one message ``eha_hil.raw.<Encoding>``: ``frame`` (``bytes``, the frame as
  it was logged) and, for encodings that have them, the frame's header fields decoded
  beside it (an EtherCAT frame's datagram commands, addresses and working counters), so a
  viewer shows what the frame is without knowing the encoding.

The frame encoding (``eha-hil/mcu-up``, ...) stays in the channel metadata
(``eha-hil.frame_encoding``), the byte layout of one frame in ``eha-hil.layout``
(:mod:`hil.framelog.layout`), and ``eha-hil.container`` = ``protobuf`` tells our reader to
unwrap the frames: :class:`~hil.framelog.reader.FrameLogReader` returns the same bytes as
before, so the replay reads them bit for bit. Logs written before (``eha-hil/block``
messages, bare single frames) are read as they were.

Messages are built and parsed with a few lines of wire format here (a block is five
length-delimited or fixed fields: no per-frame Python); any protobuf runtime reads them.
"""

from __future__ import annotations

import re
import struct
import zlib
from collections.abc import Callable

import numpy as np
from google.protobuf import descriptor_pb2

from hil.framelog.formats import DTYPE_CODES

#: Channel metadata value of ``eha-hil.container`` for frames wrapped as here.
CONTAINER = "protobuf"
#: MCAP message encodings Foxglove and the MCAP libraries decode themselves (the MCAP
#: registry's well-known message encodings); frames of any other encoding are wrapped.
STOCK_MESSAGE_ENCODINGS = ("protobuf", "json", "ros1", "cdr", "flatbuffer", "cbor")
PACKAGE = "eha_hil.raw"

_FD = descriptor_pb2.FieldDescriptorProto
_BLOCK_TYPES = {"t_ns": (1, _FD.TYPE_SFIXED64, True), "frames": (2, _FD.TYPE_BYTES, False),
                "count": (3, _FD.TYPE_FIXED32, False), "width": (4, _FD.TYPE_FIXED32, False),
                "dtype": (5, _FD.TYPE_STRING, False)}
_T_NS = np.dtype("<i8")


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if not n:
            out.append(b)
            return bytes(out)
        out.append(b | 0x80)


def message_name(encoding: str, block: bool) -> str:
    """``eha_hil.raw.McuUpBlock`` for ``eha-hil/mcu-up`` as a block, ``...McuUp`` single."""
    words = re.split(r"[^0-9A-Za-z]+", encoding.split("/", 1)[-1])
    name = "".join(w[:1].upper() + w[1:] for w in words if w) or "Frame"
    if not name[0].isalpha():
        name = "F" + name
    return f"{PACKAGE}.{name}{'Block' if block else ''}"


def _schema(full_name: str, fields: list[tuple[str, int, int, bool]]) -> bytes:
    package, _, name = full_name.rpartition(".")
    fd = descriptor_pb2.FileDescriptorProto(
        name=f"{full_name.replace('.', '/')}.proto", package=package, syntax="proto3")
    msg = fd.message_type.add(name=name)
    for fname, number, ftype, repeated in fields:
        msg.field.add(name=fname, number=number, type=ftype,
                      label=_FD.LABEL_REPEATED if repeated else _FD.LABEL_OPTIONAL)
    return descriptor_pb2.FileDescriptorSet(file=[fd]).SerializeToString()


# --- blocks ---------------------------------------------------------------------------------
def block_schema(encoding: str) -> tuple[str, bytes]:
    """(message name, ``FileDescriptorSet``) of the block message of ``encoding``."""
    name = message_name(encoding, True)
    return name, _schema(name, [(k, n, t, r) for k, (n, t, r) in _BLOCK_TYPES.items()])


def pack_block(t_ns: np.ndarray, frames: np.ndarray, dtype: np.dtype) -> bytes:
    """One block message of ``frames`` ((count, width), written as ``dtype`` little endian)
    at ``t_ns`` ((count,) int ns)."""
    count, width = frames.shape
    t = np.ascontiguousarray(t_ns, dtype=_T_NS).tobytes()
    f = np.ascontiguousarray(frames, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()
    name = np.dtype(dtype).name.encode()
    return b"".join((b"\x1d", struct.pack("<I", count), b"\x25", struct.pack("<I", width),
                     b"\x2a", _varint(len(name)), name,
                     b"\x0a", _varint(len(t)), t, b"\x12", _varint(len(f)), f))


def _fields(data: memoryview | bytes) -> dict[int, object]:
    """Top-level fields of a protobuf message: number -> int (varint, fixed) or memoryview
    (length-delimited); the last occurrence wins. ValueError for bytes that are not one."""
    mv = memoryview(data)
    out: dict[int, object] = {}
    p, n = 0, len(mv)
    while p < n:
        key = shift = 0
        while True:
            if p >= n:
                raise ValueError("message ends inside a field key")
            b = mv[p]
            p += 1
            key |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                break
        number, wire = key >> 3, key & 7
        if wire == 0:
            v = shift = 0
            while True:
                if p >= n:
                    raise ValueError("message ends inside a varint")
                b = mv[p]
                p += 1
                v |= (b & 0x7F) << shift
                shift += 7
                if not b & 0x80:
                    break
            out[number] = v
        elif wire in (1, 5):
            size = 8 if wire == 1 else 4
            if p + size > n:
                raise ValueError("message ends inside a fixed field")
            out[number] = int.from_bytes(mv[p:p + size], "little")
            p += size
        elif wire == 2:
            ln = shift = 0
            while True:
                if p >= n:
                    raise ValueError("message ends inside a length")
                b = mv[p]
                p += 1
                ln |= (b & 0x7F) << shift
                shift += 7
                if not b & 0x80:
                    break
            if p + ln > n:
                raise ValueError(f"field {number} claims {ln} bytes, {n - p} follow")
            out[number] = mv[p:p + ln]
            p += ln
        else:
            raise ValueError(f"field {number} has wire type {wire}")
    return out


_DTYPES = {dt.name: dt for dt in DTYPE_CODES.values()}


def block_count(data: memoryview | bytes) -> int:
    """Frames in a block message (ValueError if it is not one)."""
    v = _fields(data).get(3)
    if not isinstance(v, int):
        raise ValueError("block message has no count")
    return v


def unpack_block(data: memoryview | bytes) -> tuple[np.ndarray, np.ndarray]:
    """``(t_ns (count,) int64, frames (count, width))`` of a block message (views, no
    copy); ValueError if a field is missing or the sizes disagree."""
    f = _fields(data)
    count, width, dname = f.get(3), f.get(4), f.get(5)
    times, frames = f.get(1, b""), f.get(2, b"")
    if not isinstance(count, int) or not isinstance(width, int) or \
            not isinstance(dname, memoryview):
        raise ValueError("block message lacks count, width or dtype")
    dt = _DTYPES.get(bytes(dname).decode("ascii", "replace"))
    if dt is None:
        raise ValueError(f"block dtype {bytes(dname)!r} unknown")
    if len(times) != 8 * count or len(frames) != count * width * dt.itemsize:
        raise ValueError(f"block of {count} x {width} {dt} frames has {len(times)} bytes of "
                         f"times and {len(frames)} of frames")
    t = np.frombuffer(times, _T_NS, count)
    fr = np.frombuffer(frames, dt, count * width)
    return t, fr.reshape(count, width)


# --- single frames --------------------------------------------------------------------------
#: A header decoder: frame bytes -> packed field bytes (keys and values, numbers from 2).
Header = Callable[[bytes], bytes]
_HEADERS: dict[str, tuple[list[tuple[str, int, int, bool]], Header]] = {}


def register_header(encoding: str, fields: list[tuple[str, int, int, bool]],
                    fn: Header) -> None:
    """Decoded header fields written beside each single frame of ``encoding``: ``fields``
    (name, number >= 2, descriptor type, repeated) and ``fn`` (frame -> their wire bytes)."""
    _HEADERS[encoding] = (fields, fn)


def frame_schema(encoding: str) -> tuple[str, bytes]:
    """(message name, ``FileDescriptorSet``) of the single-frame message of ``encoding``."""
    name = message_name(encoding, False)
    extra = _HEADERS.get(encoding, ([], None))[0]
    return name, _schema(name, [("frame", 1, _FD.TYPE_BYTES, False), *extra])


def wrapper(encoding: str) -> Callable[[bytes], bytes]:
    """frame bytes -> its message (``frame`` and the encoding's header fields)."""
    head = _HEADERS.get(encoding, (None, None))[1]
    if head is None:
        return lambda data: b"\x0a" + _varint(len(data)) + data
    return lambda data: b"\x0a" + _varint(len(data)) + data + head(data)


def unwrap(data: memoryview | bytes) -> memoryview:
    """The frame of a single-frame message (field 1); ValueError if it is not one."""
    mv = memoryview(data)
    if len(mv) >= 2 and mv[0] == 0x0A and mv[1] < 0x80 and 2 + mv[1] <= len(mv):
        return mv[2:2 + mv[1]]  # the common case: a frame under 128 bytes first
    v = _fields(mv).get(1, b"")
    if not isinstance(v, memoryview | bytes):
        raise ValueError("frame field is not bytes")
    return memoryview(v)


# --- EtherCAT header fields -----------------------------------------------------------------
def _packed32(number: int, values: list[int]) -> bytes:
    if not values:
        return b""
    return bytes((number << 3 | 2,)) + _varint(4 * len(values)) + struct.pack(
        f"<{len(values)}I", *values)


def _ethercat_pdu_header(pdu: bytes) -> tuple[bool, list[list[int]]]:
    """(parsed whole, [cmd, idx, address, length, wkc] per datagram) of an EtherCAT PDU;
    stops at the first datagram that does not fit."""
    dgs: list[list[int]] = []
    if len(pdu) < 2:
        return False, dgs
    end = min(len(pdu), 2 + (int.from_bytes(pdu[0:2], "little") & 0x7FF))
    p = 2
    while p + 12 <= end:
        cmd, idx, adp, ado, lf = struct.unpack_from("<BBHHH", pdu, p)
        ln = lf & 0x7FF
        if p + 10 + ln + 2 > end:
            return False, dgs
        wkc = int.from_bytes(pdu[p + 10 + ln:p + 12 + ln], "little")
        dgs.append([cmd, idx, adp | ado << 16, ln, wkc])
        p += 12 + ln
        if not lf & 0x8000:
            return p == end, dgs
    return False, dgs


def _ethercat_fcs_header(data: bytes) -> bytes:
    pdu = data[:-4]
    fcs_ok = len(data) > 4 and (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") == data[-4:]
    whole, dgs = _ethercat_pdu_header(pdu)
    cols = list(zip(*dgs, strict=True)) if dgs else [(), (), (), (), ()]
    return b"".join((b"\x10", b"\x01" if fcs_ok else b"\x00",
                     b"\x18", b"\x01" if whole else b"\x00",
                     b"\x25", struct.pack("<I", len(dgs)),
                     *(_packed32(5 + i, list(c)) for i, c in enumerate(cols))))


_ECAT_FIELDS = [("fcs_ok", 2, _FD.TYPE_BOOL, False), ("pdu_ok", 3, _FD.TYPE_BOOL, False),
                ("datagrams", 4, _FD.TYPE_FIXED32, False),
                ("cmd", 5, _FD.TYPE_FIXED32, True), ("idx", 6, _FD.TYPE_FIXED32, True),
                ("address", 7, _FD.TYPE_FIXED32, True), ("length", 8, _FD.TYPE_FIXED32, True),
                ("wkc", 9, _FD.TYPE_FIXED32, True)]
register_header("eha-hil/ethercat-fcs", _ECAT_FIELDS, _ethercat_fcs_header)
