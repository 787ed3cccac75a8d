"""Chunks closed by hil.framelog.chunk: at the library's own level the very file the mcap
library writes; at ours, a file the mcap reader reads back with every CRC checked."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk, ChunkIndex, DataEnd, Footer, MetadataIndex, SummaryOffset
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
        assert len(got[0]) == 24 and got[0] == got[1]


@pytest.mark.parametrize(("compression", "level"), [("zstd", 23), ("lz4", -1),
                                                    ("none", 1)])
def test_bad_level_is_one_line(tmp_path: Path, compression: str, level: int) -> None:
    with pytest.raises(ValueError, match="level|takes no"):
        FrameLogWriter(tmp_path / "x.mcap", compression=compression,  # type: ignore[arg-type]
                       compression_level=level)
