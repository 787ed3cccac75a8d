"""Batched message records (hil.framelog.batch) make the same file as add_message."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from hil.framelog import batch


def _interleave(payloads: list[bytes], p: int) -> batch.Interleaved:
    return batch.Interleaved([np.array([list(m) for m in payloads[r::p]], np.uint8)
                              for r in range(p)])


def _file(fast: bool, payloads: list[bytes], chunk_size: int, period: int = 0) -> bytes:
    buf = io.BytesIO()
    w = Writer(buf, chunk_size=chunk_size, compression=CompressionType.NONE)
    w.start(profile="t", library="t")
    assert batch.supported(w)
    sid = w.register_schema("s", "x", b"")
    a = w.register_channel("/a", "x", sid)
    b = w.register_channel("/b", "x", sid)
    w.add_message(b, 5, b"first", 5, 0)  # a message by the library's own path in between
    times = [10 * i + (i % 3) for i in range(len(payloads))]
    half = len(payloads) // 2
    first, then = payloads[:half], payloads[half:]
    if period:  # the same messages as the rows of one array per place in the period
        first, then = _interleave(first, period), _interleave(then, period)
    batch.add_messages(w, a, times[:half], first, 2**32 - 3, fast)
    w.add_message(b, 7, b"second", 7, 1)
    batch.add_messages(w, a, times[half:], then, 2**32 - 3 + half, fast)
    w.finish()
    return buf.getvalue()


@pytest.mark.parametrize("sizes", ["fixed", "varying", "periodic"])
@pytest.mark.parametrize("chunk_size", [64, 1 << 20])
def test_same_bytes_as_add_message(sizes: str, chunk_size: int) -> None:
    lengths = {"fixed": (9,), "varying": (1, 2, 3, 4, 5, 6, 7), "periodic": (3, 11, 11, 2)}
    payloads = [bytes([i % 251]) * lengths[sizes][i % len(lengths[sizes])]
                for i in range(40)]
    period = 4 if sizes == "periodic" else 0  # Interleaved: 2 x 5 rows of 4 messages
    fast = _file(True, payloads, chunk_size, period)
    slow = _file(False, payloads, chunk_size, period)
    if chunk_size > 1000:
        assert fast == slow  # no chunk closes inside a batch: the very same file
    # small chunks: a batch stays in one chunk (closed after it), add_message closes one per
    # message; the messages, their order and the indexes' view of them are the same
    for stream in (False, True):
        got = [[(c.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, c, m in
                make_reader(io.BytesIO(f), validate_crcs=True).iter_messages(
                    log_time_order=stream)] for f in (fast, slow)]
        assert got[0] == got[1]
    msgs = list(make_reader(io.BytesIO(fast), validate_crcs=True).iter_messages(topics=["/a"]))
    assert [m.data for _, _, m in msgs] == payloads
    assert [m.sequence for _, _, m in msgs][:4] == [2**32 - 3, 2**32 - 2, 2**32 - 1, 0]


def test_bench_log_reports_both_encodings() -> None:
    """``eha-hil bench log``'s encoding comparison: sizes from the files it wrote."""
    from hil.bench.log import bench_encodings, format_report
    from hil.replay.signals import ACTUATOR

    enc = {e.encoding: e for e in bench_encodings(50)}
    assert enc["protobuf"].message_bytes == ACTUATOR.size
    assert enc["json"].message_bytes > enc["protobuf"].message_bytes
    assert all(e.file_bytes > 0 and e.encode_write_us > 0 for e in enc.values())
    assert "protobuf" in format_report(None, list(enc.values()))


