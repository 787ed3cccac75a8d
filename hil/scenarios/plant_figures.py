"""The main job's figures as scenarios: thesis F1 (open-loop response of the plant, piston
fixed) and F2 (T-N curve at 18 A), on the plant alone. ``eha-hil main`` runs these two and
prints them beside the plant summary; ``eha-hil run f1`` / ``run f2`` run one of them.

F2's figures are held to bands around the thesis's values (:data:`F2_BANDS`); F1 is
reported against the thesis's model and measured peaks without a requirement.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.scenarios import Metric, Progress, ScenarioResult, register
from plant.config import Config, linearised

#: The thesis's figures F1 and F2 (Hz; N, mm/s, efficiency as a fraction).
THESIS_F1 = {"model_peak_hz": 60.0, "measured_peak_hz": 25.0}
THESIS_F2 = {"stall_force_n": 1700.0, "no_load_velocity_mm_s": 150.0, "peak_efficiency": 0.40}
#: Acceptance bands around the thesis's F2 figures.
F2_BANDS = {
    "stall_force_n": (1600.0, 1800.0),
    "no_load_velocity_mm_s": (135.0, 165.0),
    "peak_efficiency": (0.35, 0.45),
}
#: F1's frequency grid: 1 Hz over the resonance region plus a log grid for the error figure.
F1_FREQS = np.unique(np.concatenate([np.arange(10.0, 121.0), np.geomspace(1, 300, 25).round()]))
#: F2's current and number of operating points.
F2_CURRENT_A = 18.0
F2_POINTS = 17


def within_band(key: str, value: float) -> bool:
    lo, hi = F2_BANDS[key]
    return lo <= value <= hi


@register("f1")
def f1(cfg: Config, progress: Progress = None) -> ScenarioResult:
    from hil.analysis.bode import simulate_bode

    sim = simulate_bode(cfg, "fixed", F1_FREQS)
    if progress:
        progress(1, 2)
    lin = simulate_bode(linearised(cfg), "fixed", F1_FREQS)
    if progress:
        progress(2, 2)
    ge = float(np.abs(sim.gain_error_db()).max())
    pe = float(np.abs(sim.phase_error_deg()).max())
    metrics = [
        Metric("simulated peak", sim.peak_hz(), "Hz", thesis=THESIS_F1["model_peak_hz"]),
        Metric("model peak", sim.peak_hz("analytic"), "Hz", thesis=THESIS_F1["model_peak_hz"]),
        Metric("max gain error", ge, "dB"),
        Metric("max phase error", pe, "deg"),
        Metric("linear simulated peak", lin.peak_hz(), "Hz"),
        Metric("linear max gain error", float(np.abs(lin.gain_error_db()).max()), "dB"),
        Metric("linear max phase error", float(np.abs(lin.phase_error_deg()).max()), "deg"),
        Metric("DC gain simulated", float(abs(sim.simulated[0])), ""),
    ]
    return ScenarioResult("f1", "open loop, piston fixed, tau_p -> tau_q", metrics,
                          series={"bode": sim, "bode_linear": lin}, plot=_plot_f1)


def _plot_f1(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import plot_bode

    plot_bode([res.series["bode"]], path, thesis_hz=[
        (THESIS_F1["model_peak_hz"], f"model peak {THESIS_F1['model_peak_hz']:g} Hz"),
        (THESIS_F1["measured_peak_hz"], f"measured {THESIS_F1['measured_peak_hz']:g} Hz")])


@register("f2")
def f2(cfg: Config, progress: Progress = None) -> ScenarioResult:
    from hil.analysis.tn_curve import simulate_tn_curve

    curve = simulate_tn_curve(cfg, F2_CURRENT_A, F2_POINTS, progress=progress)
    figures = {
        "stall_force_n": curve.stall_force_n,
        "no_load_velocity_mm_s": curve.no_load_velocity_m_s * 1e3,
        "peak_efficiency": curve.peak().efficiency,
    }
    names = {"stall_force_n": ("stall force", "N"),
             "no_load_velocity_mm_s": ("no-load velocity", "mm/s"),
             "peak_efficiency": ("peak efficiency", "")}
    metrics = [Metric(names[k][0], v, names[k][1],
                      f"{F2_BANDS[k][0]:g}..{F2_BANDS[k][1]:g}", within_band(k, v),
                      thesis=THESIS_F2[k]) for k, v in figures.items()]
    return ScenarioResult("f2", f"T-N curve at {F2_CURRENT_A:g} A", metrics,
                          series={"curve": curve, "figures": figures}, plot=_plot_f2)


def _plot_f2(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import plot_tn_curve

    plot_tn_curve(res.series["curve"], path, thesis=THESIS_F2)


__all__ = ["F1_FREQS", "F2_BANDS", "THESIS_F1", "THESIS_F2", "f1", "f2", "within_band"]
