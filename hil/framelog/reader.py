"""Read frame logs written by :class:`hil.framelog.writer.FrameLogWriter` (or any MCAP file).

The reader walks the file's records in order with its own small MCAP record parser: every
record's length is checked against the bytes present *before* it is parsed, so a log cut
short by a killed run is read up to its last complete record (in practice: its last
complete chunk) and then reported as truncated, never half-parsed. The mcap library's
``StreamReader`` would do the walk too, but on a short file it hands back a short final
record without complaint (its ``ReadDataStream.read`` returns what is there), and its
per-message objects cost more than the replay's 20x real-time budget likes.

Damage that is not a truncation -- a chunk whose CRC or decompression fails, a record that
does not parse although all its bytes are present, a data-section CRC mismatch -- raises
:class:`FrameLogError` naming the file, the byte offset and how far the log was readable.

All times are integer ns of simulated time (MCAP log time).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

import lz4.frame
import numpy as np
import zstandard

from hil.framelog import rawpb
from hil.framelog.chunk import crc32
from hil.framelog.formats import (
    BLOCK_HEADER,
    BLOCK_MAGIC,
    META_CONTAINER,
    META_DTYPE,
    META_FRAME_ENCODING,
    META_FRAMING,
    META_WIDTH,
    METADATA_NAME,
    unpack_block,
)

MAGIC = b"\x89MCAP0\r\n"
_REC = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_CHUNK = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed crc
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_METADATA, OP_DATA_END = 0x0C, 0x0F
#: A record claiming more than this many bytes is taken as a damaged length field, not as a
#: record cut short: no writer of these logs writes a record of a terabyte.
MAX_RECORD_BYTES = 1 << 40
#: What a closed MCAP file ends with: a Footer record (opcode, length 20, 20 bytes), then
#: the magic again.
_FOOTER_TAIL = 1 + 8 + 20 + len(MAGIC)
_INT64_MAX = (1 << 63) - 1
_OP_NAMES = {1: "Header", 2: "Footer", 3: "Schema", 4: "Channel", 5: "Message", 6: "Chunk",
             7: "MessageIndex", 8: "ChunkIndex", 9: "Attachment", 10: "AttachmentIndex",
             11: "Statistics", 12: "Metadata", 13: "MetadataIndex", 14: "SummaryOffset",
             15: "DataEnd"}


class FrameLogError(Exception):
    """A log that cannot be read (missing, empty, not MCAP, damaged); one-line message."""


class _Corrupt(Exception):
    """A record that does not parse; turned into FrameLogError with the file and offset."""


class _Cursor:
    """Bounds-checked little-endian reads from one record body."""

    __slots__ = ("buf", "pos")

    def __init__(self, buf: memoryview | bytes, pos: int = 0) -> None:
        self.buf = buf
        self.pos = pos

    def take(self, n: int) -> memoryview | bytes:
        end = self.pos + n
        if n < 0 or end > len(self.buf):
            raise _Corrupt(f"field of {n} bytes runs past the end of its record")
        out = self.buf[self.pos:end]
        self.pos = end
        return out

    def u16(self) -> int:
        return int.from_bytes(self.take(2), "little")

    def u32(self) -> int:
        return int.from_bytes(self.take(4), "little")

    def u64(self) -> int:
        return int.from_bytes(self.take(8), "little")

    def text(self) -> str:
        try:
            return bytes(self.take(self.u32())).decode("utf-8")
        except UnicodeDecodeError:
            raise _Corrupt("string is not UTF-8") from None

    def string_map(self) -> dict[str, str]:
        end = self.pos + self.u32()
        if end > len(self.buf):
            raise _Corrupt("map runs past the end of its record")
        out = {}
        while self.pos < end:
            k = self.text()
            out[k] = self.text()
        return out


# --- results --------------------------------------------------------------------------------
@dataclass(frozen=True)
class ChannelInfo:
    """One channel (topic) of a log and what was read of it.

    ``encoding`` is the frame encoding (decoder key); ``message_encoding`` the MCAP one
    (``eha-hil/block`` for block channels). ``framing`` is ``single`` or ``block``;
    ``dtype``/``width`` describe a block channel's frames. Times in ns; None when the
    channel has no message.
    """

    id: int
    topic: str
    encoding: str
    message_encoding: str
    framing: str
    schema_name: str
    schema_encoding: str
    metadata: dict[str, str]
    dtype: str | None
    width: int | None
    message_count: int = 0
    frame_count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    schema_data: bytes = field(default=b"", repr=False)


@dataclass(frozen=True)
class LogInfo:
    """What a log holds and how much of it could be read.

    ``complete``: the file ends with a footer and the closing magic (the writer was
    closed). ``truncated`` is its negation: reading stopped at the end of the last complete
    record, ``stop_reason`` says where. ``readable_until_ns``: simulated time of the last
    frame read (None if none). ``metadata`` maps each Metadata record's name to its
    key/value pairs; ``level`` comes from the ``"eha-hil"`` record (None if absent).
    """

    path: str
    size: int
    profile: str
    library: str
    level: str | None
    metadata: dict[str, dict[str, str]]
    channels: tuple[ChannelInfo, ...]
    message_count: int
    frame_count: int
    chunk_count: int
    start_ns: int | None
    end_ns: int | None
    complete: bool
    truncated: bool
    readable_until_ns: int | None
    stop_reason: str

    def channel(self, topic: str) -> ChannelInfo:
        """The channel of ``topic``; FrameLogError naming the topics present otherwise."""
        for c in self.channels:
            if c.topic == topic:
                return c
        raise FrameLogError(f"{self.path}: no topic {topic!r} (topics: "
                            f"{', '.join(c.topic for c in self.channels) or 'none'})")

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict (for ``log info --json``); a schema's data as its
        size in bytes."""
        d = asdict(self)
        for c in d["channels"]:
            c["schema_data"] = len(c["schema_data"])
        return d


