"""The plots mark the thesis's figures (legend entries "thesis: ..." at its values)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hil.scenarios import Metric, ScenarioResult


@pytest.fixture()
def saved(monkeypatch):  # noqa: ANN001, ANN201
    """The figures the plot functions save, instead of files."""
    from matplotlib.figure import Figure

    figs = []
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: figs.append(self))
    return figs


def _thesis_lines(fig) -> dict[str, list]:  # noqa: ANN001
    out = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            if line.get_label().startswith("thesis: "):
                out[line.get_label()] = list(line.get_xdata()) + list(line.get_ydata())
    return out


def test_bandwidth_plots_mark_the_thesis_bandwidths(saved, tmp_path: Path) -> None:
    from hil.scenarios.thesis import _plot_bodes

    f = np.geomspace(3, 150, 5)
    res = ScenarioResult("f6", "t", [Metric("-3 dB bandwidth, weak beam", 20.0, "Hz",
                                            thesis=22.0),
                                     Metric("-3 dB bandwidth, reinforced", 50.0, "Hz",
                                            thesis=53.0),
                                     Metric("peak gain", 1.0, "dB")],
                         {"bodes": [("weak beam", f, np.ones(5) + 0j)]})
    _plot_bodes(res, tmp_path / "x.png")
    lines = _thesis_lines(saved[0])
    assert set(lines) == {"thesis: -3 dB bandwidth, weak beam 22 Hz",
                          "thesis: -3 dB bandwidth, reinforced 53 Hz"}
    assert lines["thesis: -3 dB bandwidth, weak beam 22 Hz"][:2] == [22.0, 22.0]


def test_tn_curve_marks_stall_no_load_and_efficiency(saved, tmp_path: Path) -> None:
    from hil.analysis.tn_curve import TNCurve, TNPoint
    from hil.output.plots import plot_tn_curve
    from hil.scenarios.plant_figures import THESIS_F2

    zero = {f.name: 0.0 for f in dataclasses.fields(TNPoint)}
    curve = TNCurve(18.0, [TNPoint(**{**zero, "force_n": 1750.0}),
                           TNPoint(**{**zero, "velocity_m_s": 0.14})])
    plot_tn_curve(curve, tmp_path / "x.png", thesis=THESIS_F2)
    lines = _thesis_lines(saved[0])
    assert lines["thesis: stall 1700 N"] == [0.0, 1700.0]
    assert lines["thesis: no load 150 mm/s"] == [150.0, 0.0]
    assert lines["thesis: peak 40 %"][2:] == [40.0, 40.0]


def _level_lines(fig, db: float) -> list:  # noqa: ANN001
    """Horizontal lines across the gain axis at ``db``."""
    gain = fig.axes[0]
    return [ln for ln in gain.get_lines()
            if len(set(ln.get_ydata())) == 1 and ln.get_ydata()[0] == db]


def test_the_f1_resonance_plot_draws_no_bandwidth_line(saved, tmp_path: Path) -> None:
    """F1 as measured is a resonance figure: its plot marks the thesis's peaks, and has no
    -3 dB line (a bandwidth plot, F5/F6, keeps it)."""
    from hil.scenarios.f1_measured import _plot
    from hil.scenarios.thesis import _plot_bodes

    f = np.arange(4.0, 72.0, 2.0)
    res = ScenarioResult("f1-measured", "t",
                         [Metric("peak, rod end fixed, reinforced beam", 21.7, "Hz",
                                 thesis=25.0)],
                         {"bodes": [("rod end, reinforced", f, np.ones(len(f)) + 0j)]})
    _plot(res, tmp_path / "f1.png")
    _plot_bodes(dataclasses.replace(res, name="f6"), tmp_path / "f6.png")
    resonance, bandwidth = saved
    assert set(_thesis_lines(resonance)) == {"thesis: peak, rod end fixed, reinforced beam "
                                             "25 Hz"}
    assert _level_lines(resonance, -3.0) == []
    assert len(_level_lines(bandwidth, -3.0)) == 1
