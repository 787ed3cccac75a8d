"""Chunks closed by hil.framelog.chunk: at the library's own level the very file the mcap
library writes; at ours, a file the mcap reader reads back with every CRC checked."""

from __future__ import annotations

import io
import os
import zlib
from pathlib import Path

import numpy as np
import pytest
import zstandard
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import (
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Message,
    MessageIndex,
    MetadataIndex,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader, breakup_chunk

from hil.framelog import FrameLogWriter, chunk


def _log(path: Path, compression: str, level: int | None, ours: bool) -> bytes:
    if not ours:  # the library's own __finalize_chunk
        mp = pytest.MonkeyPatch()
        mp.setattr(chunk, "install", lambda *a: False)
    try:
        rng = np.random.default_rng(5)
        with FrameLogWriter(path, compression=compression, compression_level=level,
                            chunk_size=1500) as w:
            blk = w.add_block_channel("/b", "eha-hil/test", dtype=np.uint16, width=5)
            one = w.add_channel("/one", "eha-hil/test-frame")
            for k in range(12):
                t = np.arange(40, dtype=np.int64) + 40 * k
                w.write_block(blk, t, rng.integers(0, 50, (40, 5)))
                w.write(one, int(t[-1]), bytes(rng.integers(0, 256, 30, dtype=np.uint8)))
                if k == 6:
                    w.add_metadata("between", {"k": "6"})  # a record between two chunks
                    # channels registered amid messages, one with a schema of its own
                    late = w.add_channel("/late", "eha-hil/late-frame")
                    js = w.add_json_channel("/late/json", {"x": "number"})
                if k >= 6:
                    w.write(late, int(t[0]), bytes([k]) * 20)
                    w.write_json(js, int(t[1]), {"x": k / 3})
        return path.read_bytes()
    finally:
        if not ours:
            mp.undo()


@pytest.mark.parametrize(("compression", "level"), [("lz4", 0), ("none", None)])
def test_library_level_gives_the_librarys_file(tmp_path: Path, compression: str,
                                               level: int | None) -> None:
    ours = _log(tmp_path / "ours.mcap", compression, level, True)
    lib = _log(tmp_path / "lib.mcap", compression, level, False)
    assert ours == lib


def test_a_short_writev_is_completed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A chunk goes out in one ``os.writev``; where the kernel takes only part of it (a
    signal, a nearly full disk), the rest follows: the same file as whole writes give."""
    whole = _log(tmp_path / "whole.mcap", "zstd", None, True)
    writev = os.writev
    short = []

    def writev_some(fd: int, parts: list) -> int:
        data = b"".join(bytes(p) for p in parts)
        short.append(len(data) > 7)
        return writev(fd, [data[:7]])

    monkeypatch.setattr(os, "writev", writev_some)
    assert _log(tmp_path / "short.mcap", "zstd", None, True) == whole
    assert any(short)


def _records(data: bytes) -> list:
    """Every record of a file, chunks as (start, end, size, records inside)."""
    out = []
    for rec in StreamReader(io.BytesIO(data), emit_chunks=True).records:
        if isinstance(rec, Chunk):
            inner = breakup_chunk(rec, validate_crc=True)
            out.append((rec.message_start_time, rec.message_end_time, rec.uncompressed_size,
                        inner))
        elif isinstance(rec, ChunkIndex | MetadataIndex | DataEnd | SummaryOffset | Footer):
            out.append(type(rec).__name__)  # offsets and CRCs differ with the chunks' bytes
        else:
            out.append(rec)
    return out


def test_zstd_at_the_librarys_level_gives_the_librarys_records(tmp_path: Path) -> None:
    """zstd chunks carry zstd's checksum instead of the chunk CRC: the compressed bytes
    differ from the library's, every record inside and around the chunks is the same."""
    ours = _log(tmp_path / "ours.mcap", "zstd", 3, True)
    lib = _log(tmp_path / "lib.mcap", "zstd", 3, False)
    assert ours != lib and _records(ours) == _records(lib)
    chunks = [r for r in StreamReader(io.BytesIO(ours), emit_chunks=True).records
              if isinstance(r, Chunk)]
    assert len(chunks) > 3 and {c.uncompressed_crc for c in chunks} == {0}
    assert all(zstandard.get_frame_parameters(c.data).has_checksum for c in chunks)


def test_default_level_reads_back_with_crcs(tmp_path: Path) -> None:
    files = [_log(tmp_path / "a.mcap", "zstd", None, True),
             _log(tmp_path / "b.mcap", "zstd", None, False)]
    assert files[0] != files[1]  # ours at level 1, the library's at 3
    summary = make_reader(io.BytesIO(files[0]), validate_crcs=True).get_summary()
    assert summary.statistics.chunk_count > 3
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
    for order in (False, True):  # file order, and by the chunk and message indexes
        got = [[(c.topic, m.log_time, m.sequence, m.data) for _, c, m in
                make_reader(io.BytesIO(f), validate_crcs=True).iter_messages(
                    log_time_order=order)] for f in files]
        assert len(got[0]) == 36 and got[0] == got[1]


@pytest.mark.parametrize(("compression", "level"), [("zstd", 23), ("lz4", -1),
                                                    ("none", 1)])
def test_bad_level_is_one_line(tmp_path: Path, compression: str, level: int) -> None:
    with pytest.raises(ValueError, match="level|takes no"):
        FrameLogWriter(tmp_path / "x.mcap", compression=compression,  # type: ignore[arg-type]
                       compression_level=level)


def _checked_indexes(path: Path) -> tuple[int, dict]:
    """The index entries of ``path`` (their count, and each chunk's records and
    MessageIndex records), checked with the mcap library: one MessageIndex per channel of
    a chunk, each entry's offset a Message record of that channel at that log time."""
    records = list(StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records)
    chunks: dict = {}
    pos = 0
    for rec in records:  # chunk records in file order, then the indexes that follow each
        if isinstance(rec, Chunk):
            pos += 1
            chunks[pos] = breakup_chunk(rec, validate_crc=True), []
        elif isinstance(rec, MessageIndex):
            chunks[pos][1].append(rec)
    entries = 0
    for inner, indexes in chunks.values():
        offsets, at = {}, 0
        for r in inner:  # each record's offset inside the uncompressed chunk
            offsets[at] = r
            at += _record_length(r)
        assert {ix.channel_id for ix in indexes} == {r.channel_id for r in inner
                                                     if isinstance(r, Message)}
        assert len({ix.channel_id for ix in indexes}) == len(indexes)  # one per channel
        for ix in indexes:
            for t, off in ix.records:
                m = offsets[off]
                assert isinstance(m, Message) and m.channel_id == ix.channel_id
                assert m.log_time == t
                entries += 1
    return entries, chunks


def test_channels_batched_twice_in_one_chunk_have_one_index_each(tmp_path: Path) -> None:
    """Batches alone in a chunk (their index records written as they were built), with
    every channel in several of them: one MessageIndex per channel, every entry right."""
    path = tmp_path / "twice.mcap"
    with FrameLogWriter(path, compression="none", chunk_size=1 << 20) as w:
        blocks = [w.add_block_channel(f"/b{i}", "eha-hil/x", dtype=np.uint16, width=3)
                  for i in range(3)]
        many = [w.add_channel(f"/m{i}", "json") for i in range(2)]
        for k in range(3):
            w.write_blocks(blocks, 100 * k + np.arange(4), np.full((3, 4, 3), k))
            w.write_messages_many(many, 100 * k + 50 + np.arange(5),
                                  np.full((2, 5, 4), k, np.uint8))
            w.write_messages(many[1], 100 * k + 60 + np.arange(2), [b"a", b"bc"])
    entries, chunks = _checked_indexes(path)
    assert len(chunks) == 1 and entries == 3 * 3 + 3 * 2 * 5 + 3 * 2


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_every_message_index_entry_points_at_its_message(tmp_path: Path,
                                                         compression: str) -> None:
    """The chunk's message indexes (one entry for a channel's one block, many for a
    channel of single messages), checked record by record with the mcap library: each
    entry's offset is a Message record of that channel at that log time."""
    path = tmp_path / "i.mcap"
    with FrameLogWriter(path, compression=compression, chunk_size=4000,  # type: ignore[arg-type]
                        flush_every_ns=400) as w:
        blocks = [w.add_block_channel(f"/b{i}", "eha-hil/x", dtype=np.uint16, width=3)
                  for i in range(5)]
        one = w.add_channel("/one", "eha-hil/y")
        many = [w.add_channel(f"/m{i}", "json") for i in range(3)]  # batches of arrays
        for k in range(6):
            t = 500 * k + np.arange(4)
            w.write_blocks(blocks, t, np.full((5, 4, 3), k))
            for j in range(3):
                w.write(one, int(t[-1]) + j, bytes([k, j]))
            w.write_messages_many(many, t + 10, np.full((3, 4, 5), k, np.uint8))
            w.write_messages(many[0], t + 20, [b"x" * (1 + i) for i in range(4)])
        w.flush()  # a chunk of batches of single-frame messages alone
        t = 4000 + np.arange(5)
        w.write_messages(many[1], t, [b"y" * 3] * 5)
        w.write_messages(many[2], t, [b"z" * (1 + i) for i in range(5)])
    entries, chunks = _checked_indexes(path)
    assert entries == 6 * 5 + 6 * 3 + 6 * 3 * 4 + 6 * 4 + 10 and len(chunks) >= 7
    # most channels had one message in a chunk: the one-entry records were written
    assert sum(len(ix.records) == 1 for _, ixs in chunks.values() for ix in ixs) >= 25


def test_chunk_indexes_point_at_their_message_indexes(tmp_path: Path) -> None:
    """Each chunk index's ``message_index_offsets``: a MessageIndex record of that channel
    at that file offset, the records one run right after the chunk, as long as
    ``message_index_length``; for chunks of one block per channel, of one batch of many
    messages per channel, and of both."""
    path = tmp_path / "o.mcap"
    with FrameLogWriter(path, chunk_size=1 << 20) as w:
        blocks = [w.add_block_channel(f"/b{i}", "eha-hil/x", dtype=np.uint16, width=3)
                  for i in range(4)]
        many = [w.add_channel(f"/m{i}", "json") for i in range(3)]
        for k in range(3):
            t = 500 * k + np.arange(4)
            w.write_blocks(blocks, t, np.full((4, 4, 3), k))
            if k:
                w.write_messages_many(many, t + 10, np.full((3, 4, 5), k, np.uint8))
            w.flush()  # chunks: blocks alone, then blocks and messages
        w.write_messages_many(many, 2000 + np.arange(4), np.zeros((3, 4, 5), np.uint8))
    data = path.read_bytes()
    indexes = make_reader(io.BytesIO(data)).get_summary().chunk_indexes
    assert len(indexes) == 4
    for ci in indexes:
        assert ci.message_index_offsets and ci.message_index_length
        at = ci.chunk_start_offset + ci.chunk_length
        for cid, off in sorted(ci.message_index_offsets.items(), key=lambda kv: kv[1]):
            assert off == at and data[off] == 0x07
            assert int.from_bytes(data[off + 9:off + 11], "little") == cid
            at = off + 9 + int.from_bytes(data[off + 1:off + 9], "little")
        assert at == ci.chunk_start_offset + ci.chunk_length + ci.message_index_length


def _record_length(r: object) -> int:
    """Bytes of the record ``r`` as the library writes it (opcode and length included)."""
    rb = RecordBuilder()
    r.write(rb)  # type: ignore[attr-defined]
    return len(rb.end())


@pytest.mark.parametrize("level", [None, -7, chunk.SIGNAL_LEVEL, chunk.ACTUATOR_SIGNAL_LEVEL,
                                   3])
def test_writers_levels_give_checked_zstd_frames(level: int | None) -> None:
    """The compressor of each zstd level the writer uses (its own levels with their tuned
    match finder, and a level of zstd's own): frames that stock zstd decodes back to the
    bytes, with their content size and zstd's checksum (the chunk's only integrity check),
    and a flipped byte fails."""
    rng = np.random.default_rng(3)
    data = np.concatenate([np.zeros(40000, np.uint8), rng.integers(0, 4, 40000, np.uint8),
                           np.tile(np.arange(250, dtype=np.uint8), 200)]).tobytes()
    frame = chunk.compressor("zstd", level)(memoryview(data))
    params = zstandard.get_frame_parameters(frame)
    assert params.has_checksum and params.content_size == len(data)
    assert zstandard.ZstdDecompressor().decompress(frame) == data
    bad = bytearray(frame)
    bad[len(bad) // 2] ^= 0x10
    with pytest.raises(zstandard.ZstdError):
        zstandard.ZstdDecompressor().decompress(bytes(bad))


def test_chunk_buffer_does_what_bytesio_does_across_grows() -> None:
    """The chunk buffer against ``BytesIO`` (what the mcap library builds chunks in): the
    same bytes after writes of every kind of buffer, seeks back (the library's record
    lengths), a grow by a write and one by a reserved array filled in place."""
    ours, ref = chunk.ChunkBuffer(10), io.BytesIO()
    rng = np.random.default_rng(3)
    writes = [bytes(rng.integers(0, 256, 40_000, dtype=np.uint8)), bytearray(b"ab"),
              memoryview(np.arange(6, dtype=np.uint16).reshape(2, 3)),  # not format "B"
              np.arange(50_000, dtype=np.uint8).view(np.uint8)]
    for data in writes:
        assert ours.write(data) == ref.write(data)
        assert ours.tell() == ref.tell()
    ours.seek(3), ref.seek(3)
    ours.write(b"xyz"), ref.write(b"xyz")
    ours.seek(0, 2), ref.seek(0, 2)
    got = ours.reserve(70_000)  # a grow
    got[:] = 7
    ref.write(bytes([7]) * 70_000)
    assert ours.getvalue() == ref.getvalue() and bytes(ours.getbuffer()) == ref.getvalue()
    ours.reset()
    assert ours.tell() == 0 and ours.getvalue() == b""


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=3000), st.integers(0, 2**32 - 1))
def test_the_logs_crc32_is_zlibs(data: bytes, start: int) -> None:
    """The CRC-32 of the writer's and reader's checks (zlib-ng's where installed) is
    zlib's, continued from any value (MCAP's data-section CRC runs over many records)."""
    assert chunk.crc32(data, start) == zlib.crc32(data, start)
    assert chunk.crc32(memoryview(data)) == zlib.crc32(data)
