"""The independent rig's own model of each effect, one class per effect.

The rig (:mod:`hil.identify.rig`) is the other side of the identification's test: it
simulates the actuator from the physical description and imports nothing of the fitted
model. What it knows about an effect lives here, registered under the effect's name (the
same names as the identification library's :data:`hil.identify.effects.EFFECTS`, plus the
effects outside it):

* its realistic default magnitudes (:attr:`RigEffect.defaults`) and which of them must be
  positive (they divide);
* how it sets the kernel's parameter vector (:meth:`RigEffect.set_kernel`);
* its truth in the identification report's terms (:meth:`RigEffect.truth`), from the
  magnitudes and the simulated record.

The sensor-side effects (``sensor_saturation``, ``mains_hum``, ``backlash``) also act in the
rig's sensor chain, where they sit between the converters' steps.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hil.identify.rig_layout import (
    I_DRIFT,
    I_KAPPA,
    I_KM,
    I_KM_RATE,
    I_KPIPE,
    I_KS,
    I_KSX,
    I_PC,
    I_PC_EPS,
    I_SF_C,
    I_SF_EPS,
    I_SF_S,
    I_SF_VS,
    I_TREF,
    I_VISC,
    I_VSIDE,
    Z_XC,
)

#: Magnitudes that divide (regularisation velocities, corners, levels): must be > 0.
POSITIVE_KEYS = ("eps_m_per_s", "stribeck_m_per_s", "corner_hz", "level_pa")
PRESSURE_COLUMNS = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc")


def ks_of_x(x: np.ndarray | float, v_side: float, kappa: float, kc: float, half: float,
            k_pipe: float) -> np.ndarray:
    """Series stiffness (N/m) at piston position ``x`` (m) by Eq. 2.25-2.27."""
    x = np.asarray(x, dtype=float)
    v1 = v_side + kc * (half + x)
    v2 = v_side + kc * (half - x)
    kf = kappa * kc * kc * (1.0 / v1 + 1.0 / v2)
    return 1.0 / (1.0 / kf + 1.0 / k_pipe)


def pulsation_orders(mag: Mapping[str, float]) -> list[tuple[float, float, float, float, float]]:
    """(order, flow amplitude, flow phase, torque N, torque phase) per switched-on order."""
    rows = []
    suffixes = [""] + sorted({k.rsplit("_", 1)[1] for k in mag
                              if k.startswith("order_") and k.rsplit("_", 1)[1].isdigit()},
                             key=int)
    for sfx in suffixes:
        tail = f"_{sfx}" if sfx else ""
        order = float(mag.get(f"order{tail}", 0.0))
        if order <= 0:
            continue
        if order != round(order):
            raise ValueError(f"pump_pulsation: order{tail} must be a whole number, got {order}")
        rows.append((order, float(mag.get(f"amplitude{tail}", 0.0)),
                     float(mag.get(f"phase_rad{tail}", 0.0)),
                     float(mag.get(f"torque_n{tail}", 0.0)),
                     float(mag.get(f"torque_phase_rad{tail}", 0.0))))
    return rows


@dataclass
class KernelSetup:
    """What an effect may need to set the kernel's parameters: the load, the drawn true
    parameters, the preset, the piston area ``kc`` (m^2) and half stroke ``half`` (m).
    ``v_side`` (m^3) is set by ``stiffness_vs_position`` (nan otherwise)."""

    load: str
    truep: Mapping[str, float]
    cfg: Any
    kc: float
    half: float
    v_side: float = float("nan")


@dataclass
class RigRecord:
    """The simulated record an effect's truth is read from: states ``zs``, true oil
    temperature ``temps`` (degC), kernel parameters ``p``, logged columns ``cols``, the
    setup, the input delay (s), the pressure step (Pa) and the mains-hum phase (rad)."""

    zs: np.ndarray
    temps: np.ndarray
    p: np.ndarray
    cols: Mapping[str, np.ndarray]
    setup: KernelSetup
    delay: float
    p_lsb: float
    hum_phase: float


class RigEffect:
    """One effect as the rig implements it (module docstring). The defaults: no kernel
    parameter, the magnitudes as the truth."""

    name: str = ""
    #: part of the identification library (else an "outside" effect for unexplained tests)
    library: bool = True
    #: needs a moving oil temperature
    needs_temperature: bool = False
    defaults: dict[str, float] = {}

    def accepts(self, key: str) -> bool:
        """Whether ``key`` is one of this effect's magnitudes."""
        return key in self.defaults

    def set_kernel(self, p: np.ndarray, mag: Mapping[str, float], k: KernelSetup) -> None:
        """Switch the effect on in the kernel's parameter vector ``p``."""

    def truth(self, mag: Mapping[str, float], rec: RigRecord) -> dict[str, dict[str, float]]:
        """The effect's truth under the report's label(s)."""
        return {self.name: dict(mag)}


