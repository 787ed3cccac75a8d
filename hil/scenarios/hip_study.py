"""Where F9's position figure can lie: the hip's position loop as two masses, mapped over
the physically admissible rod path, load and damping (docs/hip.md, "The admissible region").

The PC closes tau_cmd = K_p (theta_ref - theta_pistons) over the actuators' torque layer;
the thigh (inertia I, bearing damping b) hangs on the rods' joint-space stiffness and
damping K_rod + C_rod s = (k + c s) sum_i G_i^2 (k, c the rod path's series stiffness and
damping per cylinder, G the Jacobian at the hanging pose), and the angle is measured at
the pistons (thesis 6.4.1), the rods' deflection included. With the torque layer T(s):

    theta_pistons / theta_ref = T K_p P / (1 + T K_p P),
    P(s) = 1 / (I s^2 + b s) + 1 / (K_rod + C_rod s)

and the thigh's own angle (what the leg does) is

    theta / theta_ref = T K_p / ((I s^2 + b s) (1 + T K_p P))

T = 1 (an ideal torque layer, no PC delay) is the most favourable case the stack can
approach; ``tests/scenarios/test_f9.py`` holds the formula to the stack's peak and notch.
The position figure is the first -3 dB crossing, as F9 reads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Physical bounds of the rod path's series stiffness per cylinder, N/m: the testbed's
#: weak beam as calibrated on F6 (the softest structure the thesis measured), and the
#: connecting rod alone, a chromium-molybdenum steel pipe 5/8 mm (thesis 4.4), E = 206 GPa,
#: 120 mm long (docs/hip.md): EA/L, which the beam, guide and bearings in series only lower.
ROD_STEEL_E_PA = 206e9
ROD_PIPE_DIAMETERS_M = (0.005, 0.008)
ROD_LENGTH_M = 0.120


def rod_pipe_stiffness() -> float:
    """EA/L of the connecting rod's pipe, N/m (the rod path's upper bound)."""
    d_in, d_out = ROD_PIPE_DIAMETERS_M
    area = math.pi / 4.0 * (d_out ** 2 - d_in ** 2)
    return ROD_STEEL_E_PA * area / ROD_LENGTH_M


#: The F6-calibrated weak beam of the testbed (hydra_thesis), N/m: the lower bound.
BENCH_BEAM_N_PER_M = 0.55e6
#: Bounds of the rod path's damping per cylinder, N s/m: none, to one that makes the
#: reinforced path (2.1e6 N/m) critically damped against the piston's 0.295 kg ten times
#: over (2 sqrt(k m) = 1.6e3; beyond ~2e4 the "spring" is a dashpot).
ROD_DAMPING_BOUND = (0.0, 2.0e4)


def position_response(freqs_hz: np.ndarray, inertia: float, k_rod: float, c_rod: float,
                      kp: float, bearing: float = 0.5) -> np.ndarray:
    """theta_pistons / theta_ref at ``freqs_hz`` (joint space: ``k_rod`` Nm/rad, ``c_rod``
    Nm s/rad, ``kp`` Nm/rad, ``inertia`` kg m^2, ``bearing`` Nm s/rad), T = 1."""
    s = 2j * math.pi * np.asarray(freqs_hz, dtype=float)
    p = 1.0 / (inertia * s * s + bearing * s) + 1.0 / (k_rod + c_rod * s)
    return kp * p / (1.0 + kp * p)


def thigh_response(freqs_hz: np.ndarray, inertia: float, k_rod: float, c_rod: float,
                   kp: float, bearing: float = 0.5) -> np.ndarray:
    """theta_thigh / theta_ref (the load's own angle), same arguments."""
    s = 2j * math.pi * np.asarray(freqs_hz, dtype=float)
    body = inertia * s * s + bearing * s
    p = 1.0 / body + 1.0 / (k_rod + c_rod * s)
    return kp / (body * (1.0 + kp * p))


#: The frequency grid the study reads its crossings on, Hz.
STUDY_FREQS_HZ = np.arange(0.5, 200.0, 0.1)


def first_crossing(freqs_hz: np.ndarray, h: np.ndarray, db: float = -3.0) -> float:
    """The first frequency where |h| falls below ``db``, linearly interpolated in dB (nan
    when it never does)."""
    g = 20.0 * np.log10(np.abs(h))
    below = np.nonzero(g < db)[0]
    if len(below) == 0:
        return float("nan")
    i = int(below[0])
    if i == 0:
        return float(freqs_hz[0])
    f0, f1, g0, g1 = freqs_hz[i - 1], freqs_hz[i], g[i - 1], g[i]
    return float(f0 + (db - g0) * (f1 - f0) / (g1 - g0))


def position_bandwidth(inertia: float, k_rod: float, c_rod: float, kp: float,
                       bearing: float = 0.5, thigh: bool = False) -> float:
    """The two-mass loop's position -3 dB figure, Hz: of the piston-measured angle, or of
    the thigh's own angle (``thigh``)."""
    fn = thigh_response if thigh else position_response
    return first_crossing(STUDY_FREQS_HZ, fn(STUDY_FREQS_HZ, inertia, k_rod, c_rod, kp,
                                             bearing))


def rigid_bandwidth(inertia: float, kp: float) -> float:
    """The undamped rigid-rod limit: |K_p / (K_p - I w^2)| = 1/sqrt(2) at
    w^2 = (1 + sqrt 2) K_p / I, Hz."""
    return math.sqrt((1.0 + math.sqrt(2.0)) * kp / inertia) / (2.0 * math.pi)


def inertia_for(bandwidth_hz: float, kp: float) -> float:
    """The largest inertia that the rigid-rod limit lets reach ``bandwidth_hz``, kg m^2."""
    return (1.0 + math.sqrt(2.0)) * kp / (2.0 * math.pi * bandwidth_hz) ** 2


@dataclass(frozen=True)
class RegionMap:
    """The position figure over the admissible region, at one K_p and one load."""

    kp: float
    inertia: float
    jacobian_sq: float                   # sum_i G_i^2 at the hanging pose, m^2/rad^2
    stiffness_n_per_m: np.ndarray        # per-cylinder k grid
    damping_ns_per_m: np.ndarray         # per-cylinder c grid
    bandwidth_hz: np.ndarray             # (k, c) -> piston-measured position -3 dB, Hz
    thigh_bandwidth_hz: np.ndarray       # (k, c) -> the thigh's own angle -3 dB, Hz

    def best(self, thigh: bool = False) -> tuple[float, float, float]:
        """(bandwidth, k, c) of the highest position figure in the region (of the thigh's
        own angle with ``thigh``)."""
        bw = self.thigh_bandwidth_hz if thigh else self.bandwidth_hz
        b = np.where(np.isnan(bw), -1.0, bw)
        i, j = np.unravel_index(int(np.argmax(b)), b.shape)
        return (float(bw[i, j]), float(self.stiffness_n_per_m[i]),
                float(self.damping_ns_per_m[j]))


def region_map(inertia: float, kp: float, jacobian_sq: float, n: int = 13,
               k_bounds: tuple[float, float] | None = None,
               c_bounds: tuple[float, float] = ROD_DAMPING_BOUND,
               bearing: float = 0.5) -> RegionMap:
    """Map the position figure over the rod path's admissible stiffness (log grid) and
    damping (linear grid) for one load and gain."""
    lo, hi = k_bounds or (BENCH_BEAM_N_PER_M, rod_pipe_stiffness())
    ks = np.geomspace(lo, hi, n)
    cs = np.linspace(c_bounds[0], c_bounds[1], n)
    bw, own = (np.array([[position_bandwidth(inertia, k * jacobian_sq, c * jacobian_sq, kp,
                                             bearing, thigh) for c in cs] for k in ks])
               for thigh in (False, True))
    return RegionMap(kp, inertia, jacobian_sq, ks, cs, bw, own)


def hanging_jacobian_sq(axis: int) -> float:
    """sum_i G_i^2 of the hip's pitch (0) or roll (1) at the hanging pose, m^2/rad^2."""
    from firmware_model.pc.geometry import hip_geometry
    from firmware_model.pc.kinematics import UJointKinematics

    kin = UJointKinematics(hip_geometry())
    kin.inverse(0.0, 0.0)
    g = (kin.torque(1.0, 0.0)[axis], kin.torque(0.0, 1.0)[axis])
    return float(g[0] ** 2 + g[1] ** 2)


__all__ = ["BENCH_BEAM_N_PER_M", "ROD_DAMPING_BOUND", "RegionMap", "StudySummary",
           "first_crossing", "study_summary",
           "hanging_jacobian_sq", "inertia_for", "position_bandwidth", "position_response",
           "thigh_response",
           "region_map", "rigid_bandwidth", "rod_pipe_stiffness"]


@dataclass(frozen=True)
class StudySummary:
    """What the admissible region allows the position figure, for one axis and gain."""

    axis: int
    kp: float
    inertia_load: float          # the experiment's load (thigh + servo-on leg), kg m^2
    inertia_thigh: float         # the thigh alone (the leg's joints free), kg m^2
    best_load_hz: float          # the load's own angle, best over (k, c), experiment's load
    best_thigh_hz: float         # ... with the thigh alone
    best_pistons_hz: float       # the piston-measured angle, best over (k, c), exp. load
    inertia_for_30hz: float      # the largest inertia whose rigid limit reaches 30 Hz
    kp_for_30hz: float           # the K_p the rigid limit needs for 30 Hz with the exp. load

    def lines(self) -> list[str]:
        joint = ("pitch", "roll")[self.axis]
        return [
            f"study ({joint}, K_p {self.kp:g} Nm/rad, ideal torque layer, rod path over "
            f"{BENCH_BEAM_N_PER_M:.3g}..{rod_pipe_stiffness():.3g} N/m and "
            f"{ROD_DAMPING_BOUND[0]:g}..{ROD_DAMPING_BOUND[1]:g} N s/m): the load's own angle "
            f"reaches at best {self.best_load_hz:.1f} Hz with the leg below the thigh "
            f"(I = {self.inertia_load:.2f} kg m^2), {self.best_thigh_hz:.1f} Hz with the "
            f"thigh alone (I = {self.inertia_thigh:.3f} kg m^2); 30 Hz needs I <= "
            f"{self.inertia_for_30hz:.3f} kg m^2 at this K_p, or K_p >= "
            f"{self.kp_for_30hz:.3g} Nm/rad with the leg",
            (f"study: the piston-measured angle passes -3 dB as late as "
             f"{self.best_pistons_hz:.0f} Hz only where soft rods let the pistons move "
             "without the load (its high-frequency gain K_p / (K_p + K_rod)), not where the "
             "leg follows: the thesis's position figure is shown, not judged (docs/hip.md)"
             if self.best_pistons_hz >= 30.0 else
             f"study: the piston-measured angle too stays below 30 Hz (at best "
             f"{self.best_pistons_hz:.1f} Hz): the thesis's position figure is shown, not "
             "judged (docs/hip.md)"),
        ]


def study_summary(axis: int, kp: float, inertia_load: float, inertia_thigh: float,
                  n: int = 13) -> StudySummary:
    """Map the admissible region for ``axis`` at ``kp`` and sum it up."""
    j = hanging_jacobian_sq(axis)
    load = region_map(inertia_load, kp, j, n)
    alone = region_map(inertia_thigh, kp, j, n)
    return StudySummary(axis, kp, inertia_load, inertia_thigh, load.best(thigh=True)[0],
                        alone.best(thigh=True)[0], load.best()[0], inertia_for(30.0, kp),
                        (2.0 * math.pi * 30.0) ** 2 * inertia_load / (1.0 + math.sqrt(2.0)))
