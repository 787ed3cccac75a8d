"""Chunks of several compressions in one log (``FrameLogWriter(chunk_compression=...)``):
each channel's messages in chunks of its compression, every channel record before its
messages in file order, and the stock readers read the same messages as from a log of one
compression."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_protobuf.decoder import DecoderFactory

from hil.framelog import FrameLogReader, FrameLogWriter
from hil.replay.signals import ACTUATOR


def _log(path: Path, kinds: dict[str, str] | None, signals_first: bool = False) -> None:
    rng = np.random.default_rng(3)
    with FrameLogWriter(path, chunk_size=2000, chunk_compression=kinds) as w:
        sig = [w.add_protobuf_channel(f"/signals/a{i}", ACTUATOR) for i in range(2)]
        up = [w.add_block_channel(f"/lvds/{i}/up", "eha-hil/t", dtype=np.uint16, width=3)
              for i in range(2)]
        mixed = [w.add_block_channel("/lvds/2/up", "eha-hil/t", dtype=np.uint16, width=3),
                 w.add_block_channel("/signals/raw", "eha-hil/t", dtype=np.uint16,
                                            width=3)]
        one = w.add_channel("/fieldbus/frames", "eha-hil/f")
        for k in range(6):
            t = 100 * k + np.arange(10, dtype=np.int64)
            cols = {f.name: rng.integers(0, 2, (2, 10)) for f in ACTUATOR.fields}

            def fill(out: np.ndarray, cols: dict = cols) -> None:
                for j in range(2):
                    ACTUATOR.encode_into({n: v[j] for n, v in cols.items()}, out[j])

            if signals_first:
                w.write_messages_filled(sig, t, ACTUATOR.size, fill)
            w.write_blocks(up, t, rng.integers(0, 9, (2, 10, 3)))
            if not signals_first:
                w.write_messages_filled(sig, t, ACTUATOR.size, fill)
            w.write_blocks(mixed, t + 5, rng.integers(0, 9, (2, 10, 3)))  # two kinds
            w.write(one, int(t[-1]) + 50, bytes(rng.integers(0, 256, 12, dtype=np.uint8)))
            if k == 3:
                w.flush()


def _messages(path: Path, order: bool) -> list[tuple]:
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.sequence, m.data) for _, c, m in
                make_reader(f, validate_crcs=True).iter_messages(log_time_order=order)]


def _kinds_in_file_order(path: Path) -> dict[str, set[str]]:
    """topic -> compressions of the chunks holding its messages ("outside": none),
    checking on the way that each schema and channel comes before its first use."""
    topics: dict[int, str] = {}
    schemas: set[int] = set()
    kinds: dict[str, set[str]] = {}
    for rec in StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records:
        inner = breakup_chunk(rec, validate_crc=True) if isinstance(rec, Chunk) else [rec]
        for r in inner:  # in file order: a streaming reader's view
            if isinstance(r, Schema):
                schemas.add(r.id)
            elif isinstance(r, Channel):
                assert r.schema_id in schemas or r.schema_id == 0, r.topic
                topics[r.id] = r.topic
            elif isinstance(r, Message):
                assert r.channel_id in topics, "a message before its channel"
                kinds.setdefault(topics[r.channel_id], set()).add(
                    rec.compression if isinstance(rec, Chunk) else "outside")
    return kinds


@pytest.mark.parametrize("signals_first", [False, True])
def test_each_kind_in_its_chunks_and_channels_before_messages(tmp_path: Path,
                                                               signals_first: bool) -> None:
    path = tmp_path / "k.mcap"
    _log(path, {"/signals/": "none"}, signals_first)
    plain = tmp_path / "one.mcap"
    _log(plain, None, signals_first)
    assert _kinds_in_file_order(path) == {
        "/signals/a0": {""}, "/signals/a1": {""}, "/signals/raw": {""},
        "/lvds/0/up": {"zstd"}, "/lvds/1/up": {"zstd"}, "/lvds/2/up": {"zstd"},
        "/fieldbus/frames": {"zstd"}}
    for order in (False, True):  # file order, and by time through the indexes
        got = _messages(path, order)
        assert sorted(got) == sorted(_messages(plain, order))
        if order:  # (messages of one time in chunks of two kinds: either may come first)
            assert [m[1] for m in got] == sorted(m[1] for m in got)
    topics = ["/lvds/0/up", "/lvds/2/up", "/signals/raw", "/fieldbus/frames"]
    got = [(t, ns, bytes(f)) for t, ns, f in FrameLogReader(path).frames(topics)]
    assert sorted(got) == sorted((t, ns, bytes(f)) for t, ns, f in
                                 FrameLogReader(plain).frames(topics))
    assert [ns for _, ns, _ in got] == sorted(ns for _, ns, _ in got)
    assert {t for t, _, _ in got} == set(topics)


def test_a_chunk_of_another_kind_waits_for_the_channels(tmp_path: Path) -> None:
    """The uncompressed chunk fills first while the zstd chunk holds the channel records
    and a message: the zstd chunk is written before it, whole."""
    path = tmp_path / "w.mcap"
    with FrameLogWriter(path, chunk_size=3000, chunk_compression={"/s": "none"}) as w:
        b = w.add_block_channel("/b", "eha-hil/t", dtype=np.uint16, width=2)
        s = w.add_channel("/s", "json")
        w.write_block(b, np.arange(3), np.ones((3, 2), np.uint16))
        w.write_messages(s, np.arange(400), [b'{"x":1}'] * 400)
        w.write_block(b, np.arange(3, 6), np.ones((3, 2), np.uint16))
    assert _kinds_in_file_order(path) == {"/b": {"zstd"}, "/s": {""}}
    assert len(_messages(path, True)) == 402


def test_stock_protobuf_decoder_reads_the_uncompressed_chunks(tmp_path: Path) -> None:
    path = tmp_path / "k.mcap"
    _log(path, {"/signals/a": "none", "/signals/raw": "lz4"})
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        comps = {c.compression for c in reader.get_summary().chunk_indexes}
        got = [(c.topic, d.board_mode) for _, c, _, d in
               reader.iter_decoded_messages(topics=["/signals/a0"])]
    assert comps == {"", "lz4", "zstd"}
    assert len(got) == 60


def test_a_level_of_its_own_is_a_chunk_of_its_own(tmp_path: Path) -> None:
    path = tmp_path / "k.mcap"
    _log(path, {"/signals/": ("zstd", -7)})
    topics: dict[int, str] = {}
    per_chunk = []
    for rec in StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records:
        if isinstance(rec, Chunk):
            assert rec.compression == "zstd"
            inner = breakup_chunk(rec, validate_crc=True)
            topics.update({r.id: r.topic for r in inner if isinstance(r, Channel)})
            per_chunk.append({topics[r.channel_id].startswith("/signals/")
                              for r in inner if isinstance(r, Message)})
    assert {True} in per_chunk and {False} in per_chunk and {True, False} not in per_chunk


@pytest.mark.parametrize(("kw", "apart"), [({}, True), ({"compression_level": -1}, False),
                                            ({"chunk_compression": {}}, False)])
def test_signals_have_chunks_of_their_own_by_default(tmp_path: Path, kw: dict,
                                                     apart: bool) -> None:
    """zstd at the writer's default level: /signals/ in chunks of their own (zstd -9),
    the actuators' /signals/actuator/ in others (zstd -60); a level or a
    chunk_compression of one's own: one kind of chunk."""
    path = tmp_path / "d.mcap"
    with FrameLogWriter(path, chunk_size=1 << 20, **kw) as w:
        s = w.add_channel("/signals/x", "json")
        a = w.add_channel("/signals/actuator/0.0", "json")
        b = w.add_block_channel("/lvds/0/up", "eha-hil/t", dtype=np.uint16, width=2)
        w.write_messages(s, np.arange(3), [b"{}"] * 3)
        w.write_messages(a, np.arange(3), [b"{}"] * 3)
        w.write_block(b, np.arange(3), np.ones((3, 2), np.uint16))
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        chunks = reader.get_summary().chunk_indexes
        assert len(list(reader.iter_messages())) == 7
    assert {c.compression for c in chunks} == {"zstd"}
    assert len(chunks) == (3 if apart else 1)


