"""Benchmark cases for the protocol codecs, gathered for ``eha-hil bench codecs``.

Each module in :data:`MODULES` exposes ``CASES: list[CodecCase]``. A case's ``run(n)``
does ``n`` encode+decode round trips (kind ``"frame"``) or decodes a prepared stream of
``n`` frames with the vectorised numpy path (kind ``"batch"``), and returns the number of
frames it processed. The runner in :mod:`hil.bench.engines` times it; cases never time themselves.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

#: Modules of this package that contribute cases, in the order they are printed.
MODULES: tuple[str, ...] = ("links", "buses")


@dataclass(frozen=True)
class CodecCase:
    """One codec benchmark: a name, its kind, a runner and the issue's target rate."""

    name: str
    kind: str  # "frame" or "batch"
    run: Callable[[int], int]
    target_fps: float


def all_cases() -> list[CodecCase]:
    """Return every registered case, module by module."""
    cases: list[CodecCase] = []
    for mod in MODULES:
        module = importlib.import_module(f"{__name__}.{mod}")
        cases.extend(module.CASES)
    return cases
