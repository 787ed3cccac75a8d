"""The compiled byte planes (hil/framelog/planes.py) are the numpy reference's bytes, with
and without the zigzag-coded differences, and so are the bit planes of the differences' noisy
low bits and the widths chosen for them, for every element size, strided frames included."""

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
    for deltas, low_bits, trimmed in ((False, False, False), (True, False, False),
                                      (True, True, False), (True, True, True)):
        rec = rawpb.pack_blocks(np.arange(500) * 200_000, frames, np.dtype(np.uint16),
                                deltas=deltas, low_bits=low_bits, trimmed=trimmed)
        assert ("first" in rec.dtype.names and rec.dtype["first"].itemsize > 0) == trimmed
        for i in range(4):
            assert np.array_equal(rawpb.unpack_block(rec[i].tobytes())[1], frames[i])


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.int32, np.uint64,
                                   np.int64])
def test_compiled_bit_planes_are_the_numpy_bit_planes(dtype: type) -> None:
    """The noisy widths and the split of the differences at them (bit planes below, byte
    planes above, the top plane's spare bits 0), compiled and in numpy, for counts that
    do and do not fill whole bytes of a bit plane, widths of whole bytes and not."""
    from hil.framelog.planes import low_widths, split_columns, zigzag_columns

    rng = np.random.default_rng(12)
    size = np.dtype(dtype).itemsize
    bits = 8 * size
    for count in (40, 43):
        raw = rng.integers(0, 256, (3, count + 10, 6 * size), dtype=np.uint8)
        store = raw.view(dtype)  # (3, count + 10, 6)
        store[:, :, 1] = store[:, :1, 1]  # constant: no noisy bits
        store[:, :, 2] = (store[:, :1, 2].astype(np.int64)
                          + rng.integers(-2, 3, (3, count + 10))).astype(dtype)  # 2-3 bits
        signed = store.view(f"i{size}")
        signed[0, ::2, 3] = 0  # the widest differences: +-(2^(bits-1) - 1)
        signed[0, 1::2, 3] = np.iinfo(f"i{size}").max
        frames = store[:, 5:5 + count]  # strided, as the engine's taps
        want_w = rawpb._noisy_widths_numpy(frames)
        got_w = np.empty(6, np.int64)
        for stride, share in ((1, 4), (rawpb.NOISE_STRIDE, rawpb.NOISE_SHARE)):
            saved = rawpb.NOISE_STRIDE, rawpb.NOISE_SHARE
            rawpb.NOISE_STRIDE, rawpb.NOISE_SHARE = stride, share
            try:
                want_w = rawpb._noisy_widths_numpy(frames)
            finally:
                rawpb.NOISE_STRIDE, rawpb.NOISE_SHARE = saved
            low_widths(frames.view(f"<i{size}"), bits, stride, share, got_w)
            assert got_w.tolist() == want_w.tolist()
        assert got_w[1] == 0 and want_w[2] == 8 and want_w[3] == bits  # whole bytes
        got_w[0] = bits  # every width once: all low, none, a few, the widest
        got_w[4] = 1  # any width reads back (the writer's: whole bytes)
        got_w[5] = bits - 1
        # the differences from 0 and from the first frame (trimmed blocks: frame 0's is 0)
        for first in (np.zeros((3, 6), frames.dtype), frames[:, 0]):
            want_z, want_spans = rawpb._zigzag_numpy(frames, first)
            z = np.full((3, 6, count + 2), 0x55, f"<i{size}")[..., 1:-1]  # a view, as kept
            spans = np.full(6, -1, np.int64)
            zigzag_columns(frames.view(f"<i{size}"), first.view(f"<i{size}").astype(np.int64),
                           bits, z, spans)
            assert np.array_equal(z.view(want_z.dtype), want_z)
            assert spans.view(np.uint64).astype(want_spans.dtype).tolist() == want_spans.tolist()
            # every plane, and (trimmed) fewer byte planes than the element has
            for planes in (rawpb.full_planes(got_w, size),
                           np.minimum(rawpb.full_planes(got_w, size), [1, 0, 1, 0, 2, 1])):
                low_at, high_at = rawpb.bits_layout(got_w, count, size, planes)
                want_lo = np.zeros((3, low_at[-1]), np.uint8)
                want_hi = np.zeros((3, high_at[-1]), np.uint8)
                rawpb._split_numpy(want_z, got_w, planes, low_at, high_at, want_lo, want_hi)
                rec = np.full((3, low_at[-1] + high_at[-1] + 3), 0xAA, np.uint8)  # strided
                lo, hi = rec[:, :low_at[-1]], rec[:, low_at[-1] + 1:-2]
                split_columns(z, bits, got_w, planes, low_at, high_at, lo, hi)
                assert np.array_equal(lo, want_lo) and np.array_equal(hi, want_hi)
                assert (rec[:, low_at[-1]] == 0xAA).all() and (rec[:, -2:] == 0xAA).all()
