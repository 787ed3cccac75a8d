"""Word-for-word comparison of two record arrays (the model's and a build's)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass(frozen=True)
class Mismatch:
    """The first differing word: the vector's index in its set, the field, both values."""

    step: int
    field: str
    model: str
    build: str


@dataclass
class Comparison:
    """One set of vectors compared: how many, how many differed in any field, the first."""

    source: str
    vectors: int
    mismatches: int
    first: Mismatch | None = None
    fields: dict[str, int] = field(default_factory=dict)  # field -> vectors differing there

    def as_dict(self) -> dict:
        return asdict(self)


class ComparedSets:
    """Totals over a run's compared sets (``self.sets``), for the result classes of both
    checks."""

    sets: list[Comparison]

    @property
    def vectors(self) -> int:
        return sum(c.vectors for c in self.sets)

    @property
    def mismatches(self) -> int:
        return sum(c.mismatches for c in self.sets)

    @property
    def first(self) -> Comparison | None:
        """The first set with a mismatch."""
        return next((c for c in self.sets if c.first is not None), None)


def _show(value: np.generic) -> str:
    if isinstance(value, np.floating):
        bits = value.view(np.uint32 if value.dtype.itemsize == 4 else np.uint64)
        return f"{float(value)!r} (0x{int(bits):08x})"
    return f"{int(value)} (0x{int(value):x})"


def compare(source: str, model: np.ndarray, build: np.ndarray,
            names: Mapping[str, Sequence[str]] | None = None) -> Comparison:
    """Compare ``model`` and ``build`` (same structured dtype) field by field, bits not
    values (-0.0 differs from 0.0, NaN equals the same NaN); ``names`` gives array fields'
    elements names (else ``field[k]``)."""
    if model.dtype != build.dtype or model.shape != build.shape:
        raise ValueError(f"{source}: model {model.dtype}{model.shape} and build "
                         f"{build.dtype}{build.shape} differ in layout")
    names = names or {}
    bad_rows = np.zeros(len(model), dtype=bool)
    first: tuple[int, int, str, np.generic, np.generic] | None = None
    fields: dict[str, int] = {}
    for order, name in enumerate(model.dtype.names):
        a, b = model[name], build[name]
        diff = a.view(f"u{a.dtype.itemsize}") != b.view(f"u{b.dtype.itemsize}")
        if diff.ndim == 1:
            diff = diff[:, None]
            a, b = a[:, None], b[:, None]
        for k in range(diff.shape[1]):
            rows = np.flatnonzero(diff[:, k])
            if not len(rows):
                continue
            label = name if model[name].ndim == 1 else (
                f"{name}.{names[name][k]}" if name in names and k < len(names[name])
                else f"{name}[{k}]")
            fields[label] = len(rows)
            bad_rows[rows] = True
            key = (int(rows[0]), order * 1000 + k)
            if first is None or key < first[:2]:
                first = (*key, label, a[rows[0], k], b[rows[0], k])
    mism = None
    if first is not None:
        mism = Mismatch(first[0], first[2], _show(first[3]), _show(first[4]))
    return Comparison(source, len(model), int(bad_rows.sum()), mism, fields)
