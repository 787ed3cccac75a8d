"""The chunk of the mcap library's Writer: records built in one buffer kept for the file,
closed with one compressor kept at a chosen level, compressed where they lie.

``mcap.writer.Writer`` builds a chunk in a ``BytesIO`` (a new one per chunk: its memory is
fresh pages each time) and closes it by copying its records out (``getvalue``),
compressing them with a compressor made for the call at the codec's default level (zstd
3), copying the compressed bytes into a record buffer and that buffer out again before it
writes them. A whole-robot log passes ~50 MB per simulated second through this
(docs/framelog.md, "The whole robot"), so each copy and the level show in the run's CPU
time. :func:`install` gives one Writer a :class:`ChunkBuffer` (one array for the file's
life: :meth:`ChunkBuffer.reserve` lets :mod:`hil.framelog.batch` build record arrays in
place, no copy into the chunk) and replaces its private ``__finalize_chunk`` by
:func:`_finalize`, which writes the same records (chunk, message indexes, chunk index, the
data-section CRC) from a view of that buffer with a compressor kept for the file at
``level``.

The chunk's integrity check: a zstd chunk carries zstd's own content checksum (xxh64, which
every zstd decoder checks: the mcap library's, ours) and the chunk record's CRC field 0
(MCAP: not computed), which costs half of a CRC-32 over the uncompressed bytes; lz4 and
uncompressed chunks keep the CRC-32. A flipped byte in a chunk fails either way.

Like :mod:`hil.framelog.batch`, this uses the Writer's private state (mcap 1.x);
:func:`supported` checks it is there, and without it the library's own method stays (a
future mcap release can make logging slower, never wrong). At the library's level, lz4 and
uncompressed files are byte for byte the library's: ``tests/framelog/test_chunk.py``.
"""

from __future__ import annotations

import contextlib
import functools
import struct
from collections.abc import Callable, Iterator
from io import BytesIO

import lz4.frame
import numpy as np
import zstandard
from mcap.records import Channel, ChunkIndex, Opcode
from mcap.writer import IndexType, Writer

try:  # zlib-ng's CRC-32: the same function as zlib's, ~9x faster here (carry-less multiply)
    from zlib_ng.zlib_ng import crc32
except ImportError:  # an environment made before that dependency: zlib's
    from zlib import crc32

