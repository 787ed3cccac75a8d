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


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int64])
def test_byte_planes_are_where_the_doc_says(dtype: type) -> None:
    rng = np.random.default_rng(3)
    frames = rng.integers(0, 120, (7, 3)).astype(dtype)
    frames[2, 1] = 0x7A  # a byte of its own, to be found at its place
    t = 1000 + 50 * np.arange(7)
    m = _stock("eha-hil/x", rawpb.pack_block(t, frames, np.dtype(dtype)))
    size = np.dtype(dtype).itemsize
    assert m.byte_planes and m.count == 7 and m.width == 3 and len(m.frames) == 21 * size
    assert list(m.t_ns) == [] and (m.t0_ns, m.dt_ns) == (1000, 50)
    raw = bytes(m.frames)
    for i in range(7):
        for j in range(3):
            for b in range(size):  # byte b of element j of frame i: (b * width + j) * count + i
                assert raw[(b * 3 + j) * 7 + i] == int(frames[i, j]) >> (8 * b) & 0xFF
    got_t, got = rawpb.unpack_block(m.SerializeToString())
    assert np.array_equal(got_t, t) and np.array_equal(got, frames) and got.dtype == dtype


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
