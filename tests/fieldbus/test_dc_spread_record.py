"""The frame thread's record of the slaves' system-time spread
(:func:`hil.fieldbus.esc.frames.record_spread`): the largest value per window of the slaves'
clock, whatever the box thread does; a window the thread never woke in is unknown (-1); the
ring keeps the newest windows."""

from __future__ import annotations

import numpy as np

from hil.fieldbus.esc import frames as ef

W = ef.SPREAD_WINDOW_NS


def _record(ring: np.ndarray, stats: np.ndarray, seen: list[tuple[int, int]]) -> None:
    for now, spread in seen:
        ef.record_spread(ring, stats, now, spread)


def _read(ring: np.ndarray, stats: np.ndarray) -> tuple[int, list[int]]:
    t = ef.FrameThread.__new__(ef.FrameThread)   # only its record
    t.spread_ring, t.stats = ring, stats
    return t.dc_spread()


def test_largest_per_window_and_unknown_windows():
    ring = np.full(8, -1, dtype=np.int64)
    stats = np.zeros(ef.N_STATS, dtype=np.int64)
    # window 0: 5 then 3 (keeps 5); nothing in windows 1 and 2 (a stalled thread); window
    # 3: 0 then 7 then 2
    _record(ring, stats, [(1, 5), (W - 1, 3), (3 * W, 0), (3 * W + 10, 7), (4 * W - 1, 2)])
    assert _read(ring, stats) == (0, [5, -1, -1, 7])


def test_the_ring_keeps_the_newest_windows():
    ring = np.full(4, -1, dtype=np.int64)
    stats = np.zeros(ef.N_STATS, dtype=np.int64)
    _record(ring, stats, [(k * W + W // 2, 10 * k) for k in range(10)])
    assert _read(ring, stats) == (6, [60, 70, 80, 90])
    # a jump longer than the ring: every window held is unknown but the newest
    _record(ring, stats, [(20 * W, 1)])
    assert _read(ring, stats) == (17, [-1, -1, -1, 1])