#: zstd level of our logs when none is given: against the library's 3, about half the
#: compression time for ~15 % more bytes; against level 1, 12 % less time for 7 % more
#: bytes (measured on the chunks of a whole-robot log, docs/framelog.md "The whole robot").
ZSTD_LEVEL = -1
#: zstd level of the decoded signals' chunks (:data:`hil.framelog.writer.SIGNAL_CHUNKS`):
#: zstd's fast strategy with an acceleration of 9, which tries a match every ~10 bytes of
#: the changing floats where -7 tries every ~8 (docs/framelog.md, "The match finder of the
#: writer's levels").
SIGNAL_LEVEL = -9
#: zstd level of the actuators' decoded signals' chunks (``/signals/actuator/``, 47,000
#: messages per simulated second of the whole robot: two thirds of the signals' bytes):
#: an acceleration of 60 with a table of 2^8 entries. Each record of these chunks is one
#: run of changing floats (~110 of its ~245 bytes, which zstd stores as they are) and one
#: steady run; a step of 61 bytes lands in the steady run at its first or second try, so
#: zstd tries a match a third as often as at -19 for ~10 % more bytes: ~35 % less
#: compression CPU (-19 was ~2 ms per simulated second less than :data:`SIGNAL_LEVEL`;
#: docs/framelog.md, "The actuators' signal chunks at -19" and "The signals' batches and
#: the actuators' chunks at -60").
ACTUATOR_SIGNAL_LEVEL = -60
#: zstd level of the register words' blocks (``/lvds/...``: the MCU words as raw blocks,
#: ~5.6 MB per simulated second of the whole robot after their planes of zeros are cut,
#: nearly half of it the sensors' noisy low bits as bit planes, in which zstd finds no
#: match): an acceleration of 30 with a table of 2^10 entries. On those blocks of a robot
#: second, ~60 % less compression CPU than :data:`ZSTD_LEVEL` for ~19 % more of their
#: compressed bytes (2.74 -> 3.26 MB; the log ~4 % larger); docs/framelog.md, "The
#: register words' chunks at -30".
REGISTER_BLOCK_LEVEL = -30
#: What the writer's own zstd levels (:data:`ZSTD_LEVEL`, :data:`SIGNAL_LEVEL`,
#: :data:`ACTUATOR_SIGNAL_LEVEL`, and -7 and -19, levels of the signals before) change in
#: zstd's parameters of that level: a smaller match table (zstd's: 2^13 entries; 2^12 is
#: 16 KiB, which stays in the L1 cache beside the data; the signals' 2^11: a message's
#: steady fields match the same field of the previous message, which the last few hundred
#: bytes hold) and matches of at least 7 bytes
#: (zstd's: 6; a sensor word's noise makes many 6-byte matches that save little and cost a
#: sequence each). On the chunks of a second of the whole robot (``python -m
#: hil.bench.log_chunks``; docs/framelog.md, "Compression level"): at -1 ~9 % less
#: compression CPU for ~3 % more bytes of those chunks, at -7 ~19 % less for ~5 % more;
#: the signals at -9 with 2^11 entries ~18 % less than at -7 with 2^12 for ~2.5 % more.
#: Any reader reads the frames (zstd's format leaves the match finder to the writer).
TUNED = {ZSTD_LEVEL: {"hash_log": 12, "min_match": 7}, -7: {"hash_log": 12, "min_match": 7},
         SIGNAL_LEVEL: {"hash_log": 11, "min_match": 7},
         -19: {"hash_log": 8, "min_match": 7},  # the actuators' signals' level before
         ACTUATOR_SIGNAL_LEVEL: {"hash_log": 8, "min_match": 7},
         REGISTER_BLOCK_LEVEL: {"hash_log": 10, "min_match": 7}}
TUNED_LEVELS = tuple(TUNED)
#: A chunk buffer's first capacity, in chunks (:class:`ChunkBuffer`: address space; the
#: memory is what the largest chunk and the batch that closed it write), up to
#: :data:`RESERVE_MAX` bytes (at least 1.25 chunks).
RESERVE = 16
RESERVE_MAX = 1 << 28
#: Chunk record: opcode, record length, start and end time, uncompressed size and CRC.
_HEAD = struct.Struct("<BQQQQI")
_CHUNK_OPCODE = 0x06
_PRIVATE = ("chunk_builder", "statistics", "enable_crcs", "enable_data_crcs",
            "data_section_crc", "stream", "record_builder", "index_types", "chunk_indices")


