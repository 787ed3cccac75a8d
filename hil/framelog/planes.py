"""The byte planes of a block of frames in one compiled pass (:func:`split`).

A whole-robot log turns ~23 MB of register words per simulated second into byte planes
(:func:`hil.framelog.rawpb.pack_blocks`). With numpy that is a transposed copy and a shift
per byte, and the zigzag-coded differences (field ``frame_deltas``) four passes more: each
pass over the data costs ~3-8 ms per simulated second on the project's 2-core machine, more
than the smaller planes save zstd. Here every element is read once and each of its bytes
written once into its plane. The numpy path (``rawpb._planes_numpy``, with
:func:`hil.framelog.rawpb.zigzag_deltas`) stays the readable reference;
``tests/framelog/test_planes.py`` compares the two byte for byte.
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
