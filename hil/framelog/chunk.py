"""Closing a chunk of the mcap library's Writer: one compressor kept at a chosen level, and
the chunk's bytes compressed and checksummed where they lie.

``mcap.writer.Writer`` closes a chunk by copying its records out of the chunk buffer
(``getvalue``), compressing them with a compressor made for the call at the codec's
default level (zstd 3), copying the compressed bytes into a record buffer and that buffer
out again before it writes them. A whole-robot log passes ~55 MB per simulated second
through this (docs/framelog.md, "The whole robot"), so each copy and the level show in
the run's CPU time. :func:`install` replaces the Writer's private ``__finalize_chunk`` on
one Writer by :func:`_finalize`, which writes the same records (chunk, message indexes,
chunk index, the data-section CRC) from a view of the chunk buffer with a compressor kept
for the file at ``level``.

Like :mod:`hil.framelog.batch`, this uses the Writer's private state (mcap 1.x);
:func:`supported` checks it is there, and without it the library's own method stays (a
future mcap release can make logging slower, never wrong). At the library's level (zstd 3)
the file is byte for byte the library's: ``tests/framelog/test_chunk.py``.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from io import BytesIO

import lz4.frame
import zstandard
from mcap.records import ChunkIndex
from mcap.writer import IndexType, Writer

#: zstd level of our logs when none is given: against the library's 3, a quarter less
#: compression time for ~6 % more bytes (measured on the chunks of a whole-robot log).
ZSTD_LEVEL = 1
#: Chunk record: opcode, record length, start and end time, uncompressed size and CRC.
_HEAD = struct.Struct("<BQQQQI")
_CHUNK_OPCODE = 0x06
_PRIVATE = ("chunk_builder", "statistics", "enable_crcs", "enable_data_crcs",
            "data_section_crc", "stream", "record_builder", "index_types", "chunk_indices")


def supported(w: Writer) -> bool:
    """True if ``w`` has the private state :func:`_finalize` reads and updates."""
    have = all(hasattr(w, f"_Writer__{name}") for name in _PRIVATE)
    cb = getattr(w, "_Writer__chunk_builder", None)
    return (have and cb is not None and callable(getattr(w, "_Writer__flush", None))
            and callable(getattr(w, "_Writer__finalize_chunk", None))
            and isinstance(getattr(getattr(cb, "record_writer", None), "_buffer", None),
                           BytesIO)
            and all(hasattr(cb, a) for a in ("message_indices", "num_messages",
                                             "message_start_time", "message_end_time")))


def compressor(compression: str, level: int | None) -> Callable[[memoryview], bytes]:
    """bytes-like -> compressed bytes, for ``zstd`` (``level`` None: :data:`ZSTD_LEVEL`)
    or ``lz4`` (None: the library's default)."""
    if compression == "zstd":
        return zstandard.ZstdCompressor(level=ZSTD_LEVEL if level is None else level).compress
    if compression == "lz4":
        lvl = 0 if level is None else level
        return lambda data: lz4.frame.compress(data, compression_level=lvl)
    raise ValueError(f"compression {compression!r} has no compressor here")


def install(w: Writer, compression: str, level: int | None) -> bool:
    """Make ``w`` close its chunks with :func:`_finalize` (``compression`` zstd or lz4 at
    ``level``); False (and nothing changed) if ``w`` lacks the private state."""
    if not supported(w):
        return False
    compress = compressor(compression, level)
    name = compression.encode()
    # an instance attribute: the Writer's own ``self.__finalize_chunk()`` finds it first
    w._Writer__finalize_chunk = lambda: _finalize(w, compress, name)  # noqa: SLF001
    return True


def _finalize(w: Writer, compress: Callable[[memoryview], bytes], name: bytes) -> None:
    """The library's ``__finalize_chunk`` (same records, same order) without its copies."""
    cb = w._Writer__chunk_builder  # noqa: SLF001 - see the module docstring
    if cb is None or cb.num_messages == 0:
        return
    w._Writer__statistics.chunk_count += 1  # noqa: SLF001
    view = cb.record_writer._buffer.getbuffer()  # noqa: SLF001
    try:
        size = len(view)
        data = compress(view)
        crc = zlib.crc32(view) if w._Writer__enable_crcs else 0  # noqa: SLF001
    finally:
        view.release()
    cb.record_writer._buffer = BytesIO()  # noqa: SLF001 - the chunk's records are in data now
    w._Writer__flush()  # noqa: SLF001 - records buffered before the chunk go first
    stream = w._Writer__stream  # noqa: SLF001
    start = stream.tell()
    body = 8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(data)
    head = b"".join((_HEAD.pack(_CHUNK_OPCODE, body, cb.message_start_time,
                                cb.message_end_time, size, crc),
                     struct.pack("<I", len(name)), name, struct.pack("<Q", len(data))))
    if w._Writer__enable_data_crcs:  # noqa: SLF001
        w._Writer__data_section_crc = zlib.crc32(  # noqa: SLF001
            data, zlib.crc32(head, w._Writer__data_section_crc))  # noqa: SLF001
    stream.write(head)
    stream.write(data)
    index = ChunkIndex(message_start_time=cb.message_start_time,
                       message_end_time=cb.message_end_time, chunk_start_offset=start,
                       chunk_length=len(head) + len(data), message_index_offsets={},
                       message_index_length=0, compression=name.decode(),
                       compressed_size=len(data), uncompressed_size=size)
    rb = w._Writer__record_builder  # noqa: SLF001
    at = stream.tell()
    if w._Writer__index_types & IndexType.MESSAGE:  # noqa: SLF001
        for cid, mi in cb.message_indices.items():
            index.message_index_offsets[cid] = at + rb.count
            mi.write(rb)
    index.message_index_length = rb.count
    w._Writer__flush()  # noqa: SLF001
    w._Writer__chunk_indices.append(index)  # noqa: SLF001
    # ChunkBuilder.reset, less its copy of the (already replaced) buffer
    cb.message_end_time = 0
    cb.message_indices.clear()
    cb.message_start_time = 0
    cb.num_messages = 0