class ChunkBuffer:
    """The open chunk's records in one array kept for the file (grown when a batch needs
    more, never shrunk): the part of ``BytesIO`` the mcap library's ``RecordBuilder``
    uses (``write``, ``tell``, ``seek``, ``getvalue``, ``getbuffer``), :meth:`reserve` for
    records built in place, :meth:`reset` when the chunk is written. No fresh pages per
    chunk, no copy out of it.

    The array is ``numpy.empty``: memory the kernel maps as it is first written, never
    zeroed here. So ``capacity`` can be generous (:func:`install` gives
    :data:`RESERVE` chunks' worth): what is never written costs address space only, and
    a batch several chunks large (one ``write_blocks`` of every actuator of the whole
    robot: ~4 MB) finds its room without a grow. A ``bytearray`` is zeroed when made and
    each grow made a new one and copied into it: the whole robot's log grew its buffers
    three times to 8 MB, ~6 ms per run."""

    def __init__(self, capacity: int) -> None:
        self._buf = np.empty(max(capacity, 1 << 16), np.uint8)
        self._mv = memoryview(self._buf)
        self._pos = 0
        self._end = 0

    def _room(self, n: int) -> None:
        if self._pos + n > len(self._buf):  # a new array: views of the old one stay valid
            grown = np.empty(max(self._pos + n, 2 * len(self._buf)), np.uint8)
            grown[:self._end] = self._buf[:self._end]
            self._buf, self._mv = grown, memoryview(grown)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        if not isinstance(data, bytes | bytearray):
            data = memoryview(data).cast("B")
        n = len(data)
        self._room(n)
        self._mv[self._pos:self._pos + n] = data
        self._pos += n
        self._end = max(self._end, self._pos)
        return n

    def reserve(self, n: int) -> np.ndarray:
        """``n`` bytes at the write position as a writable uint8 array (their content is
        whatever was there: fill every byte), the position moved past them."""
        self._room(n)
        out = self._buf[self._pos:self._pos + n]
        self._pos += n
        self._end = max(self._end, self._pos)
        return out

    def drop(self, at: int) -> None:
        """Forget everything from ``at`` on (records reserved but never filled)."""
        self._pos = self._end = min(at, self._end)

    def tell(self) -> int:
        return self._pos

    def seek(self, pos: int, whence: int = 0) -> int:
        self._pos = pos if whence == 0 else (self._pos + pos if whence == 1 else
                                             self._end + pos)
        return self._pos

    def getbuffer(self) -> memoryview:
        return self._mv[:self._end]

    def getvalue(self) -> bytes:
        return bytes(self._mv[:self._end])

    def close(self) -> None:
        pass  # the array is kept for the next chunk

    def reset(self) -> None:
        self._pos = self._end = 0


def _capacity(chunk_size: int) -> int:
    return max(chunk_size + (chunk_size >> 2), min(RESERVE * chunk_size, RESERVE_MAX))


def supported(w: Writer) -> bool:
    """True if ``w`` has the private state :func:`_finalize` reads and updates."""
    have = all(hasattr(w, f"_Writer__{name}") for name in _PRIVATE)
    cb = getattr(w, "_Writer__chunk_builder", None)
    return (have and cb is not None and callable(getattr(w, "_Writer__flush", None))
            and callable(getattr(w, "_Writer__finalize_chunk", None))
            and isinstance(getattr(getattr(cb, "record_writer", None), "_buffer", None),
                           BytesIO | ChunkBuffer)
            and all(hasattr(cb, a) for a in ("message_indices", "num_messages",
                                             "message_start_time", "message_end_time")))


def compressor(compression: str, level: int | None) -> Callable[[memoryview], bytes]:
    """bytes-like -> compressed bytes, for ``zstd`` (``level`` None: :data:`ZSTD_LEVEL`;
    the levels of :data:`TUNED_LEVELS` with their parameters in :data:`TUNED`; frames with
    zstd's content checksum) or ``lz4`` (None: the library's default)."""
    if compression == "zstd":
        lvl = ZSTD_LEVEL if level is None else level
        if lvl in TUNED_LEVELS:
            params = zstandard.ZstdCompressionParameters.from_level(
                lvl, write_checksum=1, **TUNED[lvl])
            return zstandard.ZstdCompressor(compression_params=params).compress
        return zstandard.ZstdCompressor(level=lvl, write_checksum=True).compress
    if compression == "lz4":
        lvl = 0 if level is None else level
        return lambda data: lz4.frame.compress(data, compression_level=lvl)
    raise ValueError(f"compression {compression!r} has no compressor here")


#: A kind of chunk: compression and level (None: the codec's default here).
Kind = tuple[str, int | None]


