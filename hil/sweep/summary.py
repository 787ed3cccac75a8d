"""The sweep's summary: per metric min / median / max, and the yield against its requirement.

Yield is the share of points that meet the requirement, out of every point of the sweep: a
point that failed with an error is not known to meet it and counts against. Beside it the
95 % Clopper-Pearson interval, which says how far a Monte Carlo yield of a few dozen
samples can be trusted (50 of 50 passing still only shows >= 93 %).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from hil.sweep.table import metric_column, metric_meta, pass_column


@dataclass
class MetricSummary:
    name: str
    unit: str
    requirement: str
    n: int                       # points with a finite value
    min: float
    median: float
    max: float
    passed: int | None = None    # judged metrics only
    yield_: float | None = None
    yield_low: float | None = None
    yield_high: float | None = None

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["yield"] = d.pop("yield_")
        return d


@dataclass
class CellYield:
    """The yield at one grid point over its seeds and samples (a grid with repeats)."""

    values: dict[str, Any]       # the grid keys' values
    points: int
    passed: int
    yield_: float
    yield_low: float
    yield_high: float
    spread: dict[str, tuple[float, float, float]]  # judged metric -> min, median, max

    def as_dict(self) -> dict[str, Any]:
        return {"values": self.values, "points": self.points, "passed": self.passed,
                "yield": self.yield_, "yield_low": self.yield_low,
                "yield_high": self.yield_high,
                "spread": {k: dict(zip(("min", "median", "max"), v, strict=True))
                           for k, v in self.spread.items()}}


@dataclass
class Summary:
    points: int
    errors: int
    metrics: list[MetricSummary]
    passed: int | None           # points meeting every judged requirement
    yield_: float | None
    yield_low: float | None
    yield_high: float | None
    cells: list[CellYield] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"points": self.points, "errors": self.errors, "passed": self.passed,
                "yield": self.yield_, "yield_low": self.yield_low,
                "yield_high": self.yield_high,
                "metrics": [m.as_dict() for m in self.metrics],
                "grid_points": [c.as_dict() for c in self.cells]}


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact two-sided confidence interval of a proportion k/n."""
    from scipy.stats import beta

    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def summarise(df: pd.DataFrame, records: list[dict[str, Any]], grid_keys: list[str] = ()
              ) -> Summary:
    """The summary of a results table (``records``: for the metrics' units and requirements).
    With ``grid_keys`` (a grid whose points repeat over seeds or samples) also the yield at
    each grid point: which settings hold across the actuators built to tolerance."""
    grid_keys = list(grid_keys)
    n = len(df)
    out = []
    for meta in metric_meta(records):
        values = df[metric_column(meta)].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        stats = ((float(finite.min()), float(np.median(finite)), float(finite.max()))
                 if len(finite) else (math.nan,) * 3)
        ms = MetricSummary(meta["name"], meta["unit"], meta["requirement"], len(finite),
                           *stats)
        if meta["judged"]:
            ms.passed = int(df[pass_column(meta)].fillna(False).sum())
            ms.yield_ = ms.passed / n
            ms.yield_low, ms.yield_high = clopper_pearson(ms.passed, n)
        out.append(ms)
    judged = any(m.passed is not None for m in out)
    passed = int(df["pass"].fillna(False).sum()) if judged else None
    y = (passed / n, *clopper_pearson(passed, n)) if judged and n else (None, None, None)
    summ = Summary(n, int((df["error"] != "").sum()), out, passed, *y)
    if judged and grid_keys and n > df.groupby(grid_keys, sort=False).ngroups:
        summ.cells = _cells(df, records, grid_keys)
    return summ


def _spread(values: pd.Series) -> tuple[float, float, float]:
    v = values.to_numpy(dtype=float)
    v = v[np.isfinite(v)]
    return (float(v.min()), float(np.median(v)), float(v.max())) if len(v) else (math.nan,) * 3


def _cells(df: pd.DataFrame, records: list[dict[str, Any]], keys: list[str]
           ) -> list[CellYield]:
    judged = [m for m in metric_meta(records) if m["judged"]]
    cells = []
    for values, cell in df.groupby(keys, sort=False):
        values = values if isinstance(values, tuple) else (values,)
        k, m = int(cell["pass"].fillna(False).sum()), len(cell)
        cells.append(CellYield(
            {key: (v.item() if hasattr(v, "item") else v) for key, v in zip(keys, values,
                                                                              strict=True)},
            m, k, k / m, *clopper_pearson(k, m),
            {j["name"]: _spread(cell[metric_column(j)]) for j in judged}))
    return cells


def text(summary: Summary, title: str) -> str:
    """The summary as a terminal table."""
    from hil.output.tables import table

    def pct(x: float | None) -> str:
        return "" if x is None else f"{100 * x:.1f} %"

    rows = []
    for m in summary.metrics:
        ci = ("" if m.yield_ is None else f"{pct(m.yield_low)}..{pct(m.yield_high)}")
        rows.append((m.name, m.unit, m.min, m.median, m.max, m.requirement, pct(m.yield_), ci))
    body = table(["metric", "unit", "min", "median", "max", "requirement", "yield",
                  "95 % interval"], rows, fmt=".4g", title=title)
    tail = f"{summary.points} points, {summary.errors} failed with an error"
    if summary.yield_ is not None:
        tail += (f"; every requirement met at {summary.passed} of {summary.points} points "
                 f"(yield {pct(summary.yield_)}, 95 % interval {pct(summary.yield_low)}.."
                 f"{pct(summary.yield_high)})")
    out = body + "\n" + tail
    if summary.cells:
        keys = list(summary.cells[0].values)
        names = list(summary.cells[0].spread)
        rows = [(*(str(v) for v in c.values.values()), c.points, c.passed, pct(c.yield_),
                 f"{pct(c.yield_low)}..{pct(c.yield_high)}",
                 *(x for lo, med, _ in c.spread.values() for x in (lo, med)))
                for c in summary.cells]
        heads = [h for n in names for h in (f"min {n}", f"median {n}")]
        out += "\n\n" + table([*keys, "points", "met", "yield", "95 % interval", *heads],
                               rows, fmt=".4g", title="every requirement, per grid point")
    return out