@pytest.mark.parametrize("chunk_size", [64, 1 << 20])
def test_messages_as_one_array_make_the_same_file(chunk_size: int) -> None:
    """A (n, size) array of payloads, and the library's own add_message on the same channel
    between two batches (its index then holds pairs and arrays of pairs, in order)."""
    import numpy as np

    payloads = [bytes([i % 251, i // 251, 7]) for i in range(40)]
    files = []
    for as_array in (True, False):
        buf = io.BytesIO()
        w = Writer(buf, chunk_size=chunk_size, compression=CompressionType.NONE)
        w.start(profile="t", library="t")
        a = w.register_channel("/a", "x", w.register_schema("s", "x", b""))
        data = np.frombuffer(b"".join(payloads), np.uint8).reshape(40, 3)
        first, second = (data[:20], data[20:]) if as_array else (payloads[:20], payloads[20:])
        batch.add_messages(w, a, np.arange(20) * 10, first, 0, as_array)
        w.add_message(a, 195, b"mid", 195, 20)
        batch.add_messages(w, a, 200 + np.arange(20) * 10, second, 21, as_array)
        w.finish()
        files.append(buf.getvalue())
    if chunk_size > 1000:
        assert files[0] == files[1]
    for f in files:
        msgs = list(make_reader(io.BytesIO(f), validate_crcs=True).iter_messages())
        assert [m.data for _, _, m in msgs] == payloads[:20] + [b"mid"] + payloads[20:]
        assert [m.log_time for _, _, m in msgs][19:22] == [190, 195, 200]


@pytest.mark.parametrize("library_chunks", [False, True])
@pytest.mark.parametrize("chunk_size", [700, 1 << 20])
def test_blocks_of_many_channels_make_the_same_file(tmp_path, chunk_size: int,  # noqa: ANN001
                                                    library_chunks: bool, monkeypatch) -> None:  # noqa: ANN001
    """FrameLogWriter.write_blocks (one record array for all channels, built in the chunk
    buffer, or with the library's own chunks copied into its buffer a slice of channels at
    a time) writes the messages write_block writes one channel at a time; with chunks
    larger than a batch, the same file byte for byte."""
    import numpy as np

    from hil.framelog import FrameLogReader, FrameLogWriter, chunk, rawpb

    if library_chunks:
        monkeypatch.setattr(chunk, "install", lambda *a: False)
    # a block's noisy low bits are chosen from the frames of all channels written with it
    # (rawpb.noisy_widths): fixed here, so that both ways give the same bytes
    monkeypatch.setattr(rawpb, "noisy_widths", lambda f: np.full(f.shape[2], 8, np.int64))

    rng = np.random.default_rng(7)
    t = [np.arange(k * 20, k * 20 + 20, dtype=np.int64) * 1000 for k in range(5)]
    frames = rng.integers(0, 2**16, (5, 3, 20, 34)).astype(np.uint16)
    files = []
    for many in (True, False):
        path = tmp_path / f"{many}.mcap"
        with FrameLogWriter(path, chunk_size=chunk_size, compression="none") as w:
            chs = [w.add_block_channel(f"/u{i}", "eha-hil/mcu-up", dtype=np.uint16, width=34)
                   for i in range(3)]
            other = w.add_block_channel("/o", "eha-hil/x", dtype=np.uint8, width=2)
            for k in range(5):
                if many:
                    w.write_blocks(chs, t[k], frames[k].astype(np.int64))  # cast checked
                else:
                    for i, c in enumerate(chs):
                        w.write_block(c, t[k], frames[k, i])
                w.write_block(other, t[k][:1], np.zeros((1, 2), np.uint8))
        files.append(path.read_bytes())
        r = FrameLogReader(path)
        for i in range(3):
            b = r.blocks(f"/u{i}")
            assert np.array_equal(b.frames, frames[:, i].reshape(-1, 34))
            assert np.array_equal(b.t_ns, np.concatenate(t))
    if chunk_size > 1000:
        assert files[0] == files[1]
    with FrameLogWriter(tmp_path / "bad.mcap") as w:
        c = w.add_block_channel("/u", "eha-hil/mcu-up", dtype=np.uint16, width=34)
        with pytest.raises(ValueError, match="fit"):
            w.write_blocks([c], t[0], np.full((1, 20, 34), 70000))


@pytest.mark.parametrize("library_chunks", [False, True])
@pytest.mark.parametrize("chunk_size", [500, 1 << 20])
def test_messages_of_many_channels_make_the_same_file(tmp_path, chunk_size: int,  # noqa: ANN001
                                                      library_chunks: bool, monkeypatch) -> None:  # noqa: ANN001
    """FrameLogWriter.write_messages_many writes what write_messages writes one channel at
    a time (the very file when no chunk closes inside a batch), in our chunk buffer or the
    library's."""
    import numpy as np

    from hil.framelog import FrameLogWriter, chunk

    if library_chunks:
        monkeypatch.setattr(chunk, "install", lambda *a: False)
    from hil.framelog.protobuf import Field, MessageType

    msg = MessageType("t.M", [Field("a", "double"), Field("b", "fixed32")])
    rng = np.random.default_rng(2)
    blocks = [(np.sort(rng.integers(0, 50, 6)) + 100 * blk,
               msg.encode_array({"a": rng.normal(size=24), "b": rng.integers(0, 9, 24)},
                                24).reshape(4, 6, -1)) for blk in range(3)]
    files = []
    for many in (True, False):
        path = tmp_path / f"{many}.mcap"
        with FrameLogWriter(path, chunk_size=chunk_size, compression="none") as w:
            chs = [w.add_protobuf_channel(f"/s{i}", msg) for i in range(4)]
            for t, m in blocks:
                if many:
                    w.write_messages_many(chs, t, m)
                else:
                    for i, c in enumerate(chs):
                        w.write_messages(c, t, m[i])
        files.append(path.read_bytes())
    if chunk_size > 1000:
        assert files[0] == files[1]
    got = []
    for f in files:
        reader = make_reader(io.BytesIO(f), validate_crcs=True)
        got.append(sorted((c.topic, m.log_time, m.sequence, m.data)
                          for _, c, m in reader.iter_messages()))
    assert got[0] == got[1] and len(got[0]) == 72


def test_messages_filled_in_place_are_the_messages_of_the_array(tmp_path) -> None:  # noqa: ANN001
    """write_messages_filled (the producer writes the messages into their records) gives
    the file write_messages_many gives; a fill that raises leaves nothing behind."""
    import numpy as np

    from hil.framelog import FrameLogReader, FrameLogWriter

    rng = np.random.default_rng(4)
    m = rng.integers(0, 256, (3, 5, 9)).astype(np.uint8)
    t = np.arange(5) * 10
    files = []
    for filled in (True, False):
        path = tmp_path / f"{filled}.mcap"
        with FrameLogWriter(path, compression="none") as w:
            chs = [w.add_channel(f"/s{i}", "json") for i in range(3)]
            if filled:
                def boom(out: np.ndarray) -> None:
                    out[0] = 1
                    raise RuntimeError("encoder failed")

                with pytest.raises(RuntimeError, match="encoder"):
                    w.write_messages_filled(chs, t, 9, boom)

                def fill(out: np.ndarray) -> None:
                    assert out.shape == (3, 5, 9)
                    out[...] = m

                w.write_messages_filled(chs, t, 9, fill)
            else:
                w.write_messages_many(chs, t, m)
        files.append(path.read_bytes())
    assert files[0] == files[1]
    got = FrameLogReader(tmp_path / "True.mcap")
    assert [bytes(d) for _, _, d in got.frames(topics=["/s2"])] == [bytes(r) for r in m[2]]