def install(w: Writer, compression: str, level: int | None, chunk_size: int,
            others: tuple[Kind, ...] = ()) -> bool:
    """Make ``w`` build its chunks in a :class:`ChunkBuffer` (of ``chunk_size`` bytes to
    start with) and close them with :func:`_finalize` (``compression`` zstd or lz4 at
    ``level``, or none); False (and nothing changed) if ``w`` lacks the private state.
    ``others``: further kinds (compression ``none``, ``lz4`` or ``zstd``, and level), each
    with a chunk of its own open beside the first (:class:`Chunks`, :func:`use`)."""
    if not supported(w):
        return False
    rw = w._Writer__chunk_builder.record_writer  # noqa: SLF001 - see the module docstring
    buf = ChunkBuffer(_capacity(chunk_size))
    buf.write(rw._buffer.getvalue())  # noqa: SLF001 - empty before the first record
    buf.seek(rw._buffer.tell())  # noqa: SLF001
    rw._buffer = buf  # noqa: SLF001
    from hil.framelog import batch

    batch.lazy(w._Writer__chunk_builder)  # noqa: SLF001 - see :func:`write_indexes`
    first = _Kind(w._Writer__chunk_builder, compression, level)  # noqa: SLF001
    if not others:
        # an instance attribute: the Writer's own ``self.__finalize_chunk()`` finds it first
        w._Writer__finalize_chunk = lambda: _finalize(  # noqa: SLF001
            w, first.compress, first.name, first.crc)
        return True
    chunks = Chunks(w, first, [_Kind(_new_builder(chunk_size), *k)
                               for k in dict.fromkeys(others) if k != first.key])
    w._Writer__finalize_chunk = chunks.finalize_all  # noqa: SLF001
    w._Writer__maybe_finalize_chunk = chunks.maybe_finalize  # noqa: SLF001
    w._eha_chunks = chunks  # noqa: SLF001 - found by use()
    return True


class _Kind:
    """One compression's chunk builder and how its chunks are closed."""

    def __init__(self, builder: object, compression: str, level: int | None) -> None:
        self.builder = builder
        self.key = (compression, None if compression == "none" else level)
        self.compress = None if compression == "none" else compressor(compression, level)
        self.name = b"" if self.compress is None else compression.encode()  # "": none
        self.crc = compression != "zstd"  # zstd frames carry their own checksum


def _new_builder(chunk_size: int) -> object:
    """A chunk builder like the Writer's own, its records in a :class:`ChunkBuffer`."""
    from mcap._chunk_builder import ChunkBuilder

    cb = ChunkBuilder()
    from hil.framelog import batch

    batch.lazy(cb)  # see write_indexes
    cb.record_writer._buffer = ChunkBuffer(_capacity(chunk_size))  # noqa: SLF001
    return cb


class Chunks:
    """Chunks of several compressions open at once in one Writer: messages of a channel go
    to the chunk of its compression (:func:`use` before writing them), so that bytes zstd
    can do little with (e.g. decoded signals) need not pass through it. The Writer's
    schema and channel records go to the first kind's chunk (:func:`use_first`); a chunk
    of another kind is only written after every such record (the first kind's chunk is
    written before it when it holds any not yet written), so that a reader reading the
    file in order meets each channel before its messages. A chunk is closed when it is
    over the size (that chunk alone), and every open chunk by ``flush``, ``finish`` and
    the time-based flush."""

    def __init__(self, w: Writer, first: _Kind, others: list[_Kind]) -> None:
        self.w = w
        self.first = first
        self.kinds = {k.key: k for k in [first, *others]}
        self.defs_pending = False  # schema or channel records in the first kind's buffer

    def use(self, kind: Kind) -> None:
        self.w._Writer__chunk_builder = self.kinds[kind].builder  # noqa: SLF001

    def finalize(self, kind: _Kind) -> None:
        if kind is self.first:
            if kind.builder.num_messages:  # (else the records wait in its buffer)
                self.defs_pending = False
        elif self.defs_pending and kind.builder.num_messages:
            self._write_first()
        _finalize(self.w, kind.compress, kind.name, kind.crc, kind.builder)

    def _write_first(self) -> None:
        """The first kind's chunk now (its schema and channel records with it); without
        messages, those records alone, outside a chunk (as MCAP allows)."""
        cb = self.first.builder
        self.defs_pending = False
        if cb.num_messages:
            _finalize(self.w, self.first.compress, self.first.name, self.first.crc, cb)
            return
        buf = cb.record_writer._buffer  # noqa: SLF001
        if isinstance(buf, ChunkBuffer) and buf.tell():
            w = self.w
            w._Writer__flush()  # noqa: SLF001
            data = bytes(buf.getbuffer())
            if w._Writer__enable_data_crcs:  # noqa: SLF001
                w._Writer__data_section_crc = crc32(  # noqa: SLF001
                    data, w._Writer__data_section_crc)  # noqa: SLF001
            w._Writer__stream.write(data)  # noqa: SLF001
            buf.reset()

    def finalize_all(self) -> None:
        for kind in self.kinds.values():  # the first kind first
            self.finalize(kind)

    def maybe_finalize(self) -> None:
        cb = self.w._Writer__chunk_builder  # noqa: SLF001
        if cb.count > self.w._Writer__chunk_size:  # noqa: SLF001
            self.finalize(next(k for k in self.kinds.values() if k.builder is cb))


