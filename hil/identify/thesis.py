"""The thesis's own residual (2.4.3): does pump Coulomb friction move the 60 Hz resonance?

The thesis fixes the piston, drives the pump with constant-frequency sine zones of pump
torque, reads gain and phase of ``tau_q / tau_p`` zone by zone, and finds the measured
resonance near 25 Hz where its linear model ``d_s k_s / G_1`` (Eq. 2.32, 2.36) resonates near
60 Hz; it presumes the pump friction's nonlinearity. This module runs that experiment on the
project's plant twice (pump Coulomb friction off and on, everything else as the preset),
reads the zone gains from the pressure sensors, and feeds the friction run to the
identification tool, so the question is answered by simulation, not by assertion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.analysis.bode import LinearParams, analytic_fixed
from hil.identify.csvdata import MeasuredData
from hil.identify.pipeline import IdentifyReport, identify
from plant import layout as L
from plant.config import Config, load_config
from plant.model import Plant, motor_torque_constant

ZONE_FREQS_HZ = (5, 10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 60, 65, 70, 80, 100)


@dataclass
class SweepResult:
    """Zone-by-zone gains of one stepped-sine run and the record it logged."""

    freq_hz: np.ndarray
    gain: np.ndarray  # complex tau_q / tau_p from the pressure sensors
    data: MeasuredData

    @property
    def peak_hz(self) -> float:
        return float(self.freq_hz[int(np.argmax(np.abs(self.gain)))])


@dataclass
class ThesisResidual:
    """The finding: resonance with and without pump Coulomb friction, and the tool's verdict."""

    amplitude_n: float
    coulomb_n: float
    linear: SweepResult
    coulomb: SweepResult
    analytic: np.ndarray
    report: IdentifyReport

    @property
    def analytic_peak_hz(self) -> float:
        f = self.linear.freq_hz
        return float(f[int(np.argmax(np.abs(self.analytic)))])


def stepped_sine(cfg: Config, freqs: tuple[float, ...] = ZONE_FREQS_HZ,
                 amplitude_n: float = 300.0, zone_s: float = 0.5, settle_s: float = 0.2,
                 sample_rate_hz: float = 5000.0) -> SweepResult:
    """Thesis 2.4.3 with the piston fixed: one sine zone of pump force per frequency.

    The plant takes the current ``iq = tau_p / K`` (ideal current source). Each zone's gain
    is the least-squares sine/cosine fit at its frequency of ``k_c (p_pump_a - p_pump_b)``
    over the zone after ``settle_s``, divided by that of ``tau_p``.
    """
    cfg = cfg.with_overrides({"load.kind": "fixed"}, source="thesis 2.4.3")
    plant = Plant(cfg)
    kc = cfg.get("hydraulics.kc_m2")
    gain_n_per_a = motor_torque_constant(cfg) * kc / cfg.get("hydraulics.kp_m3_per_rad")
    every = int(round(1.0 / (sample_rate_hz * plant.tick_s)))
    fs = 1.0 / (every * plant.tick_s)
    n_zone = int(round(zone_s * fs))
    n = n_zone * len(freqs)
    iq = np.zeros(n)
    rec = np.zeros((n, L.N_OUTPUTS))
    rec[0] = plant.y
    t = np.arange(n) / fs
    for z, f in enumerate(freqs):
        k0 = z * n_zone
        tz = t[k0: k0 + n_zone] - t[k0]
        iq[k0: k0 + n_zone] = amplitude_n / gain_n_per_a * np.sin(2 * np.pi * f * tz)
    for k in range(n - 1):
        plant.set_current(iq[k])
        plant.advance(every)
        rec[k + 1] = plant.y
    tau_q = kc * (rec[:, L.Y_P_PUMP_A] - rec[:, L.Y_P_PUMP_B])
    gains = np.zeros(len(freqs), dtype=complex)
    n_settle = int(round(settle_s * fs))
    for z, f in enumerate(freqs):
        sl = slice(z * n_zone + n_settle, (z + 1) * n_zone)
        basis = np.exp(2j * np.pi * f * t[sl])
        u = np.vdot(basis, iq[sl] * gain_n_per_a)
        # the input is held over a sample (ZOH): its sample sl is applied from t to t + 1/fs
        y = np.vdot(basis, tau_q[sl])
        zoh = (1 - np.exp(-2j * np.pi * f / fs)) / (2j * np.pi * f / fs)
        gains[z] = y / (u * zoh)
    cols = {"iq": iq, "theta_m": rec[:, L.Y_THETA_M].copy()}
    for name, idx in (("p_pump_a", L.Y_P_PUMP_A), ("p_pump_b", L.Y_P_PUMP_B),
                      ("p_cyl_a", L.Y_P_CYL_A), ("p_cyl_b", L.Y_P_CYL_B),
                      ("p_acc", L.Y_P_ACC), ("x_piston", L.Y_X_PISTON),
                      ("f_strain", L.Y_F_STRAIN), ("temp_c", L.Y_TEMP)):
        cols[name] = rec[:, idx].copy()
    data = MeasuredData("<thesis 2.4.3 stepped sine>", "fixed_piston", fs, t, cols,
                        {"source": "thesis 2.4.3 on the plant"})
    return SweepResult(np.asarray(freqs, dtype=float), gains, data)


def thesis_residual(preset: str = "hydra_linear", coulomb_n: float = 80.0,
                    amplitude_n: float = 300.0, freqs: tuple[float, ...] = ZONE_FREQS_HZ,
                    max_effects: int = 6) -> ThesisResidual:
    """Run the stepped sine with pump Coulomb friction off and on, and identify the latter
    (adding at most ``max_effects`` effects).

    Sensor noise and quantisation are on in both runs (the thesis measured with sensors).
    """
    base = load_config(preset).with_overrides(
        {"effects.sensor_noise.enabled": True, "effects.quantisation.enabled": True},
        source="thesis residual")
    lin = stepped_sine(base, freqs, amplitude_n)
    fric_cfg = base.with_overrides({"effects.pump_coulomb.enabled": True,
                                    "effects.pump_coulomb.force_n": coulomb_n},
                                   source="pump Coulomb on")
    fric = stepped_sine(fric_cfg, freqs, amplitude_n)
    analytic = analytic_fixed(np.asarray(freqs, float), LinearParams.from_config(base))
    rep = identify(fric.data, load_config("hydra_default"), max_effects=max_effects)
    return ThesisResidual(amplitude_n, coulomb_n, lin, fric, analytic, rep)


__all__ = ["SweepResult", "ThesisResidual", "ZONE_FREQS_HZ", "stepped_sine", "thesis_residual"]
