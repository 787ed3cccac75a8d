"""Figures for people (matplotlib, no display needed): Bode plots and the T-N curve."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.analysis.bode import BodeResult
from hil.analysis.tn_curve import TNCurve


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: How the thesis's figures are drawn on our plots: grey dashes, labelled "thesis: ...".
THESIS_STYLE = {"color": "0.35", "ls": "--", "lw": 1.0}


def mark_thesis(ax, *, x: float | None = None, y: float | None = None,  # noqa: ANN001
                label: str = "") -> None:
    """A thesis figure on ``ax``: a vertical line at ``x``, a horizontal one at ``y``, or a
    cross at (x, y) when both are given; labelled ``thesis: <label>`` in the legend."""
    text = f"thesis: {label}" if label else None
    if x is not None and y is not None:
        ax.plot([x], [y], "x", color="k", ms=10, mew=2, label=text)
    elif x is not None:
        ax.axvline(x, label=text, **THESIS_STYLE)
    elif y is not None:
        ax.axhline(y, label=text, **THESIS_STYLE)


def plot_bode(results: list[BodeResult], path: str | Path,
              thesis_hz: list[tuple[float, str]] = ()) -> None:
    """Gain and phase of each result: simulated markers over the analytic curve;
    ``thesis_hz``: the thesis's frequencies, (Hz, label), marked on every panel."""
    plt = _pyplot()
    titles = {
        "fixed": "piston fixed: tau_p -> tau_q  (d_s k_s / G1)",
        "free": "piston free: tau_p -> v_c  (d_s k_s / G3)",
    }
    fig, axes = plt.subplots(2, len(results), figsize=(6 * len(results), 6), squeeze=False)
    for j, r in enumerate(results):
        f_dense = np.geomspace(r.freq_hz.min(), r.freq_hz.max(), 400)
        model = r.analytic_at(f_dense)
        ax_g, ax_p = axes[0][j], axes[1][j]
        ax_g.semilogx(f_dense, BodeResult.db(model), "r-", label="model (analytic)")
        ax_g.semilogx(r.freq_hz, BodeResult.db(r.simulated), "bo", ms=4, label="simulated")
        ax_p.semilogx(f_dense, np.degrees(np.unwrap(np.angle(model))), "r-")
        ax_p.semilogx(r.freq_hz, np.degrees(np.unwrap(np.angle(r.simulated))), "bo", ms=4)
        ax_g.set_title(titles[r.load], fontsize=10)
        ax_g.set_ylabel("gain [dB]")
        ax_p.set_ylabel("phase [deg]")
        ax_p.set_xlabel("frequency [Hz]")
        for ax in (ax_g, ax_p):
            ax.grid(True, which="both", alpha=0.3)
            for hz, what in thesis_hz:
                mark_thesis(ax, x=hz, label=what if ax is ax_g else "")
        ax_g.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_tn_curve(curve: TNCurve, path: str | Path,
                  thesis: dict[str, float] | None = None) -> None:
    """The six panels of thesis Fig. 2.4 from a simulated sweep; ``thesis`` (keys
    ``stall_force_n``, ``no_load_velocity_mm_s``, ``peak_efficiency``) marks its figures."""
    plt = _pyplot()
    pts = curve.points
    v = np.array([p.velocity_m_s for p in pts]) * 1e3
    f = np.array([p.force_n for p in pts])
    panels = [
        ("T-N curve", v, f, "piston velocity [mm/s]", "piston force [N]"),
        ("input power", f, [p.power_in_w for p in pts], "piston force [N]", "P_in [W]"),
        ("output power", f, [p.power_out_w for p in pts], "piston force [N]", "P_out [W]"),
        ("volumetric efficiency", f, [100 * p.efficiency_volumetric for p in pts],
         "piston force [N]", "[%]"),
        ("torque efficiency", f, [100 * p.efficiency_torque for p in pts],
         "piston force [N]", "[%]"),
        ("total efficiency", f, [100 * p.efficiency for p in pts], "piston force [N]", "[%]"),
    ]
    fig, axes = plt.subplots(3, 2, figsize=(9, 9))
    for ax, (title, x, y, xl, yl) in zip(axes.flat, panels, strict=True):
        ax.plot(x, y, "o-", ms=3, label="simulated")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(True, alpha=0.3)
    if thesis:
        tn, eff = axes.flat[0], axes.flat[5]
        mark_thesis(tn, x=0.0, y=thesis["stall_force_n"],
                    label=f"stall {thesis['stall_force_n']:g} N")
        mark_thesis(tn, x=thesis["no_load_velocity_mm_s"], y=0.0,
                    label=f"no load {thesis['no_load_velocity_mm_s']:g} mm/s")
        mark_thesis(eff, y=100 * thesis["peak_efficiency"],
                    label=f"peak {100 * thesis['peak_efficiency']:g} %")
        tn.legend(fontsize=8)
        eff.legend(fontsize=8)
    fig.suptitle(f"Simulated T-N curve at i_q = {curve.iq_a:g} A")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