def use(w: Writer, kind: Kind) -> None:
    """Send the next messages to ``w``'s open chunk of ``kind`` (installed with
    :func:`install`'s ``others``; nothing to do for a Writer with one kind)."""
    chunks = getattr(w, "_eha_chunks", None)
    if chunks is not None:
        chunks.use(kind)


def use_first(w: Writer) -> None:
    """Send the next records (schemas, channels) to the first kind's chunk."""
    chunks = getattr(w, "_eha_chunks", None)
    if chunks is not None:
        chunks.use(chunks.first.key)
        chunks.defs_pending = True


class Made:
    """The bytes of the records made inside :func:`definitions` (``data``; empty where
    the chunk buffer is not installed)."""

    data: bytes = b""


@contextlib.contextmanager
def definitions(w: Writer) -> Iterator[Made]:
    """Schema and channel records registered inside go to the first kind's chunk
    (:func:`use_first`), each built in a ``BytesIO`` and put into the chunk's
    :class:`ChunkBuffer` as one write: the library's ``Channel.write`` makes ~27 small
    writes per record, each a Python call here (~6 ms for the 200 channels of a
    whole-robot log). The chunk's size is checked once, after. Yields a :class:`Made`
    that holds the records' bytes once the block ends (:func:`keep_channel`)."""
    use_first(w)
    made = Made()
    cb = w._Writer__chunk_builder  # noqa: SLF001 - see the module docstring
    rw = getattr(cb, "record_writer", None)
    buf = getattr(rw, "_buffer", None)
    if not isinstance(buf, ChunkBuffer):
        yield made
        return
    had = "_Writer__maybe_finalize_chunk" in vars(w)
    check = w._Writer__maybe_finalize_chunk  # noqa: SLF001
    # no chunk closed while the records are apart from the chunk's buffer
    w._Writer__maybe_finalize_chunk = _nothing  # noqa: SLF001
    tmp = BytesIO()
    rw._buffer = tmp  # noqa: SLF001
    try:
        yield made
    finally:
        rw._buffer = buf  # noqa: SLF001
        made.data = tmp.getvalue()
        buf.write(made.data)
        if had:
            w._Writer__maybe_finalize_chunk = check  # noqa: SLF001
        else:
            del w._Writer__maybe_finalize_chunk  # noqa: SLF001 - the class's method again
    check()


class _WrittenChannel(Channel):
    """A channel whose record (the bytes :meth:`Channel.write` makes) is kept: the
    summary's copy of it is written as they are (the library: ~27 small writes per
    channel at the file's end, ~1.2 ms for the 200 channels of a whole-robot log)."""

    record: bytes = b""

    def write(self, stream) -> None:  # noqa: ANN001 - mcap's RecordBuilder
        stream.write(self.record)


