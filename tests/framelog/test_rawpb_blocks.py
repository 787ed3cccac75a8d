"""Block messages as this writer lays them out (frames as byte planes, evenly spaced times
as a first time and a spacing) and as logs before did (rows, every time): both read back
the same frames; the planes are where docs/framelog.md says, read with the protobuf
runtime from the schema in the file."""

from __future__ import annotations

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from hil.framelog import rawpb


def _stock(encoding: str, data: bytes):  # noqa: ANN202 - a protobuf message
    name, fds = rawpb.block_schema(encoding)
    pool = descriptor_pool.DescriptorPool()
    for f in descriptor_pb2.FileDescriptorSet.FromString(fds).file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name)).FromString(data)


def _zigzag_deltas_by_hand(column: list[int], bits: int) -> list[int]:
    """The doc's zigzag-coded differences of one element's values, in Python integers."""
    out, before = [], 0
    for v in column:
        d = (v - before) % (1 << bits)
        d = d - (1 << bits) if d >> (bits - 1) else d  # as signed
        out.append(((d << 1) ^ (d >> (bits - 1))) % (1 << bits))
        before = v
    return out


@pytest.mark.parametrize("deltas", [True, False])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int64])
def test_byte_planes_are_where_the_doc_says(dtype: type, deltas: bool) -> None:
    rng = np.random.default_rng(3)
    frames = rng.integers(0, 120, (7, 3)).astype(dtype)
    frames[2, 1] = 0x7A  # a byte of its own, to be found at its place
    frames[4, 0] = -5 if np.dtype(dtype).kind == "i" else 250  # a step down, a sign
    t = 1000 + 50 * np.arange(7)
    rec = rawpb.pack_blocks(t, frames[None], np.dtype(dtype), deltas=deltas,
                            low_bits=False)  # field 9: logs before the noisy bits apart
    m = _stock("eha-hil/x", rec[0].tobytes())
    size = np.dtype(dtype).itemsize
    bits = 8 * size
    raw = bytes(m.frame_deltas if deltas else m.frames)
    assert m.byte_planes and m.count == 7 and m.width == 3 and len(raw) == 21 * size
    assert len(m.frames if deltas else m.frame_deltas) == 0
    assert list(m.t_ns) == [] and (m.t0_ns, m.dt_ns) == (1000, 50)
    for j in range(3):
        col = [int(v) % (1 << bits) for v in frames[:, j]]
        stored = _zigzag_deltas_by_hand(col, bits) if deltas else col
        for i in range(7):
            for b in range(size):  # byte b of element j of frame i: (b * width + j) * count + i
                assert raw[(b * 3 + j) * 7 + i] == stored[i] >> (8 * b) & 0xFF
    got_t, got = rawpb.unpack_block(m.SerializeToString())
    assert np.array_equal(got_t, t) and np.array_equal(got, frames) and got.dtype == dtype
    from tests.framelog.stock_blocks import block_rows

    assert np.array_equal(block_rows(m)[1], frames)  # numpy alone, as logs before hold them


@pytest.mark.parametrize("low_bits", [True, False])
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint32, np.int64, np.float32,
                                   np.float64])
def test_frame_deltas_give_back_every_bit(dtype: type, low_bits: bool) -> None:
    """Extremes, wrap-arounds and float bit patterns (NaN, -0.0, inf) come back exactly,
    with the noisy low bits apart and (logs before) without."""
    rng = np.random.default_rng(5)
    size = np.dtype(dtype).itemsize
    bits = rng.integers(0, 256, (2, 40, 4 * size), dtype=np.uint8)
    bits[0, ::3] = 0xFF  # all ones, then all zeros: the widest steps
    bits[0, 1::3] = 0
    frames = bits.view(dtype).reshape(2, 40, 4)
    if np.dtype(dtype).kind == "f":
        frames[1, :3, 0] = [np.nan, -0.0, np.inf]
    rec = rawpb.pack_blocks(np.arange(40) * 3, frames, np.dtype(dtype), deltas=True,
                            low_bits=low_bits)
    assert ("hi" in rec.dtype.names) == (low_bits and size > 1)  # bytes: as before
    for i in range(2):
        _, got = rawpb.unpack_block(rec[i].tobytes())
        assert got.dtype == np.dtype(dtype) and got.tobytes() == frames[i].tobytes()


