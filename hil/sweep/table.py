"""The results table: one row per point (pandas), written as Parquet or CSV.

Columns, in order: ``point``; ``sample`` (Monte Carlo sample number, when there are
tolerances); one column per varied configuration key (its value at the point); one per
metric, ``NAME [UNIT]``; one per judged metric, ``NAME: pass`` (True/False, empty where the
point failed); ``pass`` (every judged metric passed); ``error`` (empty, or why the point
failed). Timings are left out: the same sweep gives the same table on any backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from hil.sweep.space import Plan

SUFFIXES = (".parquet", ".csv")


def metric_column(meta: dict[str, Any]) -> str:
    return f"{meta['name']} [{meta['unit']}]" if meta["unit"] else meta["name"]


def pass_column(meta: dict[str, Any]) -> str:
    return f"{meta['name']}: pass"


def metric_meta(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Name, unit, requirement and whether it is judged, of every metric, in the scenario's
    order (from all records: a failed point has none)."""
    out: dict[str, dict[str, Any]] = {}
    for rec in records:
        for m in rec["metrics"]:
            meta = out.setdefault(m["name"], {"name": m["name"], "unit": m["unit"],
                                              "requirement": m["requirement"],
                                              "judged": False})
            meta["judged"] |= m["ok"] is not None
    return list(out.values())


def frame(plan: Plan, records: list[dict[str, Any]]) -> pd.DataFrame:
    """The table of ``records`` (sorted by point) for ``plan``."""
    metas = metric_meta(records)
    cols: dict[str, list[Any]] = {"point": [r["point"] for r in records]}
    if plan.tolerances:
        cols["sample"] = [r["sample"] for r in records]
    for key in plan.parameters:
        cols[key] = [r["params"].get(key) for r in records]
    by_name = [{m["name"]: m for m in r["metrics"]} for r in records]
    for meta in metas:
        cols[metric_column(meta)] = [
            float(ms[meta["name"]]["value"]) if meta["name"] in ms else float("nan")
            for ms in by_name]
    for meta in metas:
        if meta["judged"]:
            cols[pass_column(meta)] = pd.array(
                [ms[meta["name"]]["ok"] if meta["name"] in ms else None for ms in by_name],
                dtype="boolean")
    cols["pass"] = pd.array([r["ok"] for r in records], dtype="boolean")
    cols["error"] = [r["error"] for r in records]
    return pd.DataFrame(cols)


def write(df: pd.DataFrame, path: str | Path) -> None:
    """``.parquet`` (pyarrow) or ``.csv`` (the command writes it through
    :func:`hil.cli.outputs.write`: a temporary name, renamed when complete)."""
    path = Path(path)
    if path.suffix.lower() == ".parquet":
        df.to_parquet(path, index=False)
    else:
        df.to_csv(path, index=False)


def read(path: str | Path) -> pd.DataFrame:
    """A table written by :func:`write` (for tests and notebooks)."""
    path = Path(path)
    if path.suffix.lower() == ".parquet":
        return pd.read_parquet(path)
    df = pd.read_csv(path)
    # An empty cell is a missing value, except in "error", where it means "no error".
    df["error"] = ["" if pd.isna(v) else str(v) for v in df["error"]]
    return df