def keep_channel(w: Writer, channel_id: int, made: Made) -> None:
    """Keep the record of the channel ``channel_id`` just registered inside
    :func:`definitions` (``made``) for the summary, when ``made`` holds that record
    alone (else the library writes it again from its fields)."""
    channels = getattr(w, "_Writer__channels", None)
    ch = channels.get(channel_id) if isinstance(channels, dict) else None
    data = made.data
    if type(ch) is not Channel or len(data) < 9 or data[0] != Opcode.CHANNEL \
            or int.from_bytes(data[1:9], "little") != len(data) - 9:
        return
    kept = _WrittenChannel(id=ch.id, topic=ch.topic, message_encoding=ch.message_encoding,
                           metadata=ch.metadata, schema_id=ch.schema_id)
    kept.record = data
    channels[channel_id] = kept


class _ChunkIndex(ChunkIndex):
    """A ChunkIndex written as one write, its offsets (channel, offset) as one array (the
    library's: two writes per channel of the chunk, ~50 per chunk of a whole-robot log);
    the same bytes."""

    def write(self, stream) -> None:  # noqa: ANN001 - mcap's RecordBuilder
        offsets = self.message_index_offsets
        pairs = np.empty(len(offsets), _OFFSET)
        if offsets:
            pairs["ch"] = list(offsets)
            pairs["off"] = list(offsets.values())
        name = self.compression.encode()
        body = b"".join((
            _INDEX_TIMES.pack(self.message_start_time, self.message_end_time,
                              self.chunk_start_offset, self.chunk_length, pairs.nbytes),
            pairs.tobytes(), _INDEX_NAME.pack(self.message_index_length, len(name)), name,
            _INDEX_SIZES.pack(self.compressed_size, self.uncompressed_size)))
        stream.write(_REC.pack(Opcode.CHUNK_INDEX, len(body)) + body)


_OFFSET = np.dtype([("ch", "<u2"), ("off", "<u8")])
_REC = struct.Struct("<BQ")
_INDEX_TIMES = struct.Struct("<QQQQI")
_INDEX_NAME = struct.Struct("<QI")
_INDEX_SIZES = struct.Struct("<QQ")


def _nothing() -> None:
    pass


def _finalize(w: Writer, compress: Callable[[memoryview], bytes] | None, name: bytes,
              crc_on: bool, cb: object = None) -> None:
    """The library's ``__finalize_chunk`` (same records, same order) without its copies,
    of the chunk builder ``cb`` (None: the Writer's): the chunk record's head, its
    compressed records and its message indexes handed to the stream as one write
    (:func:`write_parts`; the library: three, the indexes copied through its record
    builder)."""
    if cb is None:
        cb = w._Writer__chunk_builder  # noqa: SLF001 - see the module docstring
    if cb is None or cb.num_messages == 0:
        return
    w._Writer__statistics.chunk_count += 1  # noqa: SLF001
    buf = cb.record_writer._buffer  # noqa: SLF001
    rb = w._Writer__record_builder  # noqa: SLF001
    if rb.count:  # records buffered before the chunk go first
        w._Writer__flush()  # noqa: SLF001
    stream = w._Writer__stream  # noqa: SLF001
    start = stream.tell()
    view = buf.getbuffer()
    try:
        size = len(view)
        data = view if compress is None else compress(view)
        crc = crc32(view) if crc_on and w._Writer__enable_crcs else 0  # noqa: SLF001
        compressed = len(data)
        body = 8 + 8 + 8 + 4 + 4 + len(name) + 8 + compressed
        head = b"".join((_HEAD.pack(_CHUNK_OPCODE, body, cb.message_start_time,
                                    cb.message_end_time, size, crc),
                         struct.pack("<I", len(name)), name, struct.pack("<Q", compressed)))
        index = _ChunkIndex(message_start_time=cb.message_start_time,
                           message_end_time=cb.message_end_time, chunk_start_offset=start,
                           chunk_length=len(head) + compressed, message_index_offsets={},
                           message_index_length=0, compression=name.decode(),
                           compressed_size=compressed, uncompressed_size=size)
        parts = [head, data]
        if w._Writer__index_types & IndexType.MESSAGE:  # noqa: SLF001
            indexes = _Collect()
            write_indexes(cb.message_indices, indexes, start + len(head) + compressed,
                          index.message_index_offsets, _kept(cb))
            index.message_index_length = indexes.count
            parts += indexes.parts
        if w._Writer__enable_data_crcs:  # noqa: SLF001
            at = w._Writer__data_section_crc  # noqa: SLF001
            for part in parts:
                at = crc32(part, at)
            w._Writer__data_section_crc = at  # noqa: SLF001
        write_parts(stream, parts)
    finally:
        data = parts = None
        view.release()
    if isinstance(buf, ChunkBuffer):
        buf.reset()
    else:
        cb.record_writer._buffer = BytesIO()  # noqa: SLF001 - the records are written
    w._Writer__chunk_indices.append(index)  # noqa: SLF001
    # ChunkBuilder.reset, less its copy of the (already replaced) buffer
    cb.message_end_time = 0
    _forget(cb)
    cb.message_start_time = 0
    cb.num_messages = 0


