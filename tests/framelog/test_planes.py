"""The compiled byte planes (hil/framelog/planes.py) are the numpy reference's bytes, with
and without the zigzag-coded differences, for every element size, strided frames included."""

from __future__ import annotations

import numpy as np
import pytest

from hil.framelog import rawpb
from hil.framelog.planes import split


@pytest.mark.parametrize("deltas", [False, True])
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.int32, np.uint64,
                                   np.int64])
def test_compiled_planes_are_the_numpy_planes(dtype: type, deltas: bool) -> None:
    rng = np.random.default_rng(11)
    size = np.dtype(dtype).itemsize
    raw = rng.integers(0, 256, (3, 60, 5 * size), dtype=np.uint8)
    raw[0, ::4] = 0xFF  # extremes next to each other: the widest differences
    raw[0, 1::4] = 0
    raw[1] = raw[1, :1]  # constant columns
    store = raw.view(dtype)  # (3, 60, 5)
    frames = store[:, 5:45]  # strided: rows of a larger array, as the engine's taps
    want = np.zeros((3, size, 5, 40), np.uint8)
    rawpb._planes_numpy(frames, want, deltas)
    got = np.full((3, size + 1, 5, 40), 0xAA, np.uint8)[:, :size]  # strided output too
    split(frames.view(f"<i{size}"), got, deltas)
    assert np.array_equal(got, want)


def test_large_blocks_take_the_compiled_pass_and_read_back() -> None:
    """A block of the robot's shape (over rawpb._COMPILED_FROM elements) reads back."""
    rng = np.random.default_rng(2)
    frames = (1444 + rng.integers(-3, 4, (4, 500, 34))).astype(np.uint16)
    assert frames[0].size >= rawpb._COMPILED_FROM
    for deltas in (False, True):
        rec = rawpb.pack_blocks(np.arange(500) * 200_000, frames, np.dtype(np.uint16),
                                deltas=deltas)
        for i in range(4):
            assert np.array_equal(rawpb.unpack_block(rec[i].tobytes())[1], frames[i])
