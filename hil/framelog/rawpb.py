"""Raw frames inside protobuf messages, so that every channel opens in stock tools.

A raw channel carries frames a replay needs bit for bit (register words, process records,
FPGA traces, EtherCAT frames). Their bytes have layouts only this project knows, so they
travel inside protobuf messages whose schema (a ``FileDescriptorSet`` in the file) any
protobuf reader understands -- Foxglove Studio, PlotJuggler, ``mcap-protobuf-support``:

* a **block** of fixed-width frames (``add_block_channel``) is one message
  ``eha_hil.raw.<Encoding>Block``: ``frames`` (``bytes``), ``count``, ``width``
  (``fixed32``), ``dtype`` (numpy's name of one element, ``uint32``) and the frame times:
  ``t0_ns`` and ``dt_ns`` (``sfixed64``) when they are evenly spaced, else ``t_ns`` (packed
  ``sfixed64``, one per frame). This writer stores ``frames`` as byte planes
  (``byte_planes`` true: byte ``b`` of element ``j`` of frame ``i`` at
  ``(b * width + j) * count + i``, each element little endian): a register word or a
  trace column changes little from frame to frame and its high bytes hardly at all, so
  zstd finds long runs there and compresses a whole-robot log twice as fast into a third
  fewer bytes than the frames row by row (docs/framelog.md, "The whole robot"); and it
  stores the planes of the frames' zigzag-coded differences, split at each element's
  noisy low bits: those as bit planes (``low_bits``, their widths in ``low_widths``), the
  rest as byte planes (``high_deltas``), since a byte plane of a sensor's few noisy
  values is zstd's slowest input ("The noisy low bits of the raw blocks"). Blocks of
  logs before hold all of the differences as byte planes (``frame_deltas``), the frames'
  own planes, or (without ``byte_planes``) the frames row by row and ``t_ns``;
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

import functools
import re
import struct
import threading
import zlib
from collections.abc import Callable, Sequence

try:  # zlib-ng's CRC-32: the same function as zlib's, ~3x faster on a block's bus frames
    from zlib_ng.zlib_ng import crc32
except ImportError:  # an environment made before that dependency: zlib's
    from zlib import crc32

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
                "dtype": (5, _FD.TYPE_STRING, False), "t0_ns": (6, _FD.TYPE_SFIXED64, False),
                "dt_ns": (7, _FD.TYPE_SFIXED64, False),
                "byte_planes": (8, _FD.TYPE_BOOL, False),
                "frame_deltas": (9, _FD.TYPE_BYTES, False),
                "low_bits": (10, _FD.TYPE_BYTES, False),
                "low_widths": (11, _FD.TYPE_BYTES, False),
                "high_deltas": (12, _FD.TYPE_BYTES, False),
                "first_frame": (13, _FD.TYPE_BYTES, False),
                "high_planes": (14, _FD.TYPE_BYTES, False)}
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
@functools.lru_cache(maxsize=256)
def block_schema(encoding: str) -> tuple[str, bytes]:
    """(message name, ``FileDescriptorSet``) of the block message of ``encoding`` (kept:
    a whole-robot log asks for a few encodings' schemas 200 times)."""
    name = message_name(encoding, True)
    return name, _schema(name, [(k, n, t, r) for k, (n, t, r) in _BLOCK_TYPES.items()])


def pack_block(t_ns: np.ndarray, frames: np.ndarray, dtype: np.dtype) -> bytes:
    """One block message of ``frames`` ((count, width), written as ``dtype`` little endian)
    at ``t_ns`` ((count,) int ns): :func:`pack_blocks` of one channel."""
    return pack_blocks(t_ns, frames[None], dtype).tobytes()


def even_spacing(t_ns: np.ndarray) -> int | None:
    """The spacing of ``t_ns`` (int ns, at least one) if they are evenly spaced (0 for
    one time), else None."""
    t = np.asarray(t_ns, dtype=_T_NS)
    if len(t) < 2:
        return 0
    dt = int(t[1]) - int(t[0])
    return dt if bool((np.diff(t) == dt).all()) else None


def pack_blocks(t_ns: np.ndarray, frames: np.ndarray, dtype: np.dtype,
                head: list[tuple] = (), byte_planes: bool = True,
                alloc: Callable[[np.dtype, int], np.ndarray] | None = None,
                deltas: bool = True, spacing: int | None = -1,
                low_bits: bool = True, trimmed: bool = True) -> np.ndarray:
    """The block messages of ``k`` channels at once, frames ``(k, count, width)`` at the
    same times ``t_ns`` (count,): a (k,) structured array whose row ``i`` holds, after
    the fields ``head`` (left 0, e.g. :data:`hil.framelog.batch.HEAD_FIELDS`), the block
    message of ``frames[i]`` (one pass over the frames, no bytes object): ``t0_ns`` and
    ``dt_ns`` if the times are evenly spaced, else ``t_ns``; the frames' zigzag-coded
    differences (:func:`zigzag_deltas`) split at each element's noisy low bits
    (:func:`noisy_widths`, the same for the ``k`` channels: one message size): those bits
    as bit planes in ``low_bits``, their widths in ``low_widths``, the rest as byte planes
    in ``high_deltas``; ``trimmed`` (the writer's): the differences taken from the first
    frame (``first_frame``), so that an element's high byte planes that are 0 in every
    frame of every channel, and its bit planes above its highest bit that is ever 1, are
    left out (``high_planes``: the planes kept; :func:`_pack_bits`). ``low_bits`` False,
    or elements of one byte: all of the
    differences as byte planes in ``frame_deltas`` (as logs before); ``deltas`` False: the
    frames' own byte planes in ``frames``, and ``byte_planes`` False as well: row by row,
    as logs before wrote them.
    ``alloc(dtype, k)`` gives the array to fill (every byte is written; default a new
    one). ``spacing``: the times' spacing if the caller has it (:func:`even_spacing`'s
    answer), -1: work it out here."""
    k, count, width = frames.shape
    dt = np.dtype(dtype).newbyteorder("<")
    name = np.dtype(dtype).name.encode()
    size = count * width * dt.itemsize
    t = np.asarray(t_ns, dtype=_T_NS)
    step = None if not count else even_spacing(t) if spacing == -1 else spacing
    deltas = deltas and byte_planes
    # elements of one byte (the boards' traces): as bit planes no faster to compress (the
    # raw chunks of a robot second: 9.8 ms of zstd either way), only more calls' set-up
    low_bits = low_bits and deltas and dt.itemsize > 1
    f = np.asarray(frames, dtype=dt)
    if f.strides[-1] != dt.itemsize:  # the byte views below need whole elements in a row
        f = np.ascontiguousarray(f)
    # everything but the frames is the same bytes in every channel's message: built once
    pre = [b"\x1d", struct.pack("<I", count), b"\x25", struct.pack("<I", width),
           b"\x2a", _varint(len(name)), name]
    if step is None:
        pre += [b"\x0a", _varint(8 * count), t.astype("<i8", copy=False).tobytes()]
    else:
        pre += [b"\x31", struct.pack("<q", int(t[0])), b"\x39", struct.pack("<q", step)]
    if byte_planes:
        pre.append(b"\x40\x01")
    if low_bits:
        return _pack_bits(f, k, count, width, dt.itemsize, pre, head, alloc, trimmed)
    # field 9 (frame_deltas) or 2 (frames), length-delimited
    pre += [b"\x4a" if deltas else b"\x12", _varint(size)]
    prefix = b"".join(pre)
    layout = _layout(tuple(head), len(prefix), size)
    rec = np.zeros(k, layout) if alloc is None else alloc(layout, k)
    rec["pre"] = np.frombuffer(prefix, np.uint8)
    if byte_planes:
        _planes(f, rec["f"].reshape(k, dt.itemsize, width, count), deltas)
    else:
        rec["f"] = f.reshape(k, count * width).view(np.uint8)
    return rec


#: The noisy low bits of an element (:func:`noisy_widths`): the bytes that hold all but
#: one in :data:`NOISE_SHARE` of its differences, in a sample of every
#: :data:`NOISE_STRIDE`-th frame's. Bits above them are then nearly always 0 (byte planes
#: of long runs, which zstd passes quickly), the bits below as bit planes hold a sensor's
#: noise in bytes of nearly random values, in which zstd finds no match and gives up at
#: once, where a byte plane of 2-bit noise is its slowest input (docs/framelog.md, "The
#: noisy low bits").
NOISE_SHARE = 100
NOISE_STRIDE = 256


def noisy_widths(frames: np.ndarray) -> np.ndarray:
    """The noisy low bits of each element of the frames ``(k, count, width)`` (integers
    of one size, little endian), the same for all ``k`` channels, in whole bytes: 8 x the
    fewest bytes that hold all but one in :data:`NOISE_SHARE` of the zigzag-coded
    differences of frame ``n`` to frame ``n - 1`` for ``n`` = 1, 1 + :data:`NOISE_STRIDE`,
    ... (width,) int64. Whole bytes: a sensor word's noisy low byte becomes eight bit
    planes, its high byte stays a byte plane of runs, and the block keeps its size (bits
    below a byte would leave the bytes above it two byte planes, one of them nearly all
    zeros: 8 % more bytes for zstd and the chunks). Compiled for blocks worth it, else
    :func:`_noisy_widths_numpy` (the reference)."""
    size = frames.dtype.itemsize
    out = np.empty(frames.shape[2], np.int64)
    if frames.size >= _COMPILED_FROM:
        from hil.framelog.planes import low_widths

        low_widths(frames.view(f"<i{size}"), 8 * size, NOISE_STRIDE, NOISE_SHARE, out)
        return out
    return _noisy_widths_numpy(frames)


def _noisy_widths_numpy(frames: np.ndarray) -> np.ndarray:
    """:func:`noisy_widths` in numpy."""
    k, count, width = frames.shape
    size = frames.dtype.itemsize
    bits = 8 * size
    u = np.dtype(f"<u{size}")
    x = frames.view(u)
    d = (x[:, 1::NOISE_STRIDE] - x[:, 0:count - 1:NOISE_STRIDE]).reshape(-1, width)
    z = (d << 1) ^ np.negative(d >> (bits - 1))  # zigzag: d >> (bits - 1) is the sign
    length = np.zeros(z.shape, np.int64)  # in bytes
    for b in range(0, bits, 8):
        length += (z >> b) != 0
    allowed = len(z) // NOISE_SHARE
    out = np.zeros(width, np.int64)
    for j in range(width):
        above = np.cumsum(np.bincount(length[:, j], minlength=size + 1)[::-1])[::-1]
        # above[n]: values of n bytes or more; the fewest bytes with at most `allowed` above
        out[j] = 8 * int(np.argmax(np.append(above[1:], 0) <= allowed))
    return out


@functools.lru_cache(maxsize=256)
def _bits_layout(widths: bytes, planes: bytes, count: int, size: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bits_layout` of the widths and planes as bytes, kept (a log's batches repeat
    a few; the arrays are shared: not to be written)."""
    return bits_layout(np.frombuffer(widths, np.uint8), count, size,
                       np.frombuffer(planes, np.uint8))


def full_planes(widths: np.ndarray, size: int) -> np.ndarray:
    """The byte planes of ``z >> w`` for elements of ``size`` bytes split at ``widths``
    (``(8 size - w + 7) // 8`` each): what a block without ``high_planes`` holds."""
    return (8 * size - np.asarray(widths, np.int64) + 7) // 8


def bits_layout(widths: np.ndarray, count: int, size: int,
                planes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Where element ``j``'s bit planes start in ``low_bits`` (``widths[j]`` planes of
    ``(count + 7) // 8`` bytes) and its byte planes in ``high_deltas`` (``planes[j]``
    planes of ``count`` bytes; None: :func:`full_planes`): two (width + 1,) int64 arrays,
    the last entry each field's length."""
    w = np.asarray(widths, np.int64)
    n = full_planes(w, size) if planes is None else np.asarray(planes, np.int64)
    low_at = np.zeros(len(w) + 1, np.int64)
    high_at = np.zeros(len(w) + 1, np.int64)
    np.cumsum(w * ((count + 7) // 8), out=low_at[1:])
    np.cumsum(n * count, out=high_at[1:])
    return low_at, high_at


def _pack_bits(f: np.ndarray, k: int, count: int, width: int, size: int, pre: list[bytes],
               head: list[tuple], alloc: Callable[[np.dtype, int], np.ndarray] | None,
               trimmed: bool) -> np.ndarray:
    """:func:`pack_blocks`' messages of the noisy low bits apart (fields 10-12): ``pre``
    the message's fields so far. Trimmed, the differences are taken from each channel's
    first frame (field 13, ``first_frame``: frame 0's own difference is then 0), each
    element's bit planes stop at its highest bit that is 1 in any channel's differences
    (``w_j`` = that bit length where it is below the noisy width), and of the byte planes
    of ``z >> w_j`` only those with a 1 somewhere are kept (field 14, ``high_planes``):
    most register words change in their low bits only, so a whole-robot block's high
    planes were ~3/4 of its bytes, all 0 but for frame 0 (docs/framelog.md, "The raw
    blocks' planes of zeros"). Where nothing would be left out, the block is written as
    before (frame 0's difference to 0, every plane): readers that predate 13-14 then read
    it, and refuse the trimmed ones (``high_deltas`` shorter than every plane)."""
    bits = 8 * size
    w8 = noisy_widths(f)
    first = f[:, 0] if trimmed and count else np.zeros((k, width), f.dtype)
    z, spans = _zigzag(f, first)
    widths, planes = w8, full_planes(w8, size)
    if trimmed:
        top = np.array([int(v).bit_length() for v in spans.view(f"<u{spans.itemsize}")
                        .tolist()], np.int64)  # the highest bit ever 1, per element
        tw = np.minimum(w8, top)
        tp = (np.maximum(top - tw, 0) + 7) // 8
        if bool((tp < full_planes(tw, size)).any()):
            widths, planes = tw, tp
        else:  # nothing to leave out: as before (frame 0's difference to 0)
            trimmed = False
            z[:, :, 0] = _zigzag_of(f[:, 0], bits).view(z.dtype)
    w8b = widths.astype(np.uint8).tobytes()
    pb = planes.astype(np.uint8).tobytes()
    low_at, high_at = _bits_layout(w8b, pb, count, size)
    # field 11 (low_widths), [14 (high_planes), 13 (first_frame) and frame 0], then 10
    # (low_bits) and 12 (high_deltas) around the planes
    pre = [*pre, b"\x5a", _varint(width), w8b]
    if trimmed:
        pre += [b"\x72", _varint(width), pb, b"\x6a", _varint(width * size)]
    prefix = b"".join(pre)
    mid = b"\x52" + _varint(int(low_at[-1]))
    mid2 = b"\x62" + _varint(int(high_at[-1]))
    layout = _bits_record(tuple(head), len(prefix), width * size if trimmed else 0,
                          len(mid), int(low_at[-1]), len(mid2), int(high_at[-1]))
    rec = np.zeros(k, layout) if alloc is None else alloc(layout, k)
    rec["pre"] = np.frombuffer(prefix, np.uint8)
    if trimmed:
        rec["first"] = np.ascontiguousarray(first).view(np.uint8).reshape(k, -1)
    rec["mid"] = np.frombuffer(mid, np.uint8)
    rec["mid2"] = np.frombuffer(mid2, np.uint8)
    _split(z, bits, widths, planes, low_at, high_at, rec["lo"], rec["hi"])
    return rec


def _zigzag_of(x: np.ndarray, bits: int) -> np.ndarray:
    """The zigzag code of ``x`` (integers of ``bits`` bits), as unsigned: the difference
    of a first frame to 0."""
    u = np.dtype(f"<u{bits // 8}")
    v = x.view(u)
    return (v << np.asarray(1, u)) ^ np.negative(v >> np.asarray(bits - 1, u))


def _zigzag(frames: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z (k, width, count) unsigned, spans (width,)) of the frames ((k, count, width)):
    each element's zigzag-coded differences to the frame before, frame -1 being ``first``
    ((k, width)), and the OR of each element's codes over every frame and channel:
    compiled (:func:`hil.framelog.planes.zigzag_columns`, into a work array kept per
    thread) for blocks worth it, else :func:`_zigzag_numpy` (the reference)."""
    k, count, width = frames.shape
    size = frames.dtype.itemsize
    if frames.size < _COMPILED_FROM:
        return _zigzag_numpy(frames, first)
    from hil.framelog.planes import zigzag_columns

    z = _work(2, (k, width, count), np.dtype(f"<i{size}"))
    spans = np.empty(width, np.int64)
    zigzag_columns(frames.view(f"<i{size}"), first.view(f"<i{size}").astype(np.int64),
                   8 * size, z, spans)
    return z.view(f"<u{size}"), spans


def _zigzag_numpy(frames: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_zigzag` in numpy."""
    u = np.dtype(f"<u{frames.dtype.itemsize}")
    x = np.concatenate([first.view(u)[:, None, :], frames.view(u)], axis=1)
    z = zigzag_deltas(np.ascontiguousarray(x.transpose(0, 2, 1)))[:, :, 1:]
    return z, np.bitwise_or.reduce(z, axis=(0, 2)) if z.size else np.zeros(z.shape[1], u)


def warm_up() -> None:
    """Compile (or load from numba's cache) the byte- and bit-plane passes for every element size,
    with the frames contiguous or a view of a larger array (the engine's taps), into a
    record's field (strided), as logs call it (``python -m hil.sim.warmup``)."""
    from hil.framelog.planes import low_widths, split, split_columns, zigzag_columns

    for size in (1, 2, 4, 8):
        frames = np.zeros((2, 3, 4), f"<i{size}")
        out = np.zeros((2, size + 1, 4, 3), np.uint8)[:, :size]
        widths = np.ones(4, np.int64)
        records = np.zeros((2, 40), np.uint8)  # strided: fields of a record
        z = np.zeros((2, 4, 3), f"<i{size}")
        spans = np.zeros(4, np.int64)
        for f in (frames, frames[:, :2]):
            split(f, out[..., :f.shape[1]], True)
            low_widths(f, 8 * size, NOISE_STRIDE, NOISE_SHARE, widths)
            zigzag_columns(f, np.zeros((2, 4), np.int64), 8 * size, z[..., :f.shape[1]], spans)
            planes = full_planes(widths, size)
            low_at, high_at = bits_layout(widths, f.shape[1], size, planes)
            split_columns(z[..., :f.shape[1]], 8 * size, widths, planes, low_at, high_at,
                          records[:, :10], records[:, 10:])


@functools.lru_cache(maxsize=64)
def _layout(head: tuple, prefix: int, size: int) -> np.dtype:
    """A block record: the fields ``head``, the message's ``prefix`` bytes (every field but
    the frames), the ``size`` bytes of frames."""
    return np.dtype([*head, ("pre", "u1", (prefix,)), ("f", "u1", (size,))])


@functools.lru_cache(maxsize=64)
def _bits_record(head: tuple, prefix: int, first: int, mid: int, low: int, mid2: int,
                 high: int) -> np.dtype:
    """A block record of the noisy low bits apart: the fields ``head``, ``prefix`` bytes
    (every field up to ``first_frame``'s key and length, or up to ``low_widths``), the
    ``first`` bytes of frame 0 (0 if not trimmed), ``mid`` bytes (``low_bits``' key and
    length), the ``low`` bytes of bit planes, ``mid2`` bytes (``high_deltas``' key and
    length), its ``high`` bytes."""
    return np.dtype([*head, ("pre", "u1", (prefix,)), ("first", "u1", (first,)),
                     ("mid", "u1", (mid,)), ("lo", "u1", (low,)), ("mid2", "u1", (mid2,)),
                     ("hi", "u1", (high,))])


def _split(z: np.ndarray, bits: int, widths: np.ndarray, planes: np.ndarray,
           low_at: np.ndarray, high_at: np.ndarray, low: np.ndarray,
           high: np.ndarray) -> None:
    """The bit planes of the codes' ``z`` ((k, width, count), :func:`_zigzag`) low bits
    into ``low`` (k, low_at[-1]) and the kept byte planes of the rest into ``high`` (k,
    high_at[-1]), as :func:`hil.framelog.planes.split_columns` lays them out: compiled for
    blocks worth it, else :func:`_split_numpy` (the reference)."""
    if z.size >= _COMPILED_FROM:
        from hil.framelog.planes import split_columns

        split_columns(z.view(f"<i{z.dtype.itemsize}"), bits, widths, planes, low_at, high_at,
                      low, high)
        return
    _split_numpy(z, widths, planes, low_at, high_at, low, high)


def _split_numpy(z: np.ndarray, widths: np.ndarray, planes: np.ndarray,
                 low_at: np.ndarray, high_at: np.ndarray, low: np.ndarray,
                 high: np.ndarray) -> None:
    """:func:`_split` in numpy: each element's low bits one plane at a time
    (``np.packbits``), the rest shifted down and split into bytes."""
    u = z.dtype
    size = u.itemsize
    k, width, count = z.shape
    for j in range(width):
        w = int(widths[j])
        col = z[:, j]  # (k, count)
        if w:
            bits = (col[:, None, :] >> np.arange(w, dtype=u)[:, None]) & 1
            low[:, low_at[j]:low_at[j + 1]] = np.packbits(
                bits.astype(np.uint8), axis=-1, bitorder="little").reshape(k, -1)
        n = int(planes[j])
        if n:
            rest = col >> np.asarray(w, u) if w < 8 * size else np.zeros_like(col)
            rows = rest.astype(u).view(np.uint8).reshape(k, count, size)[:, :, :n]
            high[:, high_at[j]:high_at[j + 1]] = rows.transpose(0, 2, 1).reshape(k, -1)


def _planes(frames: np.ndarray, out: np.ndarray, deltas: bool) -> None:
    """``out[i, b, j, n]`` = byte ``b`` (little endian) of element ``j`` of frame ``n`` of
    ``frames[i]`` ((k, count, width)), or of its zigzag-coded difference to frame ``n - 1``
    (``deltas``, :func:`zigzag_deltas`): one compiled pass (:func:`hil.framelog.planes.split`)
    for blocks worth it, else :func:`_planes_numpy`."""
    if frames.size >= _COMPILED_FROM:
        from hil.framelog.planes import split  # numba: imported when first needed

        size = frames.dtype.itemsize
        split(frames.view(f"<i{size}"), out, deltas)
        return
    _planes_numpy(frames, out, deltas)


#: Elements from which a block's planes are made by the compiled pass (below: numpy,
#: which costs less than the call into numba for a few frames).
_COMPILED_FROM = 4096


def _planes_numpy(frames: np.ndarray, out: np.ndarray, deltas: bool) -> None:
    """:func:`_planes` in numpy (the reference): the columns transposed once into a work
    array, then each byte split off by a shift (faster than gathering single bytes). The
    work arrays are kept per thread (:func:`_work`): fresh ones of a few MB per call cost
    page faults that the copies themselves do not."""
    size = frames.dtype.itemsize
    u = np.dtype(f"<u{size}")
    k, count, width = frames.shape
    if size == 1 and not deltas:
        out[:, 0] = frames.transpose(0, 2, 1)
        return
    cols = _work(0, (k, width, count), u)
    np.copyto(cols, frames.view(u).transpose(0, 2, 1))
    if deltas:
        cols = zigzag_deltas(cols, out=_work(1, (k, width, count), u))
    if size == 1:
        out[:, 0] = cols
        return
    np.copyto(out[:, 0], cols, casting="unsafe")  # the low byte
    for b in range(1, size):
        np.right_shift(cols, 8 * b, out=out[:, b], casting="unsafe")


_WORK = threading.local()


def _work(slot: int, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    """A work array of ``shape`` and ``dtype`` (content undefined) in this thread's buffer
    ``slot``, grown when too small and kept."""
    bufs = _WORK.__dict__.setdefault("bufs", {})
    n = int(np.prod(shape)) * dtype.itemsize
    buf = bufs.get(slot)
    if buf is None or len(buf) < n:
        buf = bufs[slot] = np.empty(max(n, 1 << 16), np.uint8)
    return buf[:n].view(dtype).reshape(shape)


def zigzag_deltas(x: np.ndarray, axis: int = -1, out: np.ndarray | None = None
                  ) -> np.ndarray:
    """``x`` (unsigned integers) as the zigzag code of each element's difference to the
    one before it along ``axis`` (the first: to 0), a new array of ``x``'s dtype:
    ``d = x[n] - x[n - 1]`` modulo 2^bits, read as signed, coded ``(d << 1) ^ (d >> (bits
    - 1))``, so that small changes either way are small numbers (a sensor word's noise
    leaves its high byte 0). :func:`undo_zigzag_deltas` inverts it exactly. ``out``: the
    array to write them to (not ``x``); ``x`` is then used as work space and overwritten."""
    ax = axis % x.ndim
    first = (slice(None),) * ax + (slice(None, 1),)
    later = (slice(None),) * ax + (slice(1, None),)
    before = (slice(None),) * ax + (slice(None, -1),)
    d = np.empty(x.shape, x.dtype) if out is None else out
    d[first] = x[first]
    np.subtract(x[later], x[before], out=d[later])
    signed = f"i{x.dtype.itemsize}"
    sign = np.right_shift(d.view(signed), 8 * x.dtype.itemsize - 1,
                          out=None if out is None else x.view(signed))
    np.left_shift(d, 1, out=d)
    np.bitwise_xor(d, sign.view(d.dtype), out=d)
    return d


def undo_zigzag_deltas(z: np.ndarray, axis: int = 0) -> np.ndarray:
    """The values whose :func:`zigzag_deltas` along ``axis`` are ``z`` (unsigned): the
    differences ``(z >> 1) ^ -(z & 1)`` summed up modulo 2^bits."""
    d = np.right_shift(z, 1)
    d ^= np.negative(z & 1)  # unsigned: 0 or all ones
    return np.cumsum(d, axis=axis, dtype=z.dtype)


def _read_varint(mv: memoryview, p: int, n: int, what: str) -> tuple[int, int]:
    """The varint at ``mv[p]`` (of ``n`` bytes) and the position after it; ValueError
    "message ends inside a <what>" if the bytes end first."""
    v = shift = 0
    while True:
        if p >= n:
            raise ValueError(f"message ends inside a {what}")
        b = mv[p]
        p += 1
        v |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return v, p


def _fields(data: memoryview | bytes) -> dict[int, object]:
    """Top-level fields of a protobuf message: number -> int (varint, fixed) or memoryview
    (length-delimited); the last occurrence wins. ValueError for bytes that are not one."""
    mv = memoryview(data)
    out: dict[int, object] = {}
    p, n = 0, len(mv)
    while p < n:
        key, p = _read_varint(mv, p, n, "field key")
        number, wire = key >> 3, key & 7
        if wire == 0:
            out[number], p = _read_varint(mv, p, n, "varint")
        elif wire in (1, 5):
            size = 8 if wire == 1 else 4
            if p + size > n:
                raise ValueError("message ends inside a fixed field")
            out[number] = int.from_bytes(mv[p:p + size], "little")
            p += size
        elif wire == 2:
            ln, p = _read_varint(mv, p, n, "length")
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
    """``(t_ns (count,) int64, frames (count, width))`` of a block message: frames as
    noisy low bits apart, byte planes or row by row (then a view, no copy), times as
    ``t_ns`` or ``t0_ns`` + ``dt_ns``; ValueError if a field is missing or the sizes
    disagree."""
    f = _fields(data)
    count, width, dname = f.get(3), f.get(4), f.get(5)
    split = 11 in f or 12 in f or 10 in f
    times, frames = f.get(1, b""), f.get(9, f.get(2, b""))
    if bool(2 in f and len(f[2])) + (9 in f) + split > 1:  # type: ignore[arg-type]
        raise ValueError("block message has more than one of frames, frame_deltas and "
                         "high_deltas")
    if not isinstance(frames, memoryview | bytes) or not isinstance(times, memoryview | bytes):
        raise ValueError("block frames or times are not length-delimited")
    if not isinstance(count, int) or not isinstance(width, int) or \
            not isinstance(dname, memoryview):
        raise ValueError("block message lacks count, width or dtype")
    dt = _DTYPES.get(bytes(dname).decode("ascii", "replace"))
    if dt is None:
        raise ValueError(f"block dtype {bytes(dname)!r} unknown")
    if len(times) != 8 * count and (len(times) or not count or 6 not in f):
        raise ValueError(f"block of {count} x {width} {dt} frames has {len(times)} bytes of "
                         "times" + ("" if len(times) or 6 in f else " and no t0_ns"))
    if not split and len(frames) != count * width * dt.itemsize:
        raise ValueError(f"block of {count} x {width} {dt} frames has {len(frames)} bytes "
                         "of frames")
    if len(times) or not count:
        t = np.frombuffer(times, _T_NS, count)
    else:
        t0, step = (_signed64(f.get(n, 0)) for n in (6, 7))
        t = t0 + step * np.arange(count, dtype=np.int64)
    if split:  # noisy low bits as bit planes, the rest as byte planes
        return t, _join_bits(f, count, width, dt)
    if 9 in f:  # zigzag-coded differences of consecutive frames, as byte planes
        u = np.dtype(f"<u{dt.itemsize}")
        fr = np.frombuffer(f[9], np.uint8).reshape(dt.itemsize, width, count)
        z = np.ascontiguousarray(fr.transpose(2, 1, 0)).view(u).reshape(count, width)
        return t, undo_zigzag_deltas(z).view(dt)
    if f.get(8):
        fr = np.frombuffer(frames, np.uint8).reshape(dt.itemsize, width, count)
        return t, np.ascontiguousarray(fr.transpose(2, 1, 0)).view(dt).reshape(count, width)
    fr = np.frombuffer(frames, dt, count * width)
    return t, fr.reshape(count, width)


def _join_bits(f: dict[int, object], count: int, width: int, dt: np.dtype) -> np.ndarray:
    """The frames (count, width) of a block whose differences are split at their noisy
    low bits (fields 10-12, :func:`pack_blocks`; trimmed: 13-14 too), no loop per
    element (:func:`_codes`); frame -1 of the differences is ``first_frame`` when the
    block has one, else 0."""
    parts = [f.get(n, b"") for n in (10, 11, 12, 13, 14)]
    if not all(isinstance(p, memoryview | bytes) for p in parts):
        raise ValueError("block low_bits, low_widths, high_deltas, first_frame or "
                         "high_planes is not length-delimited")
    low_b, widths_b, high_b, first_b, planes_b = (bytes(p) for p in parts)  # type: ignore[arg-type]
    size = dt.itemsize
    bits = 8 * size
    w = np.frombuffer(widths_b, np.uint8).astype(np.int64)
    if len(w) != width or bool((w > bits).any()):
        raise ValueError(f"block of {width} elements of {bits} bits has low_widths "
                         f"{w.tolist()[:8]}{'...' if len(w) > 8 else ''}")
    full = full_planes(w, size)
    if 14 in f:
        n = np.frombuffer(planes_b, np.uint8).astype(np.int64)
        if len(n) != width or bool((n > full).any()):
            raise ValueError(f"block of {width} elements of {bits} bits has high_planes "
                             f"{n.tolist()[:8]}{'...' if len(n) > 8 else ''} for low_widths "
                             f"{w.tolist()[:8]}{'...' if len(w) > 8 else ''}")
        planes_b = n.astype(np.uint8).tobytes()
    else:
        planes_b = full.astype(np.uint8).tobytes()
    if 13 in f and len(first_b) != width * size:
        raise ValueError(f"block of {width} {dt} elements has {len(first_b)} bytes of "
                         "first_frame")
    low_at, high_at = _bits_layout(widths_b, planes_b, count, size)
    if len(low_b) != low_at[-1] or len(high_b) != high_at[-1]:
        raise ValueError(f"block of {count} x {width} {dt} frames has {len(low_b)} bytes "
                         f"of low_bits and {len(high_b)} of high_deltas, not "
                         f"{low_at[-1]} and {high_at[-1]}")
    u = np.dtype(f"<u{size}")
    frames = undo_zigzag_deltas(_codes(low_b, high_b, widths_b, planes_b, count, size))
    if 13 in f:
        frames += np.frombuffer(first_b, u)  # modulo 2^bits
    return frames.view(dt)


def _codes(low_b: bytes, high_b: bytes, widths_b: bytes, planes_b: bytes, count: int,
           size: int) -> np.ndarray:
    """The zigzag-coded differences (count, width) of a block's bit planes ``low_b`` and
    byte planes ``high_b`` (their layout checked): each element's bit planes padded to
    whole bytes and turned back into byte planes (eight at a time, one bit-matrix
    transposition, :func:`_planes_to_bytes`), its bytes and its kept byte planes of
    ``z >> w`` set into two arrays of its bytes, then ``z = low | high << w``."""
    u = np.dtype(f"<u{size}")
    width = len(widths_b)
    if not count or not width:
        return np.zeros((count, width), u)
    per_plane = (count + 7) // 8
    into, byte_rows, plane_rows, shift = _codes_layout(widths_b, planes_b, size)
    low = np.zeros((width * size, count), np.uint8)
    if len(low_b):
        padded = np.zeros((8 * len(byte_rows), per_plane), np.uint8)
        padded[into] = np.frombuffer(low_b, np.uint8).reshape(-1, per_plane)
        low[byte_rows] = _planes_to_bytes(padded.reshape(-1, 8, per_plane))[:, :count]
    z = np.ascontiguousarray(low.reshape(width, size, count).transpose(2, 0, 1)).view(u)[..., 0]
    if len(high_b):
        high = np.zeros((width * size, count), np.uint8)
        high[plane_rows] = np.frombuffer(high_b, np.uint8).reshape(-1, count)
        rest = np.ascontiguousarray(high.reshape(width, size, count).transpose(2, 0, 1))
        z |= rest.view(u)[..., 0] << shift
    return z


@functools.lru_cache(maxsize=256)
def _codes_layout(widths_b: bytes, planes_b: bytes, size: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For :func:`_codes`: where each bit plane goes among the planes padded to whole
    bytes, which row (element x size + byte) of its bytes each padded byte is, which row
    each kept byte plane of ``z >> w`` is, and each element's ``w`` (0 where no plane is
    kept: a shift by the whole width is not one numpy makes)."""
    w = np.frombuffer(widths_b, np.uint8).astype(np.int64)
    n = np.frombuffer(planes_b, np.uint8).astype(np.int64)
    low_bytes = (w + 7) // 8
    start = np.concatenate([[0], np.cumsum(low_bytes)[:-1]])  # in padded bytes
    into = np.concatenate([[8 * start[j] + b for b in range(w[j])]
                           for j in range(len(w))] + [np.zeros(0, np.int64)]).astype(np.int64)
    byte_rows = np.concatenate([[size * j + b for b in range(low_bytes[j])]
                                for j in range(len(w))] + [np.zeros(0, np.int64)])
    plane_rows = np.concatenate([[size * j + b for b in range(n[j])]
                                 for j in range(len(w))] + [np.zeros(0, np.int64)])
    shift = np.where(n > 0, w, 0).astype(f"<u{size}")
    return into, byte_rows.astype(np.int64), plane_rows.astype(np.int64), shift


def _planes_to_bytes(planes: np.ndarray) -> np.ndarray:
    """Byte planes (g, 8 * n) of values from their bit planes (g, 8, n) (bit ``t`` of byte
    ``m`` of plane ``b`` = bit ``b`` of value ``8 m + t``): per eight values, their eight
    planes' bytes as one 64-bit word, its 8 x 8 bits transposed (the compiled writer's
    transposition, :func:`hil.framelog.planes._bit_planes`, is its own inverse)."""
    g, _, n = planes.shape
    x = np.ascontiguousarray(planes.transpose(0, 2, 1)).view("<u8").reshape(g, n)
    for shift, mask in ((7, 0x00AA00AA00AA00AA), (14, 0x0000CCCC0000CCCC),
                        (28, 0x00000000F0F0F0F0)):
        t = (x ^ (x >> np.uint64(shift))) & np.uint64(mask)
        x = x ^ t ^ (t << np.uint64(shift))
    return x.view(np.uint8).reshape(g, 8 * n)


def _signed64(v: object) -> int:
    """An ``sfixed64`` field's value (read as unsigned by :func:`_fields`)."""
    if not isinstance(v, int):
        raise ValueError("block time field is not a fixed64")
    return v - (1 << 64) if v >= 1 << 63 else v


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


#: Many frames of one length at once: (frames (k, length) uint8, the same frames as k
#: bytes-like objects, e.g. the ones logged) -> their messages (k, size) uint8, or None
#: where the group needs the per-frame :func:`wrapper`.
Many = Callable[[np.ndarray, Sequence[bytes]], np.ndarray | None]
_MANY: dict[str, Many] = {}


def wrap_many(encoding: str, frames: list[bytes]) -> list[bytes] | np.ndarray:
    """The messages of ``frames`` (as :func:`wrapper` makes each): frames of one length
    are wrapped as one array where the encoding has a vectorised header (EtherCAT: a
    bus run's frames repeat the cycle plan's few lengths and datagram layouts). Returns
    an (n, size) uint8 array when all messages have one size, else a list of bytes."""
    wrap = wrapper(encoding)
    many = _MANY.get(encoding)
    if many is None or len(frames) < 2:
        return [wrap(bytes(f)) for f in frames]
    by_len: dict[int, list[int]] = {}
    for i, f in enumerate(frames):
        by_len.setdefault(len(f), []).append(i)
    out: list[bytes] = [b""] * len(frames)
    for idx in by_len.values():
        group = [frames[i] for i in idx]
        got = many(np.frombuffer(b"".join(group), np.uint8).reshape(len(idx), -1),
                   group) if len(idx) > 1 else None
        if got is not None and len(by_len) == 1:
            return got  # one message size: the batch goes in as one array
        if got is None:
            for i in idx:
                out[i] = wrap(bytes(frames[i]))
        else:
            blob = got.tobytes()
            size = got.shape[1]
            for j, i in enumerate(idx):
                out[i] = blob[j * size:(j + 1) * size]
    return out


def wrap_periodic(encoding: str, frames: list[bytes]) -> list[np.ndarray] | None:
    """The messages of ``frames`` (as :func:`wrapper` makes each) when their lengths
    repeat with a period ``p`` of at most 8 (a bus run's cycles: the same requests and
    replies each cycle) and the encoding has a vectorised header: ``p`` arrays, array ``r``
    holding the messages of frames ``r, r + p, ...`` ((n / p, size_r) uint8); None if
    not (then :func:`wrap_many`)."""
    many = _MANY.get(encoding)
    n = len(frames)
    if many is None or n < 2:
        return None
    lens = np.fromiter(map(len, frames), np.int64, n)
    for p in range(1, min(8, n) + 1):
        if n % p == 0 and bool((lens.reshape(-1, p) == lens[:p]).all()):
            break
    else:
        return None
    rows = np.frombuffer(b"".join(frames), np.uint8).reshape(n // p, -1)
    parts: list[np.ndarray] = []
    at = 0
    for r in range(p):
        got = many(rows[:, at:at + int(lens[r])], frames[r::p])
        if got is None:
            return None
        parts.append(got)
        at += int(lens[r])
    return parts


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


def _ethercat_walk(pdu: bytes) -> tuple[bool, list[int], list[int]]:
    """(parsed whole, offset of each datagram :func:`_ethercat_pdu_header` returns, the
    byte offsets its walk depends on): a frame of the same length with the same bytes
    at those offsets parses into datagrams at the same offsets."""
    dgs: list[int] = []
    used = [0, 1]
    if len(pdu) < 2:
        return False, dgs, []
    end = min(len(pdu), 2 + (int.from_bytes(pdu[0:2], "little") & 0x7FF))
    p = 2
    while p + 12 <= end:
        used += [p + 6, p + 7]
        lf = int.from_bytes(pdu[p + 6:p + 8], "little")
        ln = lf & 0x7FF
        if p + 10 + ln + 2 > end:
            return False, dgs, used
        dgs.append(p)
        p += 12 + ln
        if not lf & 0x8000:
            return p == end, dgs, used
    return False, dgs, used


#: CRC-32 of any bytes followed by their own CRC-32 (little endian): a frame's FCS is right
#: if and only if the CRC of the whole frame is this (one C call per frame, no slice).
_CRC_RESIDUE = 0x2144DF1C


def _ethercat_fcs_many(frames: np.ndarray, each: Sequence[bytes]) -> np.ndarray | None:
    """The messages of frames of one length (:func:`wrap_many`; ``each``: the same
    frames as bytes): the datagram layout of the first, taken for every frame whose layout
    bytes agree (None if one does not). Each header field of every datagram of every frame
    by one numpy gather (a bus frame carries a datagram per box and more: a loop per
    datagram cost ~1 ms per block of 800 frames)."""
    k, size = frames.shape
    if size < 6:
        return None
    whole, dgs, used = _ethercat_walk(frames[0, :-4].tobytes())
    if used and not bool((frames[:, used] == frames[0, used]).all()):
        return None
    pdu = frames[:, :-4]
    fcs_ok = np.fromiter(map(crc32, each), np.uint32, k) == _CRC_RESIDUE
    n = len(dgs)
    rec = np.zeros(k, _ethercat_record(size, n))
    rec["k1"], rec["flen"], rec["frame"] = 0x0A, np.frombuffer(_varint(size), np.uint8), frames
    rec["k2"], rec["fcs"], rec["k3"], rec["pdu"] = 0x10, fcs_ok, 0x18, whole
    rec["k4"], rec["n"] = 0x25, n
    if n:
        at = np.asarray(dgs, np.int64)

        def u16(cols: np.ndarray) -> np.ndarray:
            return pdu[:, cols].astype(np.uint32) | pdu[:, cols + 1].astype(np.uint32) << 8

        lengths = (pdu[0, at + 6].astype(np.int64) | pdu[0, at + 7].astype(np.int64) << 8) & 0x7FF
        cols = (pdu[:, at], pdu[:, at + 1], u16(at + 2) | u16(at + 4) << 16, lengths,
                u16(at + 10 + lengths))
        vl = np.frombuffer(_varint(4 * n), np.uint8)
        for c in range(5):
            rec[f"key{c}"] = (5 + c) << 3 | 2
            rec[f"len{c}"] = vl
            rec[f"v{c}"] = cols[c]
    return rec.view(np.uint8).reshape(k, -1)


@functools.lru_cache(maxsize=64)
def _ethercat_record(size: int, n: int) -> np.dtype:
    """The message of a frame of ``size`` bytes with ``n`` datagrams, as one record: the
    frame (field 1), fcs_ok, pdu_ok, datagrams, then the five packed fields."""
    layout = [("k1", "u1"), ("flen", "u1", (len(_varint(size)),)), ("frame", "u1", (size,)),
              ("k2", "u1"), ("fcs", "u1"), ("k3", "u1"), ("pdu", "u1"), ("k4", "u1"),
              ("n", "<u4")]
    if n:
        for c in range(5):
            layout += [(f"key{c}", "u1"), (f"len{c}", "u1", (len(_varint(4 * n)),)),
                       (f"v{c}", "<u4", (n,))]
    return np.dtype(layout)


_ECAT_FIELDS = [("fcs_ok", 2, _FD.TYPE_BOOL, False), ("pdu_ok", 3, _FD.TYPE_BOOL, False),
                ("datagrams", 4, _FD.TYPE_FIXED32, False),
                ("cmd", 5, _FD.TYPE_FIXED32, True), ("idx", 6, _FD.TYPE_FIXED32, True),
                ("address", 7, _FD.TYPE_FIXED32, True), ("length", 8, _FD.TYPE_FIXED32, True),
                ("wkc", 9, _FD.TYPE_FIXED32, True)]
register_header("eha-hil/ethercat-fcs", _ECAT_FIELDS, _ethercat_fcs_header)
_MANY["eha-hil/ethercat-fcs"] = _ethercat_fcs_many