def test_a_block_with_frames_and_deltas_is_refused() -> None:
    frames = np.arange(6, dtype=np.uint16).reshape(1, 3, 2)
    m = _stock("eha-hil/x", rawpb.pack_blocks(np.arange(3), frames, np.dtype(np.uint16),
                                             deltas=True, low_bits=False)[0]
               .tobytes())
    m.frames = bytes(m.frame_deltas)
    with pytest.raises(ValueError, match="more than one of frames, frame_deltas"):
        rawpb.unpack_block(m.SerializeToString())
    m = _stock("eha-hil/x", rawpb.pack_blocks(np.arange(3), frames, np.dtype(np.uint16))[0]
               .tobytes())
    m.frame_deltas = bytes(6 * 2)
    with pytest.raises(ValueError, match="more than one of frames, frame_deltas"):
        rawpb.unpack_block(m.SerializeToString())


def test_uneven_times_are_written_one_by_one() -> None:
    t = np.array([0, 10, 10, 35])
    frames = np.arange(8, dtype=np.uint16).reshape(4, 2)
    m = _stock("eha-hil/x", rawpb.pack_block(t, frames, np.dtype(np.uint16)))
    assert list(m.t_ns) == t.tolist() and m.t0_ns == m.dt_ns == 0
    got_t, got = rawpb.unpack_block(m.SerializeToString())
    assert np.array_equal(got_t, t) and np.array_equal(got, frames)


def test_row_blocks_of_logs_before_still_read() -> None:
    t = 5 + 3 * np.arange(4)
    frames = np.arange(4 * 33, dtype=np.uint32).reshape(1, 4, 33)
    rec = rawpb.pack_blocks(t, frames, np.dtype(np.uint32), byte_planes=False)
    m = _stock("eha-hil/mcu-up", rec[0].tobytes())
    assert not m.byte_planes
    assert np.array_equal(np.frombuffer(m.frames, "<u4").reshape(4, 33), frames[0])
    old = rawpb.pack_blocks(np.array([5, 6, 9, 9]), frames, np.dtype(np.uint32),
                            byte_planes=False)[0].tobytes()
    got_t, got = rawpb.unpack_block(old)
    assert got_t.tolist() == [5, 6, 9, 9] and np.array_equal(got, frames[0])


def test_a_block_without_times_is_refused() -> None:
    m = _stock("eha-hil/x", rawpb.pack_block(np.arange(3), np.zeros((3, 2), np.uint8),
                                             np.dtype(np.uint8)))
    m.ClearField("t0_ns")
    with pytest.raises(ValueError, match="no t0_ns"):
        rawpb.unpack_block(m.SerializeToString())


@pytest.mark.parametrize("width", [1, 4])
def test_packing_leaves_the_frames_alone(width: int) -> None:
    frames = np.arange(6 * width, dtype=np.uint32).reshape(1, 6, width) * 0x01010101
    kept = frames.copy()
    rec = rawpb.pack_blocks(np.arange(6), frames, np.dtype(np.uint32))
    assert np.array_equal(frames, kept)
    assert np.array_equal(rawpb.unpack_block(rec[0].tobytes())[1], kept[0])