class _Collect:
    """What :func:`write_indexes` writes, kept as its parts (``write``) and their length
    (``count``), to go out with the chunk in one write."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.count = 0

    def write(self, data: bytes) -> None:
        self.parts.append(data)
        self.count += len(data)


def write_parts(stream: object, parts: list) -> None:
    """``parts`` (bytes-likes) written to ``stream`` in order: one ``writev`` where the
    stream has one (the writer's file: one system call), else a ``write`` each."""
    writev = getattr(stream, "writev", None)
    if writev is not None:
        writev(parts)
        return
    for part in parts:
        stream.write(part)  # type: ignore[attr-defined]


def _kept(cb: object) -> list[tuple[np.ndarray, list[int]]] | None:
    """The batches chunk builder ``cb`` kept when they are its chunk's indexes
    (:func:`hil.framelog.batch.clean`); else None, their entries put into its message
    indexes first (:func:`hil.framelog.batch.settle`)."""
    from hil.framelog import batch

    if batch.clean(cb):
        return cb.eha_batches
    batch.settle(cb)
    return None


def _forget(cb: object) -> None:
    from hil.framelog import batch

    batch.forget(cb)


#: A MessageIndex record of one entry (a channel with one message in the chunk: a block).
_ONE_INDEX = np.dtype([("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("n", "<u4"),
                       ("t", "<u8"), ("off", "<u8")])
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel, bytes of entries
_MESSAGE_INDEX_OPCODE = 0x07


@functools.lru_cache(maxsize=64)
def many_index(k: int) -> np.dtype:
    """A MessageIndex record of ``k`` (log time, offset) entries."""
    return np.dtype([("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("n", "<u4"),
                     ("e", "<u8", (k, 2))])


def write_indexes(indices: dict, rb: object, at: int, offsets: dict[int, int],
                  batches: list[tuple[np.ndarray, list[int]]] | None = None) -> None:
    """The chunk's MessageIndex records, in the order of ``indices`` (channel -> an index
    whose ``records`` are (log time, offset) pairs and (n, 2) arrays of them), as one write
    to ``rb`` starting at file offset ``at``; ``offsets[channel]`` set to each record's.
    ``batches``: instead of ``indices``, the chunk's indexes as the batches that made them
    (:func:`hil.framelog.batch.keep`: each batch's MessageIndex records already built, and
    their channels; each channel in one batch), written as they are.
    The bytes the library's ``MessageIndex.write`` makes, one by one; the records of one
    entry (most: a block channel's one message) built as one array."""
    if batches:
        _write_batches(batches, rb, at, offsets)
        return
    items = list(indices.items())
    one = [i for i, (_, mi) in enumerate(items)
           if len(mi.records) == 1 and type(mi.records[0]) is tuple]
    ones: dict[int, bytes] = {}
    if one:
        arr = np.zeros(len(one), _ONE_INDEX)
        arr["op"] = _MESSAGE_INDEX_OPCODE
        arr["len"] = _ONE_INDEX.itemsize - 9
        arr["ch"] = [items[i][0] for i in one]
        arr["n"] = 16
        arr["t"] = [items[i][1].records[0][0] for i in one]
        arr["off"] = [items[i][1].records[0][1] for i in one]
        blob = arr.tobytes()
        size = _ONE_INDEX.itemsize
        ones = {i: blob[j * size:(j + 1) * size] for j, i in enumerate(one)}
    # channels whose entries are one array (a batch's: every channel of a batch has as
    # many), built as one array per length
    runs: dict[int, list[int]] = {}
    for i, (_, mi) in enumerate(items):
        recs = mi.records
        if len(recs) == 1 and isinstance(recs[0], np.ndarray) and recs[0].ndim == 2:
            runs.setdefault(len(recs[0]), []).append(i)
    for k, idx in runs.items():
        dt = many_index(k)
        arr = np.empty(len(idx), dt)
        arr["op"] = _MESSAGE_INDEX_OPCODE
        arr["len"] = dt.itemsize - 9
        arr["ch"] = [items[i][0] for i in idx]
        arr["n"] = 16 * k
        arr["e"] = np.stack([items[i][1].records[0] for i in idx])
        blob = arr.tobytes()
        size = dt.itemsize
        ones.update({i: blob[j * size:(j + 1) * size] for j, i in enumerate(idx)})
    parts = []
    pos = at
    for i, (cid, mi) in enumerate(items):
        rec = ones.get(i)
        if rec is None:
            recs = mi.records
            if len(recs) == 1 and isinstance(recs[0], np.ndarray):  # a batch's entries
                body = recs[0].astype("<u8", copy=False).tobytes()
            else:  # runs of single pairs (add_message) as one array each, in order
                parts_of: list[np.ndarray] = []
                run: list[tuple[int, int]] = []
                for r in recs:
                    if type(r) is tuple:
                        run.append(r)
                        continue
                    if run:
                        parts_of.append(np.asarray(run, dtype="<u8"))
                        run = []
                    parts_of.append(np.asarray(r, dtype="<u8"))
                if run:
                    parts_of.append(np.asarray(run, dtype="<u8"))
                body = (np.concatenate(parts_of) if parts_of else np.zeros((0, 2), "<u8")
                        ).astype("<u8", copy=False).tobytes()
            rec = _INDEX_HEAD.pack(_MESSAGE_INDEX_OPCODE, 6 + len(body), cid, len(body)) + body
        offsets[cid] = pos
        parts.append(rec)
        pos += len(rec)
    rb.write(b"".join(parts))  # type: ignore[attr-defined]


def _write_batches(batches: list[tuple[np.ndarray, list[int]]], rb: object, at: int,
                   offsets: dict[int, int]) -> None:
    """:func:`write_indexes` of a chunk whose indexes are ``batches`` (each batch's
    MessageIndex records as rows of bytes, its channels): the arrays handed to ``rb``
    as they are (:class:`_Collect` keeps them for the chunk's one write; no copy)."""
    pos = at
    parts = getattr(rb, "parts", None)
    for arr, cids in batches:
        size = arr.shape[1]
        offsets.update(zip(cids, range(pos, pos + len(cids) * size, size), strict=True))
        pos += len(cids) * size
        if parts is not None:
            parts.append(arr)
    if parts is not None:
        rb.count += pos - at  # type: ignore[attr-defined]
    else:
        rb.write(b"".join(arr.tobytes() for arr, _ in batches))  # type: ignore[attr-defined]