def test_register_words_in_chunks_of_their_level_by_default(tmp_path: Path) -> None:
    """zstd at the writer's default level: the /lvds/ blocks in chunks of their own, each
    the frame zstd makes at chunk.REGISTER_BLOCK_LEVEL; the fieldbus frames at ZSTD_LEVEL."""
    import zstandard

    from hil.framelog import chunk

    path = tmp_path / "r.mcap"
    rng = np.random.default_rng(5)
    # a pattern that repeats every 37 frames: matches that the two levels find apart
    words = np.tile(rng.integers(0, 1 << 16, (37, 34)), (60, 1))[:2000]
    with FrameLogWriter(path, chunk_size=1 << 20) as w:
        b = w.add_block_channel("/lvds/0/up", "eha-hil/t", dtype=np.uint16, width=34)
        f = w.add_channel("/fieldbus/frames", "eha-hil/f")
        w.write_block(b, np.arange(2000), words)
        w.write_messages(f, np.arange(50), [bytes(200) + bytes([i]) for i in range(50)])
    topics: dict[int, str] = {}
    levels: dict[str, list[int]] = {}
    for rec in StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records:
        if isinstance(rec, Chunk):
            inner = breakup_chunk(rec, validate_crc=True)
            topics.update({r.id: r.topic for r in inner if isinstance(r, Channel)})
            data = zstandard.ZstdDecompressor().decompress(rec.data)
            for r in inner:
                if isinstance(r, Message):
                    levels[topics[r.channel_id]] = [
                        lvl for lvl in (chunk.ZSTD_LEVEL, chunk.REGISTER_BLOCK_LEVEL)
                        if chunk.compressor("zstd", lvl)(data) == rec.data]
    assert levels == {"/lvds/0/up": [chunk.REGISTER_BLOCK_LEVEL],
                      "/fieldbus/frames": [chunk.ZSTD_LEVEL]}


@pytest.mark.parametrize(("kind", "match"), [("brotli", "'/signals/'.*zstd, lz4, none"),
                                             (("zstd", 30), "zstd level 30 is outside"),
                                             (("none", 1), "takes no level")])
def test_unknown_chunk_compression_is_one_line(tmp_path: Path, kind: object,
                                               match: str) -> None:
    with pytest.raises(ValueError, match=match):
        FrameLogWriter(tmp_path / "x.mcap",
                       chunk_compression={"/signals/": kind})  # type: ignore[dict-item]
