"""``/signals/bus``'s per-cycle frame count and working-counter sum, counted a block at a
time from the frames the run's tap kept, against a frame-by-frame count."""

from __future__ import annotations

import numpy as np

from hil.replay.record import _frames_and_wkc


def test_frames_and_wkc_per_cycle_equal_a_frame_by_frame_count():
    rng = np.random.default_rng(2)
    frames, rx, ends = [], [], []
    want_frames, want_wkc = [], []
    for _ in range(40):
        sent = wkc = 0
        for _ in range(int(rng.integers(0, 5))):  # some cycles have no frame at all
            is_rx = bool(rng.integers(0, 2))
            f = rng.integers(0, 256, int(rng.integers(2, 30))).astype(np.uint8).tobytes()
            frames.append(f)
            rx.append(is_rx)
            if not is_rx:
                sent += 1
            elif len(f) >= 6:  # a reply: its WKC is the 2 bytes before the FCS
                wkc += int.from_bytes(f[-6:-4], "little")
        ends.append(len(frames))
        want_frames.append(sent)
        want_wkc.append(wkc)
    got_frames, got_wkc = _frames_and_wkc(frames, rx, np.array(ends))
    assert got_frames.tolist() == want_frames
    assert got_wkc.tolist() == want_wkc
    assert sum(want_wkc) > 0 and 0 in want_frames


def test_a_block_without_frames_counts_zeros():
    got = _frames_and_wkc([], [], np.array([0, 0, 0]))
    assert [g.tolist() for g in got] == [[0, 0, 0], [0, 0, 0]]
