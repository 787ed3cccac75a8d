"""Fewer examples for the property tests (``--examples-fraction``, tests/conftest.py):
``make test-fast`` runs a quarter of each one's examples, ``make test`` all of them."""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterable

from hypothesis import settings
from hypothesis.internal.detection import is_hypothesis_test

#: The fewest examples a property test runs with ``--examples-fraction``.
MIN_EXAMPLES = 10


def fraction(text: str) -> float:
    """The option's value: a number in (0, 1], else argparse's one-line refusal."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a fraction in (0, 1]")
    return value


def fewer_examples(tests: Iterable[object], share: float) -> None:
    """Each property test among ``tests`` (test functions; others are passed over) runs
    ``share`` of its examples, at least MIN_EXAMPLES. A hypothesis profile sets the
    examples only of tests that set none, and most tests here set theirs: the settings the
    test was decorated with are replaced by a copy with fewer examples."""
    for fn in {id(f): f for f in tests if is_hypothesis_test(f)}.values():
        # hypothesis keeps a test's settings here (not a public name: a release that moves
        # them leaves the test with all of its examples, the safe side, not an error)
        own = getattr(fn, "_hypothesis_internal_use_settings", None)
        if not isinstance(own, settings):
            continue
        n = max(MIN_EXAMPLES, math.ceil(own.max_examples * share))
        if n < own.max_examples:
            fn._hypothesis_internal_use_settings = settings(own, max_examples=n)
