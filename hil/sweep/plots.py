"""Figures of a sweep, one PNG per metric in ``--plot-dir``.

* one grid parameter: the metric against it (every point; the median where seeds or samples
  repeat a grid value), points that miss the requirement in red;
* two grid parameters: a heat map of the metric (median per cell), cells that miss marked;
* Monte Carlo: a histogram (stacked: meeting / missing the requirement) and the metric
  against each tolerance's first key, which shows what the spread comes from;
* three grid parameters or more: the metric against the first one.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from hil.sweep.space import Plan
from hil.sweep.table import metric_column, metric_meta, pass_column


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _colours(df: pd.DataFrame, col: str | None) -> list[str]:
    if col is None:
        return ["tab:blue"] * len(df)
    return ["tab:red" if v is False else "tab:blue" for v in df[col].astype(object)]


def _numeric(series: pd.Series) -> bool:
    return pd.api.types.is_numeric_dtype(series) and not pd.api.types.is_bool_dtype(series)


def _against(ax, df: pd.DataFrame, key: str, ycol: str, pcol: str | None) -> None:
    x = df[key] if _numeric(df[key]) else df[key].astype(str)
    ax.scatter(x, df[ycol], c=_colours(df, pcol), s=14, zorder=3)
    med = df.groupby(key, sort=False)[ycol].median()
    if len(med) < len(df) or len(med) > 1:
        xs = med.index if _numeric(df[key]) else med.index.astype(str)
        ax.plot(xs, med.to_numpy(), "-", color="0.4", lw=1, zorder=2,
                label="median" if len(med) < len(df) else None)
    ax.set_xlabel(key)
    ax.grid(True, alpha=0.3)


def _heat(ax, fig, df: pd.DataFrame, kx: str, ky: str, ycol: str, pcol: str | None) -> None:
    grid = df.pivot_table(index=ky, columns=kx, values=ycol, aggfunc="median", sort=False)
    im = ax.imshow(grid.to_numpy(dtype=float), origin="lower", aspect="auto", cmap="viridis")
    fig.colorbar(im, ax=ax, label=ycol)
    ax.set_xticks(range(grid.shape[1]), [f"{v:.4g}" if isinstance(v, float) else str(v)
                                         for v in grid.columns], rotation=45)
    ax.set_yticks(range(grid.shape[0]), [f"{v:.4g}" if isinstance(v, float) else str(v)
                                         for v in grid.index])
    ax.set_xlabel(kx)
    ax.set_ylabel(ky)
    if pcol is not None:
        miss = df.assign(_miss=df[pcol].astype(object).map(lambda v: v is False))
        cells = miss.pivot_table(index=ky, columns=kx, values="_miss", aggfunc="any",
                                 sort=False).reindex(index=grid.index, columns=grid.columns)
        for (i, j), bad in np.ndenumerate(cells.to_numpy(dtype=bool)):
            if bad:
                ax.text(j, i, "x", ha="center", va="center", color="red", fontsize=12)
    lo, hi = im.get_clim()
    for (i, j), v in np.ndenumerate(grid.to_numpy(dtype=float)):
        light = hi > lo and (v - lo) / (hi - lo) > 0.6  # viridis turns yellow up there
        ax.text(j, i + 0.3, f"{v:.3g}", ha="center", va="center",
                color="k" if light else "w", fontsize=7)


def _monte_carlo(fig, df: pd.DataFrame, plan: Plan, ycol: str, pcol: str | None) -> None:
    keys = [t.keys[0] for t in plan.tolerances]
    axes = fig.subplots(1, 1 + len(keys), squeeze=False)[0]
    values = df[ycol].to_numpy(dtype=float)
    ok = np.isfinite(values)
    if pcol is not None:
        miss = df[pcol].astype(object).map(lambda v: v is False).to_numpy(dtype=bool)
        axes[0].hist([values[ok & ~miss], values[ok & miss]], bins=15, stacked=True,
                     color=["tab:blue", "tab:red"], label=["meets", "misses"])
        axes[0].legend(fontsize=8)
    else:
        axes[0].hist(values[ok], bins=15, color="tab:blue")
    axes[0].set_xlabel(ycol)
    axes[0].set_ylabel("samples")
    axes[0].grid(True, alpha=0.3)
    for ax, key in zip(axes[1:], keys, strict=True):
        ax.scatter(df[key], values, c=_colours(df, pcol), s=12)
        ax.axvline(df[key].median(), color="0.5", ls=":", lw=0.8)
        ax.set_xlabel(key)
        ax.set_ylabel(ycol)
        ax.grid(True, alpha=0.3)


def plot_sweep(df: pd.DataFrame, plan: Plan, records: list[dict], out_dir: str | Path,
               title: str) -> list[Path]:
    """One figure per metric in ``out_dir``; the paths written."""
    from hil.output.plots import _pyplot

    plt = _pyplot()
    out_dir = Path(out_dir)
    paths = []
    for meta in metric_meta(records):
        ycol = metric_column(meta)
        pcol = pass_column(meta) if meta["judged"] else None
        fig = plt.figure(figsize=(7 + 3.5 * (len(plan.tolerances) if not plan.grid else 0),
                                  4.5))
        if plan.grid and len(plan.grid) == 2 and not plan.tolerances:
            ax = fig.subplots()
            _heat(ax, fig, df, plan.grid[0].key, plan.grid[1].key, ycol, pcol)
        elif plan.grid:
            ax = fig.subplots()
            _against(ax, df, plan.grid[0].key, ycol, pcol)
            ax.set_ylabel(ycol)
        elif plan.tolerances:
            _monte_carlo(fig, df, plan, ycol, pcol)
        else:  # seeds only
            ax = fig.subplots()
            _against(ax, df, "sim.seed", ycol, pcol)
            ax.set_ylabel(ycol)
        req = f" (requirement: {meta['requirement']})" if meta["requirement"] else ""
        fig.suptitle(f"{title}\n{meta['name']}{req}", fontsize=9)
        fig.tight_layout()
        path = out_dir / f"{_slug(meta['name'])}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths
