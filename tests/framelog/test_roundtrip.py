"""Round trips through FrameLogWriter / FrameLogReader, and the mcap library's own reader."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

from hil.framelog.formats import (
    ENC_LVDS_UP,
    level_includes,
    lvds_topic,
    pack_block,
    unpack_block,
)
from hil.framelog.reader import FrameLogError, FrameLogReader
from hil.framelog.writer import FrameLogWriter
from tests.framelog.stock_blocks import block_rows


def _write_mixed(path: Path, **kw) -> None:
    with FrameLogWriter(path, level="full", metadata={"seed": 7, "config": "a = 1\nb = 2\n"},
                        **kw) as w:
        bus = w.add_channel("/fieldbus/frames", "eha-hil/ethercat", schema_name="")
        up = w.add_block_channel(lvds_topic(0, "up"), ENC_LVDS_UP, dtype=np.uint16, width=31)
        sig = w.add_json_channel("/signals/motor", {"iq": "number", "tick": "integer"})
        for k in range(4):
            t0 = k * 1_000_000
            w.write(bus, t0 + 500_000, bytes([k]) * (k + 1))
            w.write_json(sig, t0, {"iq": k / 4, "tick": k})
            t = t0 + np.arange(5, dtype=np.int64) * 200_000
            w.write_block(up, t, (np.arange(5 * 31) + 1000 * k).reshape(5, 31).astype(np.uint16))


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_mixed_round_trip_and_info(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "mixed.mcap"
    _write_mixed(path, compression=compression, chunk_size=300)
    r = FrameLogReader(path)
    info = r.info()
    assert info.complete and not info.truncated
    assert info.profile == "eha-hil" and info.level == "full"
    assert info.metadata["eha-hil"]["seed"] == "7"
    assert info.metadata["eha-hil"]["config"] == "a = 1\nb = 2\n"
    assert info.chunk_count > 1  # the small chunk size split the log
    ch = {c.topic: c for c in info.channels}
    assert (ch["/fieldbus/frames"].message_count, ch["/fieldbus/frames"].frame_count) == (4, 4)
    assert (ch["/lvds/0/up"].message_count, ch["/lvds/0/up"].frame_count) == (4, 20)
    assert ch["/lvds/0/up"].framing == "block" and ch["/lvds/0/up"].width == 31
    assert ch["/lvds/0/up"].encoding == ENC_LVDS_UP
    assert ch["/signals/motor"].schema_encoding == "jsonschema"
    assert ch["/lvds/0/up"].first_ns == 0 and ch["/lvds/0/up"].last_ns == 3_800_000
    assert info.frame_count == 28 and info.message_count == 12
    assert (info.start_ns, info.end_ns, info.readable_until_ns) == (0, 3_800_000, 3_800_000)

    frames = list(r.frames())
    times = [t for _, t, _ in frames]
    assert times == sorted(times) and len(frames) == 28
    # A tie (t = 0: JSON sample and first snapshot) keeps file order: JSON was written
    # first, but with zstd at its default level the decoded signals have chunks of their
    # own (writer.SIGNAL_CHUNKS), written after the chunk of the channels' records.
    first = ["/signals/motor", "/lvds/0/up"]
    assert [tp for tp, t, _ in frames if t == 0] == (first[::-1] if compression == "zstd"
                                                     else first)
    assert ("/fieldbus/frames", 2_500_000, b"\x02\x02\x02") in frames
    assert json.loads(next(d for tp, t, d in frames if tp == "/signals/motor" and t == 3_000_000)
                      ) == {"iq": 0.75, "tick": 3}

    b = r.blocks("/lvds/0/up")
    assert b.frames.dtype == np.uint16 and b.frames.shape == (20, 31)
    assert b.t_ns.tolist() == sorted(k * 1_000_000 + i * 200_000 for k in range(4)
                                     for i in range(5))
    assert b.frames[6, 0] == 1000 + 31

def test_blocks_of_single_frames(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    with FrameLogWriter(path) as w:
        c = w.add_channel("/x", "raw", schema_name="")
        e = w.add_block_channel("/empty", "raw", dtype="int32", width=3)
        for i in range(5):
            w.write(c, i, bytes([i, 2 * i]))
    r = FrameLogReader(path)
    b = r.blocks("/x")
    assert b.t_ns.tolist() == [0, 1, 2, 3, 4]
    assert b.frames.tolist() == [[i, 2 * i] for i in range(5)]
    assert r.blocks("/empty").frames.shape == (0, 3)
    assert e == 2
    with pytest.raises(FrameLogError, match="no topic '/nope'"):
        r.blocks("/nope")
    with pytest.raises(ValueError, match="order"):
        r.frames(order="random")
    many = r.blocks_many(["/x", "/empty"])
    assert set(many) == {"/x", "/empty"}


def test_variable_single_frames_do_not_stack(tmp_path: Path) -> None:
    path = tmp_path / "v.mcap"
    _write_mixed(path)
    with pytest.raises(FrameLogError, match="different lengths"):
        FrameLogReader(path).blocks("/fieldbus/frames")


def test_mcap_library_reads_it_with_crc_validation(tmp_path: Path) -> None:
    path = tmp_path / "lib.mcap"
    _write_mixed(path, chunk_size=300)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 12
        msgs = list(reader.iter_messages())
        topics = {ch.topic for _, ch, _ in msgs}
        assert topics == {"/fieldbus/frames", "/lvds/0/up", "/signals/motor"}
        meta = list(reader.iter_metadata())
        assert meta[0].name == "eha-hil" and meta[0].metadata["level"] == "full"
        for schema, channel, message in msgs:
            if channel.topic == "/lvds/0/up":
                # a protobuf message the library's stock decoder reads
                assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
                blk = DecoderFactory().decoder_for("protobuf", schema)(message.data)
                t, f = block_rows(blk)
                assert t[0] == message.log_time and blk.width == 31
                assert blk.dtype == "uint16" and f.shape == (len(t), 31)
            if channel.topic == "/signals/motor":
                assert channel.message_encoding == "json"
                assert schema is not None and schema.encoding == "jsonschema"
                root = json.loads(schema.data)
                assert root["type"] == "object"
                # Foxglove accepts only a single type string per field (no ["number", "null"])
                assert root["properties"] == {"iq": {"type": "number"},
                                              "tick": {"type": "integer"}}
                json.loads(message.data)
    # The sequential reader validates the chunk CRCs and the data-section CRC.
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert sum(type(r).__name__ == "Message" for r in records) == 12


def test_writer_rejects_misuse(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown log level"):
        FrameLogWriter(tmp_path / "a.mcap", level="verbose")
    with pytest.raises(ValueError, match="compression"):
        FrameLogWriter(tmp_path / "a.mcap", compression="gzip")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="set by the writer"):
        FrameLogWriter(tmp_path / "a.mcap", metadata={"level": "x"})
    with FrameLogWriter(tmp_path / "b.mcap") as w:
        c = w.add_channel("/c", "raw", schema_name="")
        b = w.add_block_channel("/b", "raw", dtype=np.uint16, width=2)
        j = w.add_json_channel("/j", {"x": "number"})
        with pytest.raises(ValueError, match="already has a channel"):
            w.add_channel("/c", "raw", schema_name="")
        w.write(c, 10, b"x")
        with pytest.raises(ValueError, match="before the previous"):
            w.write(c, 9, b"x")
        with pytest.raises(ValueError, match="negative"):
            w.write(j, -1, b"{}")
        with pytest.raises(ValueError, match="use write_block"):
            w.write(b, 1, b"ab")
        with pytest.raises(ValueError, match="use write"):
            w.write_block(c, np.array([11]), np.zeros((1, 1), np.uint8))
        with pytest.raises(ValueError, match=r"frames \(n, 2\)"):
            w.write_block(b, np.array([1, 2]), np.zeros((2, 3), np.uint16))
        with pytest.raises(ValueError, match=r"values -1\.\.0 do not fit"):
            w.write_block(b, np.array([1]), np.array([[0, -1]], np.int64))
        with pytest.raises(ValueError, match="float64 do not fit"):
            w.write_block(b, np.array([1]), np.zeros((1, 2), np.float64))
        with pytest.raises(ValueError, match="decrease"):
            w.write_block(b, np.array([5, 4]), np.zeros((2, 2), np.uint16))
        w.write_block(b, np.array([1, 2]), np.zeros((2, 2), np.uint8))  # safe cast is fine
        w.write_block(b, np.zeros(0, np.int64), np.zeros((0, 2), np.uint16))  # no-op
        with pytest.raises(ValueError, match="not declared"):
            w.write_json(j, 1, {"y": 1.0})
        with pytest.raises(ValueError, match="not a JSON channel"):
            w.write_json(c, 11, {"x": 1.0})
        with pytest.raises(ValueError, match="no channel with id 99"):
            w.write(99, 1, b"")
        w.write_json(j, 1, {"x": float("nan")})
    with pytest.raises(ValueError, match="closed"):
        w.write(c, 20, b"x")
    frames = list(FrameLogReader(tmp_path / "b.mcap").frames(["/j"]))
    assert frames == [("/j", 1, b'{"x":null}')]
    assert FrameLogReader(tmp_path / "b.mcap").info().channel("/b").message_count == 1


def test_close_on_exception_leaves_a_complete_log(tmp_path: Path) -> None:
    path = tmp_path / "exc.mcap"
    with pytest.raises(RuntimeError), FrameLogWriter(path) as w:
        c = w.add_channel("/c", "raw", schema_name="")
        w.write(c, 1, b"a")
        raise RuntimeError("simulation failed")
    info = FrameLogReader(path).info()
    assert info.complete and info.frame_count == 1


def test_flush_every_ns_closes_chunks_by_sim_time(tmp_path: Path) -> None:
    path = tmp_path / "f.mcap"
    with FrameLogWriter(path, flush_every_ns=1000) as w:
        c = w.add_channel("/c", "raw", schema_name="")
        for i in range(10):
            w.write(c, i * 500, b"x")
    assert FrameLogReader(path).info().chunk_count == 5


def test_levels() -> None:
    assert level_includes("bus", "fieldbus") and not level_includes("bus", "lvds")
    assert level_includes("mcu", "lvds") and not level_includes("mcu", "sensors")
    assert level_includes("full", "sensors")
    with pytest.raises(ValueError, match="unknown log level"):
        level_includes("all", "lvds")


def test_block_codec_rejects_bad_blocks() -> None:
    data = pack_block(np.array([1, 2]), np.array([[1, 2], [3, 4]], np.int16))
    t, f = unpack_block(data)
    assert t.tolist() == [1, 2] and f.tolist() == [[1, 2], [3, 4]] and f.dtype == np.int16
    with pytest.raises(ValueError, match="needs"):
        unpack_block(data[:-1])
    with pytest.raises(ValueError, match="magic"):
        unpack_block(b"XXXX" + data[4:])
    with pytest.raises(ValueError, match="cannot be logged"):
        pack_block(np.array([1]), np.array([[1 + 2j]]))


# --- properties -----------------------------------------------------------------------------
_frames = st.lists(st.tuples(st.integers(0, 2), st.integers(0, 10**6), st.binary(max_size=40)),
                   max_size=60)


@settings(max_examples=60, deadline=None)
@given(_frames, st.sampled_from([1, 64, 1 << 20]), st.sampled_from(["zstd", "lz4", "none"]))
def test_property_single_frames_round_trip(frames, chunk_size, compression) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "p.mcap"
        expected = []
        t = 0
        with FrameLogWriter(path, chunk_size=chunk_size, compression=compression) as w:
            ids = [w.add_channel(f"/c{i}", "raw", schema_name="") for i in range(3)]
            for ch, dt, data in frames:
                t += dt
                w.write(ids[ch], t, data)
                expected.append((f"/c{ch}", t, data))
        r = FrameLogReader(path)
        assert list(r.frames()) == expected  # times non-decreasing: time order = input order
        assert list(r.frames(order="file")) == expected
        info = r.info()
        assert info.complete and info.frame_count == len(frames)
        assert list(r.frames(["/c1"])) == [e for e in expected if e[0] == "/c1"]


_dtypes = st.sampled_from(["uint8", "uint16", "int32", "uint64", "float64"])


@settings(max_examples=40, deadline=None)
@given(st.data(), _dtypes, st.integers(1, 9), st.integers(1, 5))
def test_property_blocks_round_trip(data, dtype, width, n_blocks) -> None:
    blocks = []
    t0 = 0
    for _ in range(n_blocks):
        n = data.draw(st.integers(0, 30))
        dts = data.draw(st.lists(st.integers(0, 10**9), min_size=n, max_size=n))
        t = t0 + np.cumsum(np.asarray(dts, dtype=np.int64))
        if n:
            t0 = int(t[-1])
        raw = data.draw(st.binary(min_size=n * width * np.dtype(dtype).itemsize,
                                  max_size=n * width * np.dtype(dtype).itemsize))
        blocks.append((t, np.frombuffer(raw, dtype).reshape(n, width)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "b.mcap"
        with FrameLogWriter(path, chunk_size=256) as w:
            c = w.add_block_channel("/b", "raw", dtype=dtype, width=width)
            for t, f in blocks:
                w.write_block(c, t, f)
        r = FrameLogReader(path)
        got = r.blocks("/b")
        assert got.t_ns.tolist() == np.concatenate([t for t, _ in blocks]).tolist()
        want = np.concatenate([f for _, f in blocks])
        assert got.frames.dtype == np.dtype(dtype)
        assert got.frames.tobytes() == want.tobytes()  # bit for bit (NaN payloads too)
        rows = list(r.frames())
        assert [x[2] for x in rows] == [row.tobytes() for row in want]
        assert r.info().channel("/b").frame_count == want.shape[0]