class RawChannel(NamedTuple):
    """All frames of one topic as stored, for columnar decoding: ``t_ns`` (n,) frame times,
    ``seq`` (n,) the number of the message each frame came in (file order over the
    selected channels) and ``row`` its row in that message (ties in time sort by these);
    ``frames`` (n, width) for a block channel, else ``payloads`` (one frame each)."""

    t_ns: np.ndarray
    seq: np.ndarray
    row: np.ndarray
    frames: np.ndarray | None
    payloads: list[memoryview] | None


class Blocks(NamedTuple):
    """All frames of one topic: ``t_ns`` (n,) int64 and ``frames`` (n, width)."""

    t_ns: np.ndarray
    frames: np.ndarray


@dataclass
class _Chan:
    id: int
    topic: str
    message_encoding: str
    schema_id: int
    metadata: dict[str, str]
    block: bool = False
    wrapped: bool = False  # frames inside protobuf messages (rawpb)
    encoding: str = ""
    dtype: np.dtype | None = None
    width: int | None = None
    messages: int = 0
    frames: int = 0
    first_ns: int | None = None
    last_ns: int | None = None


@dataclass
class _Scan:
    """State of one pass over the file, filled in as records are read."""

    profile: str = ""
    library: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    channels: dict[int, _Chan] = field(default_factory=dict)
    chunks: int = 0
    complete: bool = False
    stop_reason: str = ""
    last_ns: int | None = None


class _Msg(NamedTuple):
    chan: _Chan
    log_ns: int
    publish_ns: int
    data: memoryview


def _channel_from(cur: _Cursor) -> _Chan:
    cid, sid = cur.u16(), cur.u16()
    topic, menc = cur.text(), cur.text()
    meta = cur.string_map()
    ch = _Chan(cid, topic, menc, sid, meta)
    ch.block = meta.get(META_FRAMING) == "block"
    ch.encoding = meta.get(META_FRAME_ENCODING, menc)
    ch.wrapped = meta.get(META_CONTAINER) == rawpb.CONTAINER
    if ch.block:
        try:
            ch.dtype = np.dtype(meta[META_DTYPE]).newbyteorder("<")
            ch.width = int(meta[META_WIDTH])
        except (KeyError, TypeError, ValueError):
            raise _Corrupt(f"block channel {topic!r} lacks a valid dtype/width") from None
    return ch


