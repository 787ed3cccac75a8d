"""How the plant-based generator (:mod:`hil.identify.synth`) puts each effect into a record,
one class per effect: its default magnitudes, the plant configuration that switches it on
(the effects the plant has), and its truth in the identification library's terms.

The effects applied around the plant (the input delay, the second pulsation order, the
sensor-side effects) act in :func:`hil.identify.synth.generate`'s loop and sensor stage,
where they sit between ticks and samples; here they give their defaults and truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from plant import layout as L
from plant.config import Config


class SynthEffect:
    """One effect as the plant-based generator makes it. ``kind``: ``"plant"`` (switched
    on in the plant's configuration), ``"wrapper"`` (applied around the plant) or
    ``"outside"`` (outside the library). The defaults: no configuration, the magnitudes as
    the truth."""

    name: str = ""
    kind: str = "plant"
    defaults: dict[str, float] = {}

    def plant_overrides(self, mag: Mapping[str, float]) -> dict[str, Any]:
        """Configuration keys of the plant that switch the effect on."""
        return {}

    def truth(self, mag: Mapping[str, float], cfg: Config, rec: np.ndarray,
              fs: float) -> dict[str, float]:
        """The effect's parameters in the identification library's terms, from the
        magnitudes, the plant's configuration and the recorded outputs ``rec``."""
        return {k: float(v) for k, v in mag.items()}


class PumpPulsation(SynthEffect):
    """The plant's one pulsation order (``order`` of the 4-tooth trochoid)."""

    name = "pump_pulsation"
    defaults = {"order": 4, "amplitude": 0.02, "torque_n": 150.0}

    def plant_overrides(self, mag):
        return {"effects.pulsation.enabled": True,
                "effects.pulsation.order": int(mag["order"]),
                "effects.pulsation.amplitude": float(mag["amplitude"]),
                "effects.pulsation.torque_n": float(mag["torque_n"]),
                # The identifier models a load-independent torque ripple only.
                "effects.pulsation.torque_amplitude": 0.0,
                "effects.pulsation.phase_rad": float(mag.get("phase_rad", 0.0))}


class PumpCoulombFriction(SynthEffect):
    name = "pump_coulomb_friction"
    defaults = {"force_n": 80.0}

    def plant_overrides(self, mag):
        return {"effects.pump_coulomb.enabled": True,
                "effects.pump_coulomb.force_n": float(mag["force_n"])}


class SealFriction(SynthEffect):
    name = "seal_friction"
    defaults = {"coulomb_n": 20.0, "static_n": 35.0}

    def plant_overrides(self, mag):
        return {"effects.seal_friction.enabled": True,
                "effects.seal_friction.coulomb_n": float(mag["coulomb_n"]),
                "effects.seal_friction.static_n": float(mag["static_n"])}


class StiffnessVsPosition(SynthEffect):
    name = "stiffness_vs_position"
    defaults: dict[str, float] = {}

    def plant_overrides(self, mag):
        return {"effects.ks_position.enabled": True}

    def truth(self, mag, cfg, rec, fs):
        x = rec[:, L.Y_X_PISTON]
        return {"ks_relative_span": ks_span(cfg, float(x.min()), float(x.max())),
                "side_volume_m3": cfg.get("hydraulics.dead_volume_m3")
                + cfg.get("hydraulics.pipe_volume_m3")}


class ViscosityTemperature(SynthEffect):
    name = "viscosity_temperature"
    defaults = {"coeff_per_c": 0.03, "initial_c": 15.0, "ambient_c": 25.0}

    def plant_overrides(self, mag):
        return {"effects.oil_temperature.enabled": True,
                "effects.oil_temperature.viscosity_coeff_per_c": float(mag["coeff_per_c"]),
                "effects.oil_temperature.initial_c": float(mag["initial_c"]),
                "effects.oil_temperature.ambient_c": float(mag["ambient_c"])}

    def truth(self, mag, cfg, rec, fs):
        return {"coeff_per_c": mag["coeff_per_c"]}


class StrainThermalDrift(SynthEffect):
    """Strain drift with the rod temperature, which follows an ambient step."""

    name = "strain_thermal_drift"
    defaults = {"n_per_c": 2.5, "ambient_c": 35.0}

    def plant_overrides(self, mag):
        return {"effects.strain_drift.enabled": True,
                "effects.strain_drift.n_per_c": float(mag["n_per_c"])}

    def truth(self, mag, cfg, rec, fs):
        from plant.model import build_params

        p = build_params(cfg)
        tau = p[L.P_ROD_TAU]
        t_end = (rec.shape[0] - 1) / fs
        t_amb0 = cfg.get("effects.oil_temperature.ambient_c")
        step = mag["ambient_c"] - t_amb0
        return {"drift_n": mag["n_per_c"] * step * (1 - math.exp(-t_end / tau)),
                "n_per_c": mag["n_per_c"]}


class InputDelay(SynthEffect):
    """The applied current lags the logged one by whole ticks."""

    name = "input_delay"
    kind = "wrapper"
    defaults = {"delay_ticks": 5}

    def truth(self, mag, cfg, rec, fs):
        return {"delay_s": mag["delay_ticks"] * cfg.get("sim.tick_ns") * 1e-9}


class SensorSaturation(SynthEffect):
    name = "sensor_saturation"
    kind = "wrapper"
    defaults = {"level_pa": 4.0e6}


class PumpPulsationExtra(SynthEffect):
    """A second pulsation order's meshing torque, applied through the current."""

    name = "pump_pulsation_extra"
    kind = "wrapper"
    defaults = {"order": 2, "torque_n": 100.0, "phase_rad": 0.7}

    def truth(self, mag, cfg, rec, fs):
        return {"order": mag["order"], "amplitude": 0.0, "torque_n": mag["torque_n"]}


class MainsHum(SynthEffect):
    name = "mains_hum"
    kind = "outside"
    defaults = {"amplitude_pa": 1.0e4, "freq_hz": 50.0}


class Backlash(SynthEffect):
    name = "backlash"
    kind = "outside"
    defaults = {"width_rad": 0.05}


def ks_span(cfg: Config, x_lo: float, x_hi: float) -> float:
    """(k_s(x_hi) + k_s(x_lo)) / 2 / k_s(mid-range) - 1 over the visited range (Eq. 2.27)."""
    from plant import kernel
    from plant.model import build_params

    p = build_params(cfg, substeps=1)
    p[L.P_KSX_ON] = 1.0
    mid = 0.5 * (x_lo + x_hi)
    k_mid = kernel.series_stiffness(p, mid)
    return 0.5 * (kernel.series_stiffness(p, x_lo) + kernel.series_stiffness(p, x_hi)) / k_mid - 1


#: Every effect the plant-based generator makes, by name: the plant's, then those applied
#: around it, then those outside the library.
SYNTH_REGISTRY: dict[str, SynthEffect] = {e.name: e for e in (
    PumpPulsation(), PumpCoulombFriction(), SealFriction(), StiffnessVsPosition(),
    ViscosityTemperature(), StrainThermalDrift(), InputDelay(), SensorSaturation(),
    PumpPulsationExtra(), MainsHum(), Backlash())}

PLANT_EFFECTS = tuple(n for n, e in SYNTH_REGISTRY.items() if e.kind == "plant")
WRAPPER_EFFECTS = tuple(n for n, e in SYNTH_REGISTRY.items() if e.kind == "wrapper")
OUTSIDE_EFFECTS = tuple(n for n, e in SYNTH_REGISTRY.items() if e.kind == "outside")
ALL_SYNTH_EFFECTS = PLANT_EFFECTS + WRAPPER_EFFECTS + OUTSIDE_EFFECTS

__all__ = ["ALL_SYNTH_EFFECTS", "OUTSIDE_EFFECTS", "PLANT_EFFECTS", "SYNTH_REGISTRY",
           "SynthEffect", "WRAPPER_EFFECTS", "ks_span"]
