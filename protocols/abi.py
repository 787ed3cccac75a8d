"""ABI incremental (quadrature) signals of the RLS RMB30SI and their 4x decoder.

Convention: one *count* is one edge of A or B (4x decoding). For increasing count the
(A, B) state runs 00 -> 10 -> 11 -> 01 -> 00, i.e. A leads B by a quarter cycle when
turning forward (the usual convention; swap A and B in the wiring to reverse it).
The index I is high while ``count mod counts_per_rev == 0`` (one count wide, gated with
A = B = 0 as most encoders do). ``counts_per_rev`` defaults to 2048 quadrature counts per
revolution (512 A/B cycles), matching the SSI resolution; the RMB30 data sheet's meaning
of "2048" for the incremental output is not confirmed, so it is a parameter.

A transition in which both A and B change between two samples is illegal (the sample
rate was too low or a line glitched): the decoder cannot tell the direction, does not
count it, and counts it in ``illegal``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from protocols.bits import as_index
from protocols.errors import FrameError, RangeError, as_int, finite_number

COUNTS_PER_REV = 2048
#: (A, B) per quadrature phase 0..3 (count mod 4).
STATES: tuple[tuple[int, int], ...] = ((0, 0), (1, 0), (1, 1), (0, 1))
#: Phase 0..3 of the state index A << 1 | B.
_PHASE = (0, 3, 1, 2)
_PHASE_NP = np.asarray(_PHASE, dtype=np.int64)
#: Count change per phase difference (new - old) mod 4; 2 is illegal (counted as 0).
_DELTA_NP = np.asarray((0, 1, 0, -1), dtype=np.int64)


def ab_from_count(count: int) -> tuple[int, int]:
    """(A, B) levels at a quadrature count (any integer, negative allowed)."""
    if count.__class__ is not int:
        count = as_int(count, "quadrature count")
    return STATES[count & 3]


def abi_from_count(count: int, counts_per_rev: int = COUNTS_PER_REV) -> tuple[int, int, int]:
    """(A, B, I) levels at a quadrature count."""
    count = as_int(count, "quadrature count")
    counts_per_rev = as_int(counts_per_rev, "counts_per_rev", 1)
    a, b = STATES[count & 3]
    return a, b, int(count % counts_per_rev == 0)


def count_from_angle(theta_mech_rad: float, counts_per_rev: int = COUNTS_PER_REV) -> int:
    """Quadrature count (floor) of an unwrapped mechanical angle in radians."""
    x = (finite_number(theta_mech_rad, "mechanical angle")
         * as_int(counts_per_rev, "counts_per_rev", 1) / (2.0 * math.pi))
    if not math.isfinite(x):
        raise RangeError(f"angle {theta_mech_rad!r} is not finite")
    return math.floor(x)


def abi_from_angle(theta_mech_rad: float, counts_per_rev: int = COUNTS_PER_REV
                   ) -> tuple[int, int, int]:
    """(A, B, I) levels at an unwrapped mechanical angle in radians."""
    return abi_from_count(count_from_angle(theta_mech_rad, counts_per_rev), counts_per_rev)


def _level(x: object, name: str) -> int:
    v = as_index(x, name)
    if v not in (0, 1):
        raise FrameError(f"{name} level {v} is neither 0 nor 1")
    return v


class QuadratureCounter:
    """4x quadrature decoder: feed (A, B[, I]) samples, read ``count`` and ``illegal``.

    ``index_count`` holds the count at the last rising edge of I (None before the first).
    """

    def __init__(self, a: int = 0, b: int = 0, count: int = 0) -> None:
        self._phase = _PHASE[_level(a, "A") << 1 | _level(b, "B")]
        self._index = 0
        self.count = as_int(count, "quadrature count")
        self.illegal = 0
        self.index_count: int | None = None

    def update(self, a: object, b: object, i: object = 0) -> int:
        """Take one sample; return the count change (+1, -1, 0; 0 for an illegal one)."""
        phase = _PHASE[_level(a, "A") << 1 | _level(b, "B")]
        d = (phase - self._phase) & 3
        self._phase = phase
        if d == 1:
            self.count += 1
            delta = 1
        elif d == 3:
            self.count -= 1
            delta = -1
        else:
            delta = 0
            if d == 2:
                self.illegal += 1
        idx = _level(i, "I")
        if idx and not self._index:
            self.index_count = self.count
        self._index = idx
        return delta


class QuadratureBatch(NamedTuple):
    """Result of :func:`count_array`."""

    count: np.ndarray  # int64 count after each sample
    illegal: np.ndarray  # bool: this sample was an illegal transition


def count_array(a: np.ndarray, b: np.ndarray, a0: int = 0, b0: int = 0,
                count0: int = 0) -> QuadratureBatch:
    """Vectorised decoder over logged A/B samples, starting from state (a0, b0, count0)."""
    av = np.asarray(a).ravel()
    bv = np.asarray(b).ravel()
    if av.shape != bv.shape:
        raise FrameError("A and B sample arrays differ in shape")
    for arr, name in ((av, "A"), (bv, "B")):
        if arr.dtype.kind not in "biu" or (arr.size and (arr.min() < 0 or arr.max() > 1)):
            raise FrameError(f"{name} samples must be integers 0 or 1")
    start = _PHASE[_level(a0, "A") << 1 | _level(b0, "B")]
    # The counts are int64: a start beyond it would overflow inside numpy.
    count0 = as_int(count0, "count0", -(1 << 62), 1 << 62)
    if av.size == 0:
        return QuadratureBatch(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool))
    phase = _PHASE_NP[(av.astype(np.int64) << 1) | bv.astype(np.int64)]
    prev = np.concatenate(([start], phase[:-1]))
    d = (phase - prev) & 3
    return QuadratureBatch(count0 + np.cumsum(_DELTA_NP[d]), d == 2)