def _decompress(compression: str, data: memoryview, size: int) -> bytes:
    if compression == "":
        return bytes(data)
    try:
        if compression == "zstd":
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        if compression == "lz4":
            return lz4.frame.decompress(data)
    except Exception as exc:  # zstd/lz4 raise their own error types
        raise _Corrupt(f"{compression} decompression failed ({exc})") from None
    raise _Corrupt(f"chunk compression {compression!r} is not supported")


class FrameLogReader:
    """Reader of one frame log. Each call reads the file afresh (a log still being written
    can be read again later); nothing stays open between calls.

    Raises :class:`FrameLogError` at construction if the file is missing, empty or not
    MCAP, and from any method if the file is damaged (not merely truncated).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            with open(self.path, "rb") as f:
                head = f.read(len(MAGIC))
        except FileNotFoundError:
            raise FrameLogError(f"{self.path}: no such file") from None
        except IsADirectoryError:
            raise FrameLogError(f"{self.path}: is a directory, not a log file") from None
        except OSError as exc:
            raise FrameLogError(f"{self.path}: cannot read ({exc.strerror})") from None
        if not head:
            raise FrameLogError(f"{self.path}: empty file, not an MCAP log")
        if head != MAGIC[:len(head)] or len(head) < len(MAGIC):
            raise FrameLogError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")

    # -- the record walk -----------------------------------------------------------------
    def _ends_with_footer(self, f: object, size: int) -> bool:
        """Whether the file ends with a Footer record and the closing magic, i.e. it was
        closed by its writer: a walk that runs off its end is then reading a damaged
        length field, not a file cut short."""
        if size < len(MAGIC) + _FOOTER_TAIL:
            return False
        here = f.tell()  # type: ignore[attr-defined]
        f.seek(size - _FOOTER_TAIL)  # type: ignore[attr-defined]
        tail = f.read(_FOOTER_TAIL)  # type: ignore[attr-defined]
        f.seek(here)  # type: ignore[attr-defined]
        return (tail[0] == OP_FOOTER and int.from_bytes(tail[1:9], "little") == 20
                and tail[-len(MAGIC):] == MAGIC)

    def _error(self, offset: int, what: str, scan: _Scan) -> FrameLogError:
        upto = "nothing" if scan.last_ns is None else f"t = {scan.last_ns} ns"
        return FrameLogError(f"{self.path}: damaged at byte {offset}: {what} "
                             f"(readable up to {upto})")

    def _walk(self, scan: _Scan, wanted: Callable[[_Chan], bool] | None) -> Iterator[_Msg]:
        """Yield the messages (of channels ``wanted`` accepts) in file order, updating
        ``scan``; return at the end of the file or of the last complete record."""
        size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            f.read(len(MAGIC))
            pos = len(MAGIC)
            crc = crc32(MAGIC)
            keep: dict[int, bool] = {}
            first = True
            while True:
                head = f.read(_REC.size)
                if not head:
                    if self._ends_with_footer(f, size):
                        raise self._error(pos, "the records end without reaching the Footer "
                                          "the file ends with (a damaged length field)", scan)
                    scan.stop_reason = (f"file ends at byte {pos}, after the last complete "
                                        "record")
                    return
                if len(head) < _REC.size:
                    if self._ends_with_footer(f, size):
                        raise self._error(pos, "a record header runs into the end of a closed "
                                          "file (a damaged length field before it)", scan)
                    scan.stop_reason = f"file ends inside a record header at byte {pos}"
                    return
                op, length = _REC.unpack(head)
                name = _OP_NAMES.get(op, f"opcode {op:#04x}")
                if op == 0:
                    raise self._error(pos, "invalid record opcode 0x00", scan)
                if pos + _REC.size + length > size:
                    present = size - pos - _REC.size
                    if length > MAX_RECORD_BYTES or self._ends_with_footer(f, size):
                        # A closed file cannot end inside a record: its length is wrong.
                        raise self._error(pos, f"{name} record claims {length} bytes, only "
                                          f"{present} follow (a damaged length field)", scan)
                    scan.stop_reason = (f"file ends inside a {name} record at byte {pos} "
                                        f"({present} of {length} bytes present)")
                    return
                body = memoryview(f.read(length))
                if first and op != OP_HEADER:
                    raise self._error(pos, f"first record is a {name}, not a Header", scan)
                first = False
                try:
                    if op == OP_DATA_END:
                        stored = _Cursor(body).u32()
                        if stored and stored != crc:
                            raise _Corrupt("data section CRC mismatch")
                    else:
                        crc = crc32(body, crc32(head, crc))
                    if op == OP_CHUNK:
                        scan.chunks += 1
                        yield from self._chunk(body, scan, wanted, keep)
                    elif op == OP_MESSAGE:
                        m = self._message(body, 0, len(body), scan, wanted, keep)
                        if m is not None:
                            yield m
                    elif op == OP_CHANNEL:
                        ch = _channel_from(_Cursor(body))
                        scan.channels.setdefault(ch.id, ch)
                    elif op == OP_SCHEMA:
                        self._schema(_Cursor(body), scan)
                    elif op == OP_METADATA:
                        cur = _Cursor(body)
                        mname = cur.text()
                        scan.metadata[mname] = cur.string_map()
                    elif op == OP_HEADER:
                        cur = _Cursor(body)
                        scan.profile, scan.library = cur.text(), cur.text()
                    elif op == OP_FOOTER:
                        tail = f.read(len(MAGIC))
                        if tail == MAGIC:
                            scan.complete = True
                            scan.stop_reason = "complete (footer and closing magic present)"
                        else:
                            scan.stop_reason = "file ends inside the closing magic"
                        return
                    # everything else (indexes, statistics, attachments) is not needed
                except _Corrupt as exc:
                    raise self._error(pos, f"{name} record: {exc}", scan) from None
                pos += _REC.size + length

    @staticmethod
    def _schema(cur: _Cursor, scan: _Scan) -> None:
        sid = cur.u16()
        name, encoding = cur.text(), cur.text()
        scan.schemas[sid] = (name, encoding, bytes(cur.take(cur.u32())))

    def _chunk(self, body: memoryview, scan: _Scan, wanted: Callable[[_Chan], bool] | None,
               keep: dict[int, bool]) -> Iterator[_Msg]:
        cur = _Cursor(body)
        _start, _end, usize, ucrc = _CHUNK.unpack(cur.take(_CHUNK.size))
        compression = cur.text()
        data = cur.take(cur.u64())
        buf = _decompress(compression, data, usize)  # type: ignore[arg-type]
        if len(buf) != usize:
            raise _Corrupt(f"chunk holds {len(buf)} bytes, its header says {usize}")
        if ucrc and crc32(buf) != ucrc:
            raise _Corrupt("chunk CRC mismatch")
        mv = memoryview(buf)
        p, n = 0, len(buf)
        msg = self._message
        while p < n:
            if p + _REC.size > n:
                raise _Corrupt("record header runs past the end of the chunk")
            op, length = _REC.unpack_from(buf, p)
            p += _REC.size
            end = p + length
            if end > n:
                raise _Corrupt("record runs past the end of the chunk")
            if op == OP_MESSAGE:
                m = msg(mv, p, end, scan, wanted, keep)
                if m is not None:
                    yield m
            elif op == OP_CHANNEL:
                ch = _channel_from(_Cursor(mv[p:end]))
                scan.channels.setdefault(ch.id, ch)
            elif op == OP_SCHEMA:
                self._schema(_Cursor(mv[p:end]), scan)
            p = end

    @staticmethod
    def _message(buf: memoryview, p: int, end: int, scan: _Scan,
                 wanted: Callable[[_Chan], bool] | None, keep: dict[int, bool]) -> _Msg | None:
        if end - p < _MSG.size:
            raise _Corrupt("message shorter than its 22-byte header")
        cid, _seq, log_ns, pub_ns = _MSG.unpack_from(buf, p)
        ch = scan.channels.get(cid)
        if ch is None:
            raise _Corrupt(f"message on channel {cid}, which has no Channel record before it")
        data = buf[p + _MSG.size:end]
        if ch.block:
            if ch.wrapped:
                try:
                    count = rawpb.block_count(data)
                except ValueError as exc:
                    raise _Corrupt(f"{ch.topic}: block message: {exc}") from None
            else:
                if len(data) < BLOCK_HEADER.size:
                    raise _Corrupt(f"{ch.topic}: block shorter than its header")
                magic, count, _w, _c = BLOCK_HEADER.unpack_from(data)
                if magic != BLOCK_MAGIC:
                    raise _Corrupt(f"{ch.topic}: block magic {bytes(magic)!r} is not "
                                   f"{BLOCK_MAGIC!r}")
            last = pub_ns if count else log_ns
        else:
            count, last = 1, log_ns
        ch.messages += 1
        ch.frames += count
        if ch.first_ns is None:
            ch.first_ns = log_ns
        if ch.last_ns is None or last > ch.last_ns:
            ch.last_ns = last
        if scan.last_ns is None or last > scan.last_ns:
            scan.last_ns = last
        ok = keep.get(cid)
        if ok is None:
            ok = keep[cid] = wanted is None or wanted(ch)
        return _Msg(ch, log_ns, pub_ns, data) if ok else None

    @staticmethod
    def _selector(topics: Iterable[str] | None) -> Callable[[_Chan], bool] | None:
        if topics is None:
            return None
        want = set(topics)
        return lambda ch: ch.topic in want

    # -- public API ----------------------------------------------------------------------
    def info(self) -> LogInfo:
        """Read the whole log (every chunk, CRCs checked) and summarise it."""
        scan = _Scan()
        for _ in self._walk(scan, lambda ch: False):
            pass
        return self._info(scan)

    def _info(self, scan: _Scan) -> LogInfo:
        chans = [_channel_info(ch, scan) for ch in sorted(scan.channels.values(),
                                                          key=lambda c: c.id)]
        firsts = [c.first_ns for c in chans if c.first_ns is not None]
        lasts = [c.last_ns for c in chans if c.last_ns is not None]
        return LogInfo(
            path=str(self.path), size=self.path.stat().st_size, profile=scan.profile,
            library=scan.library, level=scan.metadata.get(METADATA_NAME, {}).get("level"),
            metadata=scan.metadata, channels=tuple(chans),
            message_count=sum(c.message_count for c in chans),
            frame_count=sum(c.frame_count for c in chans), chunk_count=scan.chunks,
            start_ns=min(firsts) if firsts else None, end_ns=max(lasts) if lasts else None,
            complete=scan.complete, truncated=not scan.complete,
            readable_until_ns=scan.last_ns, stop_reason=scan.stop_reason)

    def frames(self, topics: Iterable[str] | None = None,
               order: str = "time") -> Iterator[tuple[str, int, bytes]]:
        """``(topic, t_ns, frame bytes)`` for every frame of ``topics`` (None: all).

        ``order="time"``: by simulated time, ties in file order (blocks are written after
        the frames of other channels that fall inside them, so this holds the selected
        frames in memory to sort them). ``order="file"``: as stored, constant memory; each
        channel on its own is still in time order. Stops quietly at the end of a truncated
        log (see :meth:`info`).
        """
        if order not in ("time", "file"):
            raise ValueError(f"order must be 'time' or 'file', got {order!r}")
        msgs = self._walk(_Scan(), self._selector(topics))
        return self._file_ordered(msgs) if order == "file" else self._time_ordered(msgs,
                                                                                    self.path)

    @staticmethod
    def _file_ordered(msgs: Iterator[_Msg]) -> Iterator[tuple[str, int, bytes]]:
        for m in msgs:
            if m.chan.block:
                t, fr = _block(m)
                topic = m.chan.topic
                for i in range(t.shape[0]):
                    yield topic, int(t[i]), fr[i].tobytes()
            else:
                yield m.chan.topic, m.log_ns, bytes(_single(m))

    @staticmethod
    def _time_ordered(msgs: Iterator[_Msg], path: Path) -> Iterator[tuple[str, int, bytes]]:
        # Singles go to plain lists; blocks stay numpy views. One lexsort over
        # (time, message number, row) then gives time order with ties in file order.
        s_t: list[int] = []
        s_seq: list[int] = []
        s_ref: list[tuple[str, bytes]] = []
        b_t: list[np.ndarray] = []
        b_seq: list[int] = []
        b_ref: list[tuple[str, np.ndarray]] = []
        for k, m in enumerate(msgs):
            if m.chan.block:
                t, fr = _block(m)
                b_t.append(t)
                b_seq.append(k)
                b_ref.append((m.chan.topic, fr))
            else:
                s_t.append(m.log_ns)
                s_seq.append(k)
                s_ref.append((m.chan.topic, bytes(_single(m))))
        sizes = [t.shape[0] for t in b_t]
        times = np.concatenate([_times(s_t, b_t, path), *b_t]) if (s_t or b_t) \
            else np.zeros(0, np.int64)
        seq = np.concatenate([np.asarray(s_seq, dtype=np.int64),
                              np.repeat(np.asarray(b_seq, dtype=np.int64), sizes)])
        src = np.concatenate([np.full(len(s_t), -1, dtype=np.int64),
                              np.repeat(np.arange(len(b_t), dtype=np.int64), sizes)])
        row = np.concatenate([np.arange(len(s_t), dtype=np.int64),
                              *(np.arange(n, dtype=np.int64) for n in sizes)])
        for k in np.lexsort((row, seq, times)).tolist():
            s, r = int(src[k]), int(row[k])
            if s < 0:
                topic, data = s_ref[r]
                yield topic, int(times[k]), data
            else:
                topic, fr = b_ref[s]
                yield topic, int(times[k]), fr[r].tobytes()

    def raw_channels(self, topics: Iterable[str] | None = None) -> dict[str, RawChannel]:
        """Every frame of ``topics`` (None: all) grouped by channel, in one pass: blocks as
        stacked arrays, single frames as a list (see :class:`RawChannel`); a selected
        channel without frames is there, empty."""
        want = None if topics is None else set(topics)
        scan = _Scan()
        acc = _RawAccum(self.path)
        for k, m in enumerate(self._walk(scan, self._selector(want))):
            acc.add(k, m)
        return acc.take([ch for ch in sorted(scan.channels.values(), key=lambda c: c.id)
                         if want is None or ch.topic in want])

    def raw_batches(self, topics: Iterable[str] | None = None,
                    batch_bytes: int = 16 << 20) -> RawBatches:
        """The frames of :meth:`raw_channels` a batch at a time, in file order: each batch
        holds the frames of the messages read since the last one (about ``batch_bytes`` of
        frame data), per channel that has any, with ``seq`` numbered over the whole file
        as in :meth:`raw_channels`. What a streaming export decodes, in bounded memory;
        the returned iterable also describes what it has read (:class:`RawBatches`)."""
        return RawBatches(self, topics, batch_bytes)

    def blocks(self, topic: str) -> Blocks:
        """All frames of ``topic`` as numpy arrays, for replay: ``t_ns`` (n,) int64 and
        ``frames`` (n, width) of the channel's dtype (uint8 bytes for a single-frame
        channel, whose frames must then all have the same length).

        FrameLogError if the topic is not in the log or its frames differ in length.
        """
        return self.blocks_many([topic])[topic]

    def blocks_many(self, topics: Iterable[str]) -> dict[str, Blocks]:
        """:meth:`blocks` of several topics in one pass over the file."""
        want = list(dict.fromkeys(topics))
        scan = _Scan()
        ts: dict[int, list[np.ndarray]] = {}
        fs: dict[int, list[np.ndarray]] = {}
        singles: dict[int, list[memoryview]] = {}
        singles_t: dict[int, list[int]] = {}
        for m in self._walk(scan, self._selector(want)):
            cid = m.chan.id
            if m.chan.block:
                t, fr = _block(m)
                if fr.shape[1] != m.chan.width or fr.dtype != m.chan.dtype:
                    raise FrameLogError(f"{self.path}: {m.chan.topic}: a block of "
                                        f"{fr.shape[1]} x {fr.dtype} frames on a channel of "
                                        f"{m.chan.width} x {m.chan.dtype}")
                ts.setdefault(cid, []).append(t)
                fs.setdefault(cid, []).append(fr)
            else:
                singles_t.setdefault(cid, []).append(m.log_ns)
                singles.setdefault(cid, []).append(_single(m))
        by_topic = {c.topic: c for c in scan.channels.values()}
        out: dict[str, Blocks] = {}
        for topic in want:
            ch = by_topic.get(topic)
            if ch is None:
                raise FrameLogError(f"{self.path}: no topic {topic!r} (topics: "
                                    f"{', '.join(by_topic) or 'none'})")
            if ch.block:
                t_list = ts.get(ch.id, [])
                times = np.concatenate(t_list) if t_list else np.zeros(0, np.int64)
                assert ch.dtype is not None and ch.width is not None
                f_list = fs.get(ch.id, [])
                frames = np.concatenate(f_list) if f_list else np.zeros((0, ch.width),
                                                                         ch.dtype)
            else:
                data = singles.get(ch.id, [])
                lengths = {len(d) for d in data}
                if len(lengths) > 1:
                    raise FrameLogError(f"{self.path}: {topic}: frames of different lengths "
                                        f"({min(lengths)}..{max(lengths)} bytes) do not stack")
                width = lengths.pop() if lengths else 0
                frames = np.frombuffer(b"".join(data), np.uint8).reshape(len(data), width)
                times = _times(singles_t.get(ch.id, []), [], self.path)
            out[topic] = Blocks(times, frames)
        return out



def _channel_info(ch: _Chan, scan: _Scan) -> ChannelInfo:
    sname, senc, sdata = scan.schemas.get(ch.schema_id, ("", "", b""))
    return ChannelInfo(ch.id, ch.topic, ch.encoding, ch.message_encoding,
                       "block" if ch.block else "single", sname, senc, dict(ch.metadata),
                       None if ch.dtype is None else ch.dtype.name, ch.width,
                       ch.messages, ch.frames, ch.first_ns, ch.last_ns, sdata)


class RawBatches:
    """The batches of :meth:`FrameLogReader.raw_batches` (iterate once); meanwhile
    :meth:`channel` describes a channel as far as read (its schema, its first message's
    time), and :meth:`info` is the log's :meth:`FrameLogReader.info` once the batches are
    exhausted (one pass over the file serves both)."""

    def __init__(self, reader: FrameLogReader, topics: Iterable[str] | None,
                 batch_bytes: int) -> None:
        self.reader = reader
        self.want = None if topics is None else set(topics)
        self.batch_bytes = batch_bytes
        self.scan = _Scan()
        self._done = False

    def __iter__(self) -> Iterator[dict[str, RawChannel]]:
        acc = _RawAccum(self.reader.path)
        size = 0
        walk = self.reader._walk(self.scan, self.reader._selector(self.want))
        for k, m in enumerate(walk):
            size += acc.add(k, m)
            if size >= self.batch_bytes:
                yield acc.take(list(acc.chans.values()))
                size = 0
        if acc.chans:
            yield acc.take(list(acc.chans.values()))
        self._done = True

    def channel(self, topic: str) -> ChannelInfo:
        """What has been read of ``topic``'s channel (KeyError: none of it yet)."""
        for ch in self.scan.channels.values():
            if ch.topic == topic:
                return _channel_info(ch, self.scan)
        raise KeyError(topic)

    def info(self) -> LogInfo:
        """The log's summary, as :meth:`FrameLogReader.info` (after the last batch)."""
        if not self._done:
            raise RuntimeError("RawBatches.info() before the batches are exhausted")
        return self.reader._info(self.scan)


