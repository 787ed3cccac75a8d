"""T-N curve and efficiencies at a constant q-axis current (thesis 2.3, Fig. 2.4; target F2).

Each point is a simulation: the motor is held at ``iq`` (ideal current source), the piston
pushes against a constant external force (free piston; the stall point holds the piston
fixed), and once the transient has died out the means over the last window give

* piston force tau_c and velocity v_c (the T-N curve),
* input power tau_p v_p (pump shaft, piston-equivalent) and output power tau_c v_c,
* volumetric efficiency v_c / v_p (piston displacement over theoretical pump displacement),
* torque efficiency tau_c / tau_p, and total efficiency = their product = P_out / P_in.

The electrical input (adding copper loss 1.5 R i_q^2) is reported too, as
``efficiency_electrical``; the thesis's 40 % is the transmission (shaft-to-piston) figure.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from plant.config import Config
from plant.layout import Y_F_ROD, Y_TAU_P, Y_TAU_Q, Y_V_PISTON, Y_VP
from plant.model import Plant


@dataclass
class TNPoint:
    """One operating point at constant current (SI units)."""

    force_n: float
    velocity_m_s: float
    pump_velocity_m_s: float
    tau_p_n: float
    tau_q_n: float
    power_in_w: float
    power_out_w: float
    efficiency_volumetric: float
    efficiency_torque: float
    efficiency: float
    efficiency_electrical: float


@dataclass
class TNCurve:
    """A T-N sweep; ``points`` run from stall (first) to no load (last)."""

    iq_a: float
    points: list[TNPoint]

    @property
    def stall_force_n(self) -> float:
        return self.points[0].force_n

    @property
    def no_load_velocity_m_s(self) -> float:
        return self.points[-1].velocity_m_s

    def peak(self) -> TNPoint:
        return max(self.points, key=lambda p: p.efficiency)

    def as_dict(self) -> dict:
        return {
            "iq_a": self.iq_a,
            "stall_force_n": self.stall_force_n,
            "no_load_velocity_m_s": self.no_load_velocity_m_s,
            "peak_efficiency": self.peak().efficiency,
            "peak_efficiency_force_n": self.peak().force_n,
            "points": [asdict(p) for p in self.points],
        }


def _settle_and_average(plant: Plant, settle_ticks: int, avg_ticks: int) -> np.ndarray:
    """Advance past the transient, then return the mean output row over ``avg_ticks``."""
    plant.advance(settle_ticks)
    acc = np.zeros_like(plant.y)
    chunk = 10
    n = 0
    while n < avg_ticks:
        plant.advance(chunk)
        acc += plant.y
        n += chunk
    return acc / (n // chunk)


def _point(plant: Plant, row: np.ndarray, force_n: float, iq_a: float) -> TNPoint:
    vc = float(row[Y_V_PISTON])
    vp = float(row[Y_VP])
    tau_p = float(row[Y_TAU_P])
    p_in = tau_p * vp
    p_out = force_n * vc
    r_phase = plant.config.get("motor.resistance_ohm")
    p_elec = p_in + 1.5 * r_phase * iq_a * iq_a
    return TNPoint(
        force_n=force_n,
        velocity_m_s=vc,
        pump_velocity_m_s=vp,
        tau_p_n=tau_p,
        tau_q_n=float(row[Y_TAU_Q]),
        power_in_w=p_in,
        power_out_w=p_out,
        efficiency_volumetric=vc / vp if vp else 0.0,
        efficiency_torque=force_n / tau_p if tau_p else 0.0,
        efficiency=p_out / p_in if p_in else 0.0,
        efficiency_electrical=p_out / p_elec if p_elec else 0.0,
    )


def simulate_tn_curve(
    cfg: Config,
    iq_a: float = 18.0,
    points: int = 17,
    settle_s: float = 0.08,
    average_s: float = 0.02,
    progress=None,
) -> TNCurve:
    """Sweep the load force from stall to zero at constant ``iq_a`` and return the curve.

    The stall point is simulated with the piston fixed; its force (the rod force) sets the
    range of the sweep. ``progress(i, n)`` is called after each point when given.
    """
    if points < 3:
        raise ValueError("a T-N curve needs at least 3 points")
    tick_s = cfg.get("sim.tick_ns") * 1e-9
    settle = int(round(settle_s / tick_s))
    avg = max(10, int(round(average_s / tick_s)))
    half = cfg.get("hydraulics.stroke_m") / 2

    stall_plant = Plant(cfg.with_overrides({"load.kind": "fixed"}, source="tn stall"))
    stall_plant.set_current(iq_a)
    row = _settle_and_average(stall_plant, settle, avg)
    stall_force = float(row[Y_F_ROD])
    out = [_point(stall_plant, row, stall_force, iq_a)]
    if progress:
        progress(1, points)

    # Start near the far end so the piston has the whole stroke to reach steady speed.
    start = -np.sign(iq_a) * (half - 0.5e-3)
    free_cfg = cfg.with_overrides({"load.kind": "free", "load.x0_m": float(start)},
                                  source="tn sweep")
    for i, frac in enumerate(np.linspace(1.0, 0.0, points)[1:], start=2):
        force = stall_force * frac
        plant = Plant(free_cfg)
        plant.set_current(iq_a)
        plant.set_external_force(-force)
        row = _settle_and_average(plant, settle, avg)
        out.append(_point(plant, row, force, iq_a))
        if progress:
            progress(i, points)
    return TNCurve(iq_a, out)
