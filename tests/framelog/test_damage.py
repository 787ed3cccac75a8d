"""Truncated, damaged, empty and foreign files; the kill test."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.stream_reader import StreamReader, breakup_chunk

from hil.framelog.reader import MAGIC, FrameLogError, FrameLogReader
from hil.framelog.writer import FrameLogWriter

REPO = Path(__file__).resolve().parents[2]


def _counter_log(path: Path, n: int, chunk_size: int = 200, compression: str = "lz4") -> None:
    with FrameLogWriter(path, chunk_size=chunk_size, compression=compression) as w:
        c = w.add_channel("/counter", "raw", schema_name="")
        for i in range(n):
            w.write(c, i * 1000, i.to_bytes(4, "little"))


def _counters(path: Path) -> list[int]:
    return [int.from_bytes(d, "little") for _, _, d in FrameLogReader(path).frames()]


@pytest.mark.slow
def test_cut_anywhere_reads_a_prefix(tmp_path: Path) -> None:
    full = tmp_path / "full.mcap"
    _counter_log(full, 60)
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    previous = 0
    # Every byte of the first chunks and of the summary/footer, a stride in between.
    cuts = sorted({*range(len(MAGIC), 1200), *range(1200, len(data), 13),
                   *range(len(data) - 80, len(data))})
    for n in cuts:
        cut.write_bytes(data[:n])
        info = FrameLogReader(cut).info()
        got = _counters(cut)
        assert got == list(range(len(got))), n  # a gap-free prefix, never a half record
        assert len(got) >= previous
        previous = len(got)
        assert info.truncated and not info.complete
        assert info.frame_count == len(got)
        assert info.readable_until_ns == (None if not got else (len(got) - 1) * 1000)
    assert previous == 60  # the data section is whole before the summary is cut
    assert FrameLogReader(full).info().complete


@pytest.mark.parametrize(("content", "match"), [
    (b"", "empty file"),
    (b"hello world, not a log", "not an MCAP file"),
    (MAGIC[:5], "not an MCAP file"),
])
def test_foreign_files_raise_one_line(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(FrameLogError, match=match) as exc:
        FrameLogReader(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(FrameLogError, match="no such file"):
        FrameLogReader(tmp_path / "nope.mcap")
    with pytest.raises(FrameLogError, match="directory"):
        FrameLogReader(tmp_path)


@pytest.mark.parametrize("compression", ["lz4", "zstd"])
def test_damaged_chunk_raises_with_offset(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "d.mcap"
    _counter_log(path, 60, compression=compression)
    data = bytearray(path.read_bytes())
    # Flip a byte inside the second chunk's payload: its CRC (lz4) or zstd's checksum or
    # the decompression must fail.
    offsets = _chunk_offsets(bytes(data))
    assert len(offsets) > 2
    data[offsets[1] + 80] ^= 0x55
    path.write_bytes(bytes(data))
    with pytest.raises(FrameLogError, match=rf"damaged at byte {offsets[1]}: Chunk record") as e:
        FrameLogReader(path).info()
    assert "readable up to t = " in str(e.value)
    # frames() yields the intact first chunk, then raises
    got = []
    with pytest.raises(FrameLogError):
        for _, _, d in FrameLogReader(path).frames(order="file"):
            got.append(int.from_bytes(d, "little"))
    assert got == list(range(len(got))) and got


def test_garbage_record_and_wrong_first_record(tmp_path: Path) -> None:
    path = tmp_path / "g.mcap"
    _counter_log(path, 10)
    data = path.read_bytes()
    path.write_bytes(data[:len(MAGIC)] + bytes(20) + data[len(MAGIC):])
    with pytest.raises(FrameLogError, match="invalid record opcode 0x00"):
        FrameLogReader(path).info()
    path.write_bytes(MAGIC + bytes([5]) + (4).to_bytes(8, "little") + b"abcd")
    with pytest.raises(FrameLogError, match="first record is a Message, not a Header"):
        FrameLogReader(path).info()


def test_only_magic_is_truncated_and_empty(tmp_path: Path) -> None:
    path = tmp_path / "m.mcap"
    path.write_bytes(MAGIC)
    info = FrameLogReader(path).info()
    assert info.truncated and info.channels == () and info.readable_until_ns is None


def _chunk_offsets(data: bytes) -> list[int]:
    out, pos = [], len(MAGIC)
    while pos + 9 <= len(data):
        op = data[pos]
        length = int.from_bytes(data[pos + 1:pos + 9], "little")
        if op == 6:
            out.append(pos)
        if op == 2:
            break
        pos += 9 + length
    return out


# --- the kill test ----------------------------------------------------------------------------
# The child logs a counter (single frames) and the same counter in blocks of 10 with a small
# chunk size. "busy": it prints "ready" after 3000 counts and keeps writing, so SIGKILL lands
# anywhere, possibly inside a write. "quiet": it stops after 3000 counts and waits, so the
# chunks completed before the kill are known exactly (the writer must not hold any back).
CHILD = """
import sys
import numpy as np
from hil.framelog.writer import FrameLogWriter
path, mode = sys.argv[1], sys.argv[2]
with FrameLogWriter(path, chunk_size=2000, compression="zstd") as w:
    c = w.add_channel("/counter", "raw", schema_name="")
    b = w.add_block_channel("/block", "raw", dtype=np.uint32, width=1)
    i = 0
    while True:
        w.write(c, i * 1000, i.to_bytes(8, "little"))
        if i % 10 == 9:
            w.write_block(b, np.arange(i - 9, i + 1) * 1000, np.arange(i - 9, i + 1))
        i += 1
        if i == 3000:
            print("ready", flush=True)
            if mode == "quiet":
                sys.stdin.read()  # blocks until killed