class _RawAccum:
    """Frames of the messages added so far, per channel, until :meth:`take`."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._reset()

    def _reset(self) -> None:
        self.chans: dict[int, _Chan] = {}
        self.t_b: dict[int, list[np.ndarray]] = {}
        self.f_b: dict[int, list[np.ndarray]] = {}
        self.k_b: dict[int, list[int]] = {}
        self.t_s: dict[int, list[int]] = {}
        self.k_s: dict[int, list[int]] = {}
        self.p_s: dict[int, list[memoryview]] = {}

    def add(self, k: int, m: _Msg) -> int:
        """Message number ``k`` of the walk; returns its frame bytes."""
        cid = m.chan.id
        self.chans.setdefault(cid, m.chan)
        if m.chan.block:
            t, fr = _block(m)
            if fr.shape[1] != m.chan.width:
                raise FrameLogError(f"{self.path}: {m.chan.topic}: a block of "
                                    f"{fr.shape[1]}-element frames on a channel of "
                                    f"{m.chan.width}")
            self.t_b.setdefault(cid, []).append(t)
            self.f_b.setdefault(cid, []).append(fr)
            self.k_b.setdefault(cid, []).append(k)
            return fr.nbytes
        data = _single(m)
        self.t_s.setdefault(cid, []).append(m.log_ns)
        self.k_s.setdefault(cid, []).append(k)
        self.p_s.setdefault(cid, []).append(data)
        return len(data)

    def take(self, chans: list[_Chan]) -> dict[str, RawChannel]:
        """The frames of ``chans`` as :class:`RawChannel` (by topic); then start afresh."""
        out: dict[str, RawChannel] = {}
        for ch in chans:
            if ch.block:
                ts = self.t_b.get(ch.id, [])
                sizes = [len(t) for t in ts]
                assert ch.width is not None and ch.dtype is not None
                out[ch.topic] = RawChannel(
                    np.concatenate(ts) if ts else np.zeros(0, np.int64),
                    np.repeat(np.asarray(self.k_b.get(ch.id, []), np.int64), sizes),
                    np.concatenate([np.arange(n, dtype=np.int64) for n in sizes])
                    if sizes else np.zeros(0, np.int64),
                    np.concatenate(self.f_b[ch.id]) if ts else
                    np.zeros((0, ch.width), ch.dtype), None)
            else:
                t = _times(self.t_s.get(ch.id, []), [], self.path)
                out[ch.topic] = RawChannel(t, np.asarray(self.k_s.get(ch.id, []), np.int64),
                                           np.zeros(len(t), np.int64), None,
                                           self.p_s.get(ch.id, []))
        self._reset()
        return out


def _block(m: _Msg) -> tuple[np.ndarray, np.ndarray]:
    """Times and frames of a block message, either container."""
    if not m.chan.wrapped:
        return unpack_block(m.data)
    try:
        return rawpb.unpack_block(m.data)
    except ValueError as exc:
        raise FrameLogError(f"{m.chan.topic}: block message at t = {m.log_ns} ns: {exc}"
                            ) from None


def _single(m: _Msg) -> memoryview:
    """The frame of a single message (unwrapped from its protobuf message if wrapped)."""
    if not m.chan.wrapped:
        return m.data
    try:
        return rawpb.unwrap(m.data)
    except ValueError as exc:
        raise FrameLogError(f"{m.chan.topic}: message at t = {m.log_ns} ns: {exc}") from None


def _times(singles: list[int], blocks: list[np.ndarray], path: Path) -> np.ndarray:
    """Log times of single messages as an array: int64 as our logs write them, or uint64
    when a foreign MCAP file (log time is u64 there) holds times of 2^63 ns and beyond.
    ``blocks`` (int64 block times to be sorted with them) are converted in place to match;
    a negative block time cannot share an order with such times: FrameLogError."""
    if not singles or max(singles) <= _INT64_MAX:
        return np.asarray(singles, dtype=np.int64)
    for i, t in enumerate(blocks):
        if t.size and int(t.min()) < 0:
            raise FrameLogError(f"{path}: log times up to {max(singles)} ns (beyond 2^63) "
                                "next to negative block times cannot be ordered")
        blocks[i] = t.astype(np.uint64)
    return np.asarray(singles, dtype=np.uint64)