@pytest.mark.parametrize("widths", [None, [3, 0, 16], [8, 1, 15]])
def test_noisy_low_bits_are_where_the_doc_says(widths: list[int] | None,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Fields 10-12 by hand from the doc: element j's w_j bit planes (bit t of byte m =
    bit b of z of frame 8 m + t), then z >> w_j as byte planes (all of them: blocks before
    the trimmed ones, still written where trimming leaves nothing out); read back by our reader
    and by numpy alone on the stock-decoded message (tests/framelog/stock_blocks.py), for
    the writer's own widths (whole bytes) and any others a writer may choose."""
    from tests.framelog.stock_blocks import block_rows

    rng = np.random.default_rng(4)
    frames = (30_000 + rng.integers(-40, 41, (11, 3))).astype(np.uint16)
    frames[:, 1] = 7  # constant
    frames[1, 2] = 2  # a wide step where the sample looks (frame 1 - frame 0)
    if widths is not None:
        monkeypatch.setattr(rawpb, "noisy_widths", lambda f: np.array(widths, np.int64))
    m = _stock("eha-hil/x", rawpb.pack_blocks(5 + 10 * np.arange(11), frames[None],
                                              np.dtype(np.uint16), trimmed=False)[0]
               .tobytes())  # every plane (logs before the trimmed blocks)
    assert len(m.frames) == len(m.frame_deltas) == len(m.first_frame) == 0 and m.byte_planes
    assert len(m.high_planes) == 0
    w = list(m.low_widths)
    assert w == (widths or [8, 0, 16])  # noise: a byte; constant: none; a wide step: all
    low, high = bytes(m.low_bits), bytes(m.high_deltas)
    lo = hi = 0
    for j in range(3):
        z = _zigzag_deltas_by_hand([int(v) for v in frames[:, j]], 16)
        for b in range(w[j]):
            for i in range(11):
                assert (low[lo + i // 8] >> (i % 8)) & 1 == (z[i] >> b) & 1
            assert low[lo + 1] >> 3 == 0  # past the last frame: 0
            lo += 2
        for b in range((16 - w[j] + 7) // 8):
            assert list(high[hi:hi + 11]) == [(v >> w[j] >> 8 * b) & 0xFF for v in z]
            hi += 11
    assert (lo, hi) == (len(low), len(high))
    assert np.array_equal(block_rows(m)[1], frames)
    got_t, got = rawpb.unpack_block(m.SerializeToString())
    assert np.array_equal(got, frames) and got_t.tolist() == (5 + 10 * np.arange(11)).tolist()


def test_noisy_low_bits_of_wrong_sizes_are_refused() -> None:
    frames = np.arange(12, dtype=np.uint16).reshape(1, 6, 2)
    m = _stock("eha-hil/x", rawpb.pack_blocks(np.arange(1, 7), frames, np.dtype(np.uint16))[0]
               .tobytes())
    for field, value, match in (("low_widths", bytes([17, 0]), "low_widths"),
                                ("low_widths", bytes([8]), "low_widths"),
                                ("high_deltas", b"\0" * 5, "high_deltas")):
        bad = _stock("eha-hil/x", m.SerializeToString())
        setattr(bad, field, value)
        with pytest.raises(ValueError, match=match):
            rawpb.unpack_block(bad.SerializeToString())


def test_trimmed_blocks_are_where_the_doc_says() -> None:
    """Fields 13-14 by hand from the doc: the differences taken from the first frame
    (frame 0's is 0), each element's bit planes up to its highest bit ever 1 (below the
    noisy width), and only the byte planes of z >> w_j that hold a 1 (high_planes); read
    back by our reader and by numpy alone on the stock-decoded message, and refused by a
    reader of the blocks before (high_deltas shorter than every plane)."""
    from tests.framelog.stock_blocks import block_rows

    rng = np.random.default_rng(6)
    frames = (30_000 + rng.integers(-3, 4, (2, 11, 4))).astype(np.uint16)
    frames[:, :, 1] = [[7], [9]]  # constant, a different value per channel
    frames[0, 4, 2] = 29_000  # one step down and back: 11 bits, beyond the noisy byte
    frames[:, :, 3] = 0x8000 + 5 * np.arange(11)  # a ramp: 4 bits, no byte plane
    rec = rawpb.pack_blocks(5 + 10 * np.arange(11), frames, np.dtype(np.uint16))
    bits = 16
    for i in range(2):
        m = _stock("eha-hil/x", rec[i].tobytes())
        w, planes = list(m.low_widths), list(m.high_planes)
        assert np.frombuffer(m.first_frame, "<u2").tolist() == frames[i, 0].tolist()
        zs = []
        for j in range(4):  # the differences from the first frame, by hand
            col = [int(v) for v in frames[:, :, j].ravel()]  # both channels' (one layout)
            zs.append([_zigzag_deltas_by_hand([c[0]] + c, bits)[1:]
                       for c in (col[:11], col[11:])])
        top = [max(max(z) for z in zs[j]).bit_length() for j in range(4)]
        w8 = rawpb.noisy_widths(frames).tolist()  # (its sample: frame 1 - frame 0)
        assert w == [min(a, b) for a, b in zip(w8, top, strict=True)]
        assert planes == [(max(t - a, 0) + 7) // 8 for t, a in zip(top, w, strict=True)]
        assert w[1] == top[1] == 0 and w[3] == top[3] == 4  # constant; a ramp of 5s
        assert top[2] == 11 and planes[2] == 1  # the step: its 3 bits above w8 in one plane
        low, high = bytes(m.low_bits), bytes(m.high_deltas)
        lo = hi = 0
        for j in range(4):
            z = zs[j][i]
            assert z[0] == 0
            for b in range(w[j]):
                for n in range(11):
                    assert (low[lo + n // 8] >> (n % 8)) & 1 == (z[n] >> b) & 1
                lo += 2
            for b in range(planes[j]):
                assert list(high[hi:hi + 11]) == [(v >> w[j] >> 8 * b) & 0xFF for v in z]
                hi += 11
        assert (lo, hi) == (len(low), len(high)) == (2 * sum(w), 11 * sum(planes))
        assert np.array_equal(block_rows(m)[1], frames[i])
        got_t, got = rawpb.unpack_block(m.SerializeToString())
        assert np.array_equal(got, frames[i])
        # a reader of the blocks before takes every byte plane: the sizes disagree
        old = _stock("eha-hil/x", m.SerializeToString())
        old.ClearField("high_planes")
        with pytest.raises(ValueError, match="high_deltas"):
            rawpb.unpack_block(old.SerializeToString())


def test_a_block_with_nothing_to_trim_is_written_as_before() -> None:
    """Noise over every bit (nothing to leave out): no first_frame or high_planes, the
    bytes of the untrimmed writer, so readers of the blocks before read it."""
    rng = np.random.default_rng(8)
    frames = rng.integers(0, 2**16, (2, 30, 3)).astype(np.uint16)
    rec = rawpb.pack_blocks(np.arange(30), frames, np.dtype(np.uint16))
    assert rec.tobytes() == rawpb.pack_blocks(np.arange(30), frames, np.dtype(np.uint16),
                                              trimmed=False).tobytes()
    m = _stock("eha-hil/x", rec[1].tobytes())
    assert len(m.first_frame) == len(m.high_planes) == 0 and list(m.low_widths) == [16] * 3
    assert np.array_equal(rawpb.unpack_block(rec[1].tobytes())[1], frames[1])


def test_trimmed_blocks_of_wrong_sizes_are_refused() -> None:
    frames = (100 + np.arange(24, dtype=np.uint16) % 3).reshape(1, 12, 2)
    m = _stock("eha-hil/x", rawpb.pack_blocks(np.arange(1, 13), frames, np.dtype(np.uint16))[0]
               .tobytes())
    assert len(m.first_frame) == 4 and list(m.high_planes) == [0, 0]
    for field, value, match in (("high_planes", bytes([3, 0]), "high_planes"),
                                ("high_planes", bytes([0]), "high_planes"),
                                ("high_planes", bytes([1, 0]), "high_deltas"),
                                ("first_frame", b"\0" * 3, "first_frame")):
        bad = _stock("eha-hil/x", m.SerializeToString())
        setattr(bad, field, value)
        with pytest.raises(ValueError, match=match):
            rawpb.unpack_block(bad.SerializeToString())