class PumpPulsation(RigEffect):
    """Flow ripple and meshing torque of the trochoid pump, one or more orders (further
    orders by suffix ``order_2`` ...; order 0 = off); the kernel takes them as an array."""

    name = "pump_pulsation"
    defaults = {"order": 4.0, "amplitude": 0.02, "phase_rad": 0.3, "torque_n": 150.0,
                "torque_phase_rad": 1.1, "order_2": 0.0, "amplitude_2": 0.0,
                "phase_rad_2": 0.0, "torque_n_2": 0.0, "torque_phase_rad_2": 0.0}

    def accepts(self, key: str) -> bool:
        return key in self.defaults or key.rsplit("_", 1)[-1].isdigit()

    def truth(self, mag, rec):
        out: dict[str, dict[str, float]] = {}
        rows = pulsation_orders(mag)
        for i, (o, a, ph, tq, tph) in enumerate(rows):
            d = {"order": o, "amplitude": a, "phase_rad": ph, "torque_n": tq,
                 "torque_phase_rad": tph}
            if i == 0:
                out[self.name] = dict(d)
            if len(rows) > 1:
                # several orders: each also under the report's label
                out[f"pump_pulsation[order={int(o)}]"] = d
        return out


class PumpCoulombFriction(RigEffect):
    """Pump friction ``F (2/pi) atan(v/eps)`` (the fit's law is tanh, its eps 1e-4 m/s)."""

    name = "pump_coulomb_friction"
    defaults = {"force_n": 80.0, "eps_m_per_s": 3.0e-4}

    def set_kernel(self, p, mag, k):
        p[I_PC] = mag["force_n"]
        p[I_PC_EPS] = mag["eps_m_per_s"]

    def truth(self, mag, rec):
        return {self.name: {"force_n": mag["force_n"], "eps_m_per_s": mag["eps_m_per_s"]}}


class SealFriction(RigEffect):
    """Piston seal friction with a Stribeck level (fit: Stribeck 5 mm/s, eps 2 mm/s); a
    fixed piston does not move, so it stays off there."""

    name = "seal_friction"
    defaults = {"coulomb_n": 20.0, "static_n": 35.0, "stribeck_m_per_s": 4.0e-3,
                "eps_m_per_s": 1.0e-3}

    def set_kernel(self, p, mag, k):
        if k.load == "fixed_piston":
            return
        p[I_SF_C] = mag["coulomb_n"]
        p[I_SF_S] = mag["static_n"]
        p[I_SF_VS] = mag["stribeck_m_per_s"]
        p[I_SF_EPS] = mag["eps_m_per_s"]


class StiffnessVsPosition(RigEffect):
    """Series stiffness from the oil columns on both sides (Eq. 2.25-2.27); side volume
    nan = the preset's dead plus pipe volume."""

    name = "stiffness_vs_position"
    defaults = {"side_volume_m3": float("nan")}

    def set_kernel(self, p, mag, k):
        v_side = mag["side_volume_m3"]
        if not math.isfinite(v_side):
            v_side = float(k.cfg.get("hydraulics.dead_volume_m3")
                           + k.cfg.get("hydraulics.pipe_volume_m3"))
        k.v_side = v_side
        p[I_KSX] = 1.0
        p[I_VSIDE] = v_side
        p[I_KAPPA] = k.truep["bulk_modulus_pa"]
        p[I_KPIPE] = k.truep["ks_pipe_n_per_m"]
        # the baseline k_s is then the mid-stroke value of the physical law
        p[I_KS] = float(ks_of_x(0.0, v_side, p[I_KAPPA], k.kc, k.half, p[I_KPIPE]))

    def truth(self, mag, rec):
        p, k = rec.p, rec.setup
        x = rec.zs[:, Z_XC]
        lo, hi = float(x.min()), float(x.max())
        kfun = ks_of_x(np.array([lo, 0.5 * (lo + hi), hi]), k.v_side, p[I_KAPPA], k.kc,
                       k.half, p[I_KPIPE])
        a_eq = (k.v_side + k.kc * k.half) * p[I_KAPPA] / k.cfg.get("hydraulics.bulk_modulus_pa")
        return {self.name: {
            "ks_relative_span": float(0.5 * (kfun[0] + kfun[2]) / kfun[1] - 1.0),
            "side_volume_m3": k.v_side,
            # what the report's volume (computed with the preset's bulk modulus) sees
            "side_volume_at_preset_kappa_m3": float(a_eq - k.kc * k.half),
            "bulk_modulus_pa": float(p[I_KAPPA]),
            "ks_pipe_n_per_m": float(p[I_KPIPE]),
            "ks_mid_stroke_n_per_m": float(p[I_KS]),
            "x_min_m": lo, "x_max_m": hi,
        }}


