"""The byte and bit planes of a block of frames in compiled passes.

A whole-robot log turns ~23 MB of register words per simulated second into planes
(:func:`hil.framelog.rawpb.pack_blocks`). With numpy that is a transposed copy and a shift
per byte, and the zigzag-coded differences four passes more: each pass over the data costs
~3-8 ms per simulated second on the project's 2-core machine, more than the smaller planes
save zstd. Here every element of the engine's block is read once: :func:`split` (the byte
planes of the frames or of their differences, field 9) or :func:`zigzag_columns` (the
differences into one contiguous column per element, with the OR of each element's codes
that decides which planes a trimmed block keeps) and :func:`split_columns` (those columns'
bit and byte planes). The numpy paths (``rawpb._planes_numpy``, ``rawpb._zigzag_numpy``,
``rawpb._split_numpy``) stay the readable references; ``tests/framelog/test_planes.py``
compares them byte for byte.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def split(frames: np.ndarray, out: np.ndarray, deltas: bool) -> None:  # pragma: no cover
    """``out[i, b, j, n]`` = byte ``b`` of element ``j`` of frame ``n`` of ``frames[i]``
    (``frames`` (k, count, width) signed integers of ``out.shape[1]`` bytes, any strides;
    ``out`` (k, size, width, count) uint8), or with ``deltas`` of the zigzag code of its
    difference to frame ``n - 1`` (the first: to 0), modulo 2^bits."""
    k, count, width = frames.shape
    size = out.shape[1]
    bits = 8 * size
    shift = 64 - bits  # (d << shift) >> shift: d modulo 2^bits, as signed
    col = np.empty(count, np.int64)
    for i in range(k):
        for j in range(width):
            for n in range(count):
                col[n] = frames[i, n, j]  # sign-extended
            if deltas:
                for n in range(count - 1, 0, -1):
                    d = ((col[n] - col[n - 1]) << shift) >> shift
                    col[n] = (d << 1) ^ (d >> 63)
                d = col[0]
                col[0] = (d << 1) ^ (d >> 63)
            for b in range(size):
                plane = out[i, b, j]
                s = 8 * b
                for n in range(count):
                    plane[n] = (col[n] >> s) & 0xFF


@njit(cache=True, nogil=True)
def low_widths(frames: np.ndarray, bits: int, stride: int, share: int,
               out: np.ndarray) -> None:  # pragma: no cover
    """``out[j]``: the noisy low bits of element ``j`` of ``frames`` ((k, count, width)
    signed integers of ``bits`` bits), in whole bytes: 8 x the fewest bytes that hold all
    but ``1 / share`` of a sample of its zigzag-coded differences (frame ``n`` minus frame
    ``n - 1`` for ``n`` = 1, 1 + ``stride``, ... of every one of the ``k`` channels)."""
    k, count, width = frames.shape
    shift = 64 - bits
    size = bits // 8
    hist = np.zeros((width, 9), np.int64)  # samples per element and byte length
    total = 0
    for i in range(k):
        for n in range(1, count, stride):
            row = frames[i, n]
            before = frames[i, n - 1]
            for j in range(width):
                d = ((row[j] - before[j]) << shift) >> shift
                z = (d << 1) ^ (d >> 63)
                length = 0
                while z != 0:  # bytes, at most 8 steps (logical shift)
                    z = (z >> 8) & 0x00FFFFFFFFFFFFFF
                    length += 1
                hist[j, length] += 1
            total += 1
    allowed = total // share
    for j in range(width):
        above = 0
        length = size
        while length > 0 and above + hist[j, length] <= allowed:
            above += hist[j, length]
            length -= 1
        out[j] = 8 * length


@njit(cache=True, nogil=True)
def zigzag_columns(frames: np.ndarray, first: np.ndarray, bits: int, z: np.ndarray,
                   spans: np.ndarray) -> None:  # pragma: no cover
    """``z[i, j, n]``: the zigzag code of the difference of element ``j`` of frame ``n`` of
    ``frames[i]`` ((k, count, width) signed integers of ``bits`` bits, any strides) to the
    same element of frame ``n - 1``, modulo 2^bits, frame ``-1`` being ``first[i]``
    ((k, width) int64: zeros, or the first frame, whose own difference is then 0); ``z``
    (k, width, count) signed integers of the element's size (the code's bits as they
    are). ``spans[j]``: the OR of element ``j``'s codes over all frames and channels (its
    highest bit that is ever 1). Every element is read once, each code written once, into
    one contiguous column per element (read again by :func:`split_columns`)."""
    k, count, width = frames.shape
    shift = 64 - bits
    col = np.empty(count, np.int64)
    for j in range(width):
        spans[j] = 0
    for i in range(k):
        for j in range(width):
            for n in range(count):
                col[n] = frames[i, n, j]  # sign-extended
            out = z[i, j]
            acc = 0
            if count:
                d = ((col[0] - first[i, j]) << shift) >> shift
                v = (d << 1) ^ (d >> 63)
                out[0] = v
                acc = v
            for n in range(1, count):
                d = ((col[n] - col[n - 1]) << shift) >> shift
                v = (d << 1) ^ (d >> 63)
                out[n] = v
                acc |= v
            spans[j] |= acc


@njit(cache=True, nogil=True)
def split_columns(z: np.ndarray, bits: int, widths: np.ndarray, planes: np.ndarray,
                  low_at: np.ndarray, high_at: np.ndarray, low: np.ndarray,
                  high: np.ndarray) -> None:  # pragma: no cover
    """The zigzag-coded differences ``z`` ((k, width, count), :func:`zigzag_columns`) split
    at ``widths[j]`` = ``w`` bits: the low ``w`` bits of element ``j`` as ``w`` bit planes
    into ``low[i, low_at[j]:]`` (plane ``b``: ``(count + 7) // 8`` bytes, bit ``t`` of byte
    ``m`` = bit ``b`` of ``z`` of frame ``8 m + t``, 0 past the last frame), the first
    ``planes[j]`` byte planes of ``z >> w`` into ``high[i, high_at[j]:]`` (``count`` bytes
    each; the planes above them are left out, the caller having seen them 0). The inner
    loops write through slices (an index that numba must check for a negative value keeps
    LLVM from vectorising them), the bit planes in their own function
    (:func:`_bit_planes`: inline, they slow the loops around them by ~10 %)."""
    k, width, count = z.shape
    per_plane = (count + 7) // 8
    whole = -1 if bits >= 64 else (1 << bits) - 1  # the code's bits, without the sign
    col = np.empty(count, np.int64)
    lows = np.zeros(8 * per_plane, np.uint8)  # past count: 0 for good
    words = lows.view(np.int64)
    planes8 = np.empty(per_plane, np.int64)
    for i in range(k):
        for j in range(width):
            src = z[i, j]
            for n in range(count):
                col[n] = src[n] & whole
            w = widths[j]
            if w:
                _bit_planes(col, w, low[i, low_at[j]:low_at[j + 1]], lows, words, planes8)
            q = high_at[j]
            for b in range(planes[j]):
                s = w + 8 * b
                # the top plane's bits past the element's: 0 (the shift brings the sign)
                mask = 0xFF if bits - s >= 8 else (1 << (bits - s)) - 1
                plane = high[i, q:q + count]
                for n in range(count):
                    plane[n] = (col[n] >> s) & mask
                q += count


@njit(cache=True, nogil=True, inline="never")
def _bit_planes(col: np.ndarray, w: int, out: np.ndarray, lows: np.ndarray,
                words: np.ndarray, planes8: np.ndarray) -> None:  # pragma: no cover
    """The ``w`` low bit planes of ``col`` (count,) into ``out`` (``w`` planes of
    ``len(words)`` bytes): per byte of the values, eight values' bytes (``lows``, as the
    int64 ``words``) turned into their eight bit planes' bytes by one 8 x 8 bit-matrix
    transposition (``planes8``: byte ``b`` of word ``m`` = bit plane ``b`` of values
    ``8 m`` to ``8 m + 7``). ``lows`` past ``len(col)``: 0."""
    count = len(col)
    per_plane = len(words)
    p = 0
    for byte in range((w + 7) // 8):
        s = 8 * byte
        for n in range(count):
            lows[n] = (col[n] >> s) & 0xFF
        for m in range(per_plane):  # arithmetic shifts: the masks drop the sign they bring
            x = words[m]
            t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AA
            x = x ^ t ^ (t << 7)
            t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCC
            x = x ^ t ^ (t << 14)
            t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0
            planes8[m] = x ^ t ^ (t << 28)
        for b in range(min(8, w - s)):
            plane = out[p:p + per_plane]
            sb = 8 * b
            for m in range(per_plane):
                plane[m] = (planes8[m] >> sb) & 0xFF
            p += per_plane
