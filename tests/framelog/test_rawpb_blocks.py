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
    assert ("hi" in rec.dtype.names) == low_bits
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