class ViscosityTemperature(RigEffect):
    """Dampers scaled by ``exp(-c (T_oil - T_ref))``."""

    name = "viscosity_temperature"
    needs_temperature = True
    defaults = {"coeff_per_c": 0.03}

    def set_kernel(self, p, mag, k):
        p[I_VISC] = mag["coeff_per_c"]

    def truth(self, mag, rec):
        return {self.name: {"coeff_per_c": mag["coeff_per_c"],
                            "reference_c": float(rec.p[I_TREF])}}


class StrainThermalDrift(RigEffect):
    """The strain gauge's offset follows the oil temperature."""

    name = "strain_thermal_drift"
    needs_temperature = True
    defaults = {"n_per_c": 2.5}

    def set_kernel(self, p, mag, k):
        p[I_DRIFT] = mag["n_per_c"]

    def truth(self, mag, rec):
        return {self.name: {"n_per_c": mag["n_per_c"],
                            "drift_n": float(mag["n_per_c"] * (rec.temps[-1] - rec.temps[0]))}}


class InputDelay(RigEffect):
    """The motor gets the current ``delay_s`` late (the kernel splits the step there)."""

    name = "input_delay"
    defaults = {"delay_s": 300e-6}

    def truth(self, mag, rec):
        return {self.name: {"delay_s": rec.delay}}


class SensorSaturation(RigEffect):
    """Pressure channels clip at a level (applied in the rig's sensor chain)."""

    name = "sensor_saturation"
    defaults = {"level_pa": 4.0e6}

    def truth(self, mag, rec):
        level_code = math.floor(mag["level_pa"] / rec.p_lsb + 0.5)
        fracs = {c: float(np.mean(rec.cols[c] >= level_code * rec.p_lsb))
                 for c in PRESSURE_COLUMNS}
        return {self.name: {"level_pa": level_code * rec.p_lsb, "level_set_pa": mag["level_pa"],
                            **{f"clip_fraction_{c}": v for c, v in fracs.items()}}}


class HoseViscoelastic(RigEffect):
    """A Maxwell branch beside the series spring (outside the library). Set after the
    stiffness's law, whose mid-stroke ``k_s`` it scales."""

    name = "hose_viscoelastic"
    library = False
    defaults = {"stiffness_ratio": 0.5, "corner_hz": 30.0}

    def set_kernel(self, p, mag, k):
        p[I_KM] = mag["stiffness_ratio"] * p[I_KS]
        p[I_KM_RATE] = 2.0 * math.pi * mag["corner_hz"]

    def truth(self, mag, rec):
        p = rec.p
        return {self.name: {"k_m_n_per_m": float(p[I_KM]),
                            "c_m_ns_per_m": float(p[I_KM] / p[I_KM_RATE]),
                            "corner_hz": mag["corner_hz"]}}


class MainsHum(RigEffect):
    """A sinusoid on ``p_pump_a`` (outside the library; applied in the sensor chain)."""

    name = "mains_hum"
    library = False
    defaults = {"amplitude_pa": 1.0e4, "freq_hz": 50.0}

    def truth(self, mag, rec):
        return {self.name: {**mag, "phase_rad": rec.hum_phase}}


class Backlash(RigEffect):
    """A dead band between rotor and encoder disc (outside the library; sensor chain)."""

    name = "backlash"
    library = False
    defaults = {"width_rad": 0.05}


#: Every effect the rig implements, by name, in the order the kernel is set up (the
#: stiffness's law before the hose, which scales its k_s).
RIG_REGISTRY: dict[str, RigEffect] = {e.name: e for e in (
    PumpPulsation(), PumpCoulombFriction(), SealFriction(), StiffnessVsPosition(),
    ViscosityTemperature(), StrainThermalDrift(), InputDelay(), SensorSaturation(),
    HoseViscoelastic(), MainsHum(), Backlash())}

#: Effects of the identification library, as the rig implements them.
LIBRARY_EFFECTS: tuple[str, ...] = tuple(n for n, e in RIG_REGISTRY.items() if e.library)
#: Effects outside the library (for "unexplained" tests).
OUTSIDE_EFFECTS: tuple[str, ...] = tuple(n for n, e in RIG_REGISTRY.items() if not e.library)
RIG_EFFECTS: tuple[str, ...] = LIBRARY_EFFECTS + OUTSIDE_EFFECTS

__all__ = ["LIBRARY_EFFECTS", "OUTSIDE_EFFECTS", "RIG_EFFECTS", "KernelSetup",
           "POSITIVE_KEYS", "RIG_REGISTRY", "RigEffect", "RigRecord", "ks_of_x",
           "pulsation_orders"]
