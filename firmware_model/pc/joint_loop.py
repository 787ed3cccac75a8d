"""The onboard PC's 1 kHz joint loop for one two-DoF universal joint (thesis 5.5, 6.3).

Per cycle, from the two actuators' process data (piston positions, rod strain-gauge
forces) to their force commands:

1. joint state: theta by Newton (:mod:`firmware_model.pc.kinematics`), omega by a filtered
   difference; measured torque tau = G^T (cos(alpha) f^strain) (Eq. 6.4-6.6);
2. position loop: the reference clamped to the joint's range, then
   tau_cmd = K_p (theta_ref - theta) - K_d omega + tau_g(theta) + tau_ff
   (PD, the thigh's gravity torque from the PC's own model, a feed-forward torque), each
   axis saturated at its rated torque;
3. torque layer: the cylinder force commands f = G^-T tau_cmd (Eq. 6.4 inverted),
   saturated at the cylinder's rated force, go to the MCUs, whose 5 kHz force loops are
   the minor torque loop the thesis's position loop rests on.

Gains: the thesis gives K_p = 3000 Nm/rad for pitch and 6000 Nm/rad for roll (6.4.1); it
gives no K_d, which stays 0 by default: the angle comes from the pistons, two cycles old
by the time its force acts, and a derivative of it excites the thigh's mode on the rods
(docs/hip.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from firmware_model.pc.geometry import CYLINDER_FORCE_N, UJointGeometry
from firmware_model.pc.kinematics import UJointKinematics
from firmware_model.pc.strain import piston_force

GRAVITY = 9.80665


@dataclass(frozen=True)
class JointGains:
    """Position-loop gains per axis (pitch, roll), and the rate filter."""

    kp_nm_per_rad: tuple[float, float] = (3000.0, 6000.0)   # thesis 6.4.1
    kd_nms_per_rad: tuple[float, float] = (0.0, 0.0)        # not in the thesis
    omega_cutoff_hz: float = 150.0   # first-order filter on the differenced angle
    period_s: float = 1e-3           # 1 kHz (thesis 5.5)


def reference_acceleration(reference: Callable[[float], tuple[float, float]], t: float,
                           h: float) -> tuple[float, float]:
    """theta_ref_ddot (rad/s^2) at ``t`` by central differences over one cycle ``h`` of
    the reference the PC plans (it knows its trajectory one cycle ahead)."""
    rm, r0, rp = reference(max(t - h, 0.0)), reference(t), reference(t + h)
    return ((rp[0] - 2.0 * r0[0] + rm[0]) / (h * h), (rp[1] - 2.0 * r0[1] + rm[1]) / (h * h))


@dataclass(frozen=True)
class JointLimits:
    """Saturations: rated joint torques (thesis 6.2.2) and cylinder force."""

    torque_nm: tuple[float, float] = (80.0, 135.0)
    force_n: float = CYLINDER_FORCE_N


#: The PC's own figures for the thigh (thesis 6.2.2: 8.50 kg; COM 0.15 m below the joint
#: and radius of gyration 0.10 m are the same assumptions the plant makes, docs/hip.md),
#: kept here because firmware is built from its own values, not the plant's.
THIGH_MASS_KG = 8.50
THIGH_COM_M = 0.15
THIGH_GYRATION_M = 0.10


@dataclass(frozen=True)
class GravityModel:
    """The PC's model of the link below the joint: m g c (Nm), hanging at theta = 0, and
    its inertia about the joint I_hat = m (c^2 + k^2) (kg m^2) for the inverse dynamics."""

    mgc_nm: float = THIGH_MASS_KG * GRAVITY * THIGH_COM_M
    inertia_kgm2: float = THIGH_MASS_KG * (THIGH_COM_M ** 2 + THIGH_GYRATION_M ** 2)

    def torque(self, tp: float, tr: float) -> tuple[float, float]:
        """Gravity torque on theta (Nm), what the loop adds to hold the link."""
        return (-self.mgc_nm * math.sin(tp) * math.cos(tr),
                -self.mgc_nm * math.cos(tp) * math.sin(tr))

    def feed_forward(self, acc: tuple[float, float]) -> tuple[float, float]:
        """Inverse dynamics of the reference: tau_ff = I_hat theta_ref_ddot (Nm) per axis
        (diagonal inertia; the coupling terms are second order in F9's 0.25 deg)."""
        return self.inertia_kgm2 * acc[0], self.inertia_kgm2 * acc[1]


class JointController:
    """Position loop over the torque layer for one universal joint."""

    def __init__(self, geometry: UJointGeometry, gains: JointGains | None = None,
                 limits: JointLimits | None = None, gravity: GravityModel | None = None
                 ) -> None:
        self.kin = UJointKinematics(geometry)
        self.geometry = geometry
        self.gains = gains or JointGains()
        self.limits = limits or JointLimits()
        self.gravity = gravity or GravityModel()
        wc = 2.0 * math.pi * self.gains.omega_cutoff_hz * self.gains.period_s
        self._a = wc / (1.0 + wc)           # backward-Euler first-order low-pass
        self.theta = np.zeros(2)
        self.omega = np.zeros(2)
        self.tau = np.zeros(2)             # measured joint torque, Nm
        self.tau_cmd = np.zeros(2)
        self.theta_ref = np.zeros(2)
        self.f_cmd = np.zeros(2)
        self._started = False

    def measure(self, x: tuple[float, float], f_strain: tuple[float, float]) -> None:
        """Joint angle, rate and torque from the pistons and the rods' gauges."""
        theta = self.kin.forward(x[0], x[1])
        if self._started:
            rate = (theta - self.theta) / self.gains.period_s
            self.omega += self._a * (rate - self.omega)
        self._started = True
        self.theta = theta
        ca = self.kin.cos_alpha
        self.tau = self.kin.torque(piston_force(ca[0], f_strain[0]),
                                   piston_force(ca[1], f_strain[1]))

    def command(self, theta_ref: tuple[float, float],
                tau_ff: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """Cylinder force commands (N) for the reference, from the last :meth:`measure`."""
        (plo, phi), (rlo, rhi) = self.geometry.pitch_range_rad, self.geometry.roll_range_rad
        ref = (min(max(theta_ref[0], plo), phi), min(max(theta_ref[1], rlo), rhi))
        self.theta_ref[:] = ref
        g = self.gravity.torque(self.theta[0], self.theta[1])
        kp, kd = self.gains.kp_nm_per_rad, self.gains.kd_nms_per_rad
        for j in range(2):
            t = (kp[j] * (ref[j] - self.theta[j]) - kd[j] * self.omega[j] + g[j] + tau_ff[j])
            lim = self.limits.torque_nm[j]
            self.tau_cmd[j] = min(max(t, -lim), lim)
        f = self.kin.forces(self.tau_cmd[0], self.tau_cmd[1])
        lim = self.limits.force_n
        self.f_cmd[:] = np.clip(f, -lim, lim)
        return self.f_cmd.copy()
