"""``--examples-fraction`` (tests/hypothesis_examples.py): a property test runs the share of
its examples it is given, never fewer than the floor, and keeps its other settings."""

from __future__ import annotations

import argparse

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.hypothesis_examples import MIN_EXAMPLES, fewer_examples, fraction


def _property(examples: int) -> tuple[object, list[int]]:
    seen: list[int] = []

    @given(st.integers())
    @settings(max_examples=examples, deadline=None, database=None)
    def prop(x: int) -> None:
        seen.append(x)

    return prop, seen


@pytest.mark.parametrize("examples,share,runs", [(200, 0.25, 50), (25, 0.25, MIN_EXAMPLES),
                                                 (5, 0.25, 5), (40, 1.0, 40)])
def test_a_property_runs_its_share_of_examples(examples, share, runs):
    prop, seen = _property(examples)
    fewer_examples([prop, prop, len], share)  # a test listed twice, and not a property
    prop()
    assert len(seen) == runs
    assert prop._hypothesis_internal_use_settings.deadline is None


@pytest.mark.parametrize("text", ["0", "1.5", "-0.1", "nan", "a quarter"])
def test_a_value_outside_0_1_is_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="not a fraction"):
        fraction(text)
