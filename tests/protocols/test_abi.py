"""ABI quadrature signals and the 4x counter.

Known answers: quadrature is a convention, not a data-sheet example; the sequence for
forward motion is 00 -> 10 -> 11 -> 01 (A leads B), checked literally below. No public
RMB30 worked example of counts versus angle was found.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.abi import (
    COUNTS_PER_REV,
    QuadratureCounter,
    ab_from_count,
    abi_from_angle,
    abi_from_count,
    count_array,
    count_from_angle,
)
from protocols.errors import CodecError, FrameError, RangeError

steps = st.lists(st.sampled_from([-1, 0, 1]), max_size=300)


def test_forward_sequence_a_leads_b() -> None:
    assert [ab_from_count(k) for k in range(5)] == [(0, 0), (1, 0), (1, 1), (0, 1), (0, 0)]
    assert ab_from_count(-1) == (0, 1)


@settings(max_examples=200, deadline=None)
@given(st.integers(-10**6, 10**6), steps)
def test_random_walk_round_trip(start: int, walk: list[int]) -> None:
    counter = QuadratureCounter(*ab_from_count(start))
    pos = start
    for s in walk:
        pos += s
        assert counter.update(*ab_from_count(pos)) == s
    assert counter.count == pos - start
    assert counter.illegal == 0


@settings(max_examples=200, deadline=None)
@given(st.integers(-1000, 1000), st.lists(st.sampled_from([-2, -1, 0, 1, 2]), max_size=200))
def test_illegal_transitions_detected_and_counted(start: int, walk: list[int]) -> None:
    counter = QuadratureCounter(*ab_from_count(start))
    pos = start
    legal_sum = 0
    for s in walk:
        pos += s
        a0, b0 = ab_from_count(pos - s)
        a1, b1 = ab_from_count(pos)
        both_changed = a0 != a1 and b0 != b1
        assert both_changed == (abs(s) == 2)
        counter.update(a1, b1)
        legal_sum += s if abs(s) < 2 else 0
    assert counter.illegal == sum(1 for s in walk if abs(s) == 2)
    assert counter.count == legal_sum


@settings(max_examples=50, deadline=None)
@given(st.integers(-100, 100), st.lists(st.sampled_from([-2, -1, 0, 1, 2]), max_size=300))
def test_batch_equals_scalar(start: int, walk: list[int]) -> None:
    counts = start + np.cumsum(np.asarray(walk, dtype=np.int64))
    ab = np.array([ab_from_count(int(c)) for c in counts], dtype=np.uint8).reshape(-1, 2)
    a0, b0 = ab_from_count(start)
    batch = count_array(ab[:, 0], ab[:, 1], a0, b0, count0=7)
    counter = QuadratureCounter(a0, b0, count=7)
    for i in range(len(walk)):
        counter.update(int(ab[i, 0]), int(ab[i, 1]))
        assert batch.count[i] == counter.count
    assert int(batch.illegal.sum()) == counter.illegal


@settings(max_examples=200, deadline=None)
@given(st.floats(-100.0, 100.0, allow_nan=False))
def test_angle_to_count(theta: float) -> None:
    c = count_from_angle(theta)
    # The count is the floor of theta in count units.
    assert c * 2 * math.pi / COUNTS_PER_REV <= theta + 1e-9
    assert (c + 1) * 2 * math.pi / COUNTS_PER_REV > theta - 1e-9
    assert abi_from_angle(theta)[:2] == ab_from_count(c)


def test_one_revolution_by_angle_counts_2048_and_one_index() -> None:
    counter = QuadratureCounter(*ab_from_count(0))
    index_edges = 0
    last_i = abi_from_count(0)[2]
    n = 20_000
    for k in range(1, n + 1):
        a, b, i = abi_from_angle(2 * math.pi * k / n + 1e-6)
        counter.update(a, b, i)
        index_edges += int(i and not last_i)
        last_i = i
    assert counter.count == COUNTS_PER_REV
    assert index_edges == 1
    assert counter.index_count == COUNTS_PER_REV


def test_bad_levels_raise_codec_errors() -> None:
    counter = QuadratureCounter()
    for a, b in ((2, 0), (0, -1), (None, 0), ("1", 0), (0.5, 1)):
        with pytest.raises(CodecError):
            counter.update(a, b)
    assert counter.count == 0 and counter.illegal == 0
    with pytest.raises(FrameError):
        count_array(np.array([0, 2]), np.array([0, 0]))
    with pytest.raises(FrameError):
        count_array(np.array([0.0]), np.array([0.0]))
    with pytest.raises(RangeError):
        count_from_angle(math.inf)
    assert len(count_array(np.array([], dtype=np.uint8), np.array([], dtype=np.uint8)).count) == 0