"""
COUNTS = 3000


def _chunk_message_counts(path: Path) -> list[int]:
    """Messages per complete, CRC-valid chunk, counted with the mcap library."""
    counts = []
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, emit_chunks=True).records:
                if type(rec).__name__ == "Chunk":
                    recs = breakup_chunk(rec, validate_crc=True)  # a short chunk fails here
                    counts.append(sum(type(r).__name__ == "Message" for r in recs))
        except Exception:  # the truncated tail: whatever the library trips over
            pass
    return counts


def _run_and_kill(path: Path, mode: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path), mode],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                            cwd=REPO)
    try:
        line = proc.stdout.readline() if proc.stdout else ""
        assert line.strip() == "ready", "the writer died before writing enough"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
        for stream in (proc.stdin, proc.stdout):
            if stream:
                stream.close()
    assert proc.returncode == -signal.SIGKILL


def _check_gap_free(path: Path) -> tuple[int, list[int]]:
    reader = FrameLogReader(path)
    info = reader.info()
    assert info.truncated and not info.complete
    counters = [int.from_bytes(d, "little") for _, _, d in reader.frames(["/counter"])]
    assert counters == list(range(len(counters)))  # no gap up to the last readable one
    blocks = reader.blocks("/block")
    assert blocks.frames[:, 0].tolist() == list(range(blocks.frames.shape[0]))
    assert blocks.t_ns.tolist() == [k * 1000 for k in range(blocks.frames.shape[0])]
    assert info.readable_until_ns == max(counters[-1], int(blocks.frames[-1, 0])) * 1000
    # every message of every completed chunk, and nothing else
    assert info.message_count == sum(_chunk_message_counts(path))
    return info.message_count, counters


def test_killed_while_writing_leaves_a_readable_log(tmp_path: Path) -> None:
    path = tmp_path / "busy.mcap"
    _run_and_kill(path, "busy")
    _, counters = _check_gap_free(path)
    assert len(counters) > COUNTS // 2


@pytest.mark.slow
def test_killed_writer_lost_only_its_open_chunk(tmp_path: Path) -> None:
    # The same 3000 counts written in-process and closed: its last chunk is the one the
    # killed writer still had open; every chunk before it must be in the killed file.
    ref = tmp_path / "ref.mcap"
    with FrameLogWriter(ref, chunk_size=2000, compression="zstd") as w:
        c = w.add_channel("/counter", "raw", schema_name="")
        b = w.add_block_channel("/block", "raw", dtype=np.uint32, width=1)
        for i in range(COUNTS):
            w.write(c, i * 1000, i.to_bytes(8, "little"))
            if i % 10 == 9:
                w.write_block(b, np.arange(i - 9, i + 1) * 1000, np.arange(i - 9, i + 1))
    per_chunk = _chunk_message_counts(ref)
    assert len(per_chunk) > 10 and sum(per_chunk) == COUNTS + COUNTS // 10
    # the last chunk was still open when the counting stopped, unless its last message
    # took it over the chunk size (the writer then closed it at once)
    with open(ref, "rb") as f:
        last = [r for r in StreamReader(f, emit_chunks=True).records
                if type(r).__name__ == "Chunk"][-1]
    closed_by_size = last.uncompressed_size > 2000

    path = tmp_path / "quiet.mcap"
    _run_and_kill(path, "quiet")
    messages, _ = _check_gap_free(path)
    assert messages == sum(per_chunk if closed_by_size else per_chunk[:-1])


# --- damage that looks like a cut ---------------------------------------------------------------
def test_flipped_length_byte_in_a_closed_log_is_damage_not_truncation(tmp_path: Path) -> None:
    # A Header one byte longer makes the walk read garbage and run off the end. The file
    # ends with its Footer and closing magic, so it was not cut short: its length is bad.
    path = tmp_path / "len.mcap"
    _counter_log(path, 60)
    data = bytearray(path.read_bytes())
    data[len(MAGIC) + 1] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(FrameLogError, match=r"damaged at byte \d+: .*a damaged length field"):
        FrameLogReader(path).info()
    # Without the footer the same file is indistinguishable from one cut short, unless the
    # length it claims is beyond any record a writer makes.
    cut = tmp_path / "len_cut.mcap"
    cut.write_bytes(bytes(data[:-100]))
    with pytest.raises(FrameLogError, match="a damaged length field"):
        FrameLogReader(cut).info()


def test_implausible_record_length_is_damage(tmp_path: Path) -> None:
    path = tmp_path / "huge.mcap"
    _counter_log(path, 10)
    data = bytearray(path.read_bytes())
    chunk = _chunk_offsets(bytes(data))[0]
    data[chunk + 1:chunk + 9] = (1 << 50).to_bytes(8, "little")
    path.write_bytes(bytes(data[:chunk + 500]))  # cut, so no footer vouches for the file
    with pytest.raises(FrameLogError, match=rf"damaged at byte {chunk}: Chunk record claims"):
        FrameLogReader(path).info()


def test_log_times_beyond_int64_read_and_export(tmp_path: Path) -> None:
    """MCAP log times are u64: a legal file from another tool may hold 2^63 and beyond."""
    from mcap.writer import Writer

    from hil.framelog.export import export_csv

    path = tmp_path / "late.mcap"
    times = [5, 2**63, 2**64 - 1]
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        cid = w.register_channel("/late", "raw", 0)
        for t in times:
            w.add_message(cid, log_time=t, data=b"x", publish_time=t)
        w.finish()
    reader = FrameLogReader(path)
    assert [t for _, t, _ in reader.frames()] == times
    assert reader.blocks("/late").t_ns.tolist() == times
    out = tmp_path / "late.csv"
    assert export_csv(path, out) == 3
    last = 2**64 - 1
    assert out.read_text().splitlines()[-1] == f"{last // 10**9}.{last % 10**9:09d},/late,1"
