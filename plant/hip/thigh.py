"""The thigh on the hip's universal joint, coupled to two EHA plants through their rods.

Joint side (theta = [theta_p, theta_r], rad; thigh hanging at theta = 0):

    I_j d omega_j/dt = tau_j + tau_g,j - b_j omega_j,   tau = G(theta)^T f_rod  (Eq. 6.4)
    tau_g = -m g c [sin theta_p cos theta_r, cos theta_p sin theta_r]

with the thigh's COM at c below the joint (potential m g z_COM, z_COM = -c cos theta_p
cos theta_r), diagonal inertia about the joint (constant: the F9 motion is 0.25 deg).

Cylinder side: each plant runs its ``conrod`` load, f_rod = k (x_c - x_anchor) + c v_c,
with the anchor moved every tick to where the joint puts the slider, z_i(theta)
(:mod:`firmware_model.pc.kinematics`), shifted by c zdot_i / k so that the rod's damping
acts on the relative velocity: f_rod,i = k (x_c,i - z_i) + c (v_c,i - zdot_i). k is the
series stiffness of the piston rod, beam, slider and rod-end bearings (thesis 5.4), the
one figure that separates the reinforced from the unreinforced structure.

The strain gauge sits on the connecting rod, which leans by alpha_i: it reads the rod-axis
force f_rod,i / cos(alpha_i) (Eq. 6.5 the other way); the plant's own strain output (its
drift, noise and quantisation) is scaled so.

Per tick (:func:`couple_tick`): the two plants have integrated to t with their anchors
held; the joint integrates over the same tick on their rod forces (semi-implicit Euler:
the joint's modes, < 100 Hz, are far below 20 kHz), then the anchors for the next tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from firmware_model.pc.kinematics import joint_to_cylinder
from plant.layout import P_C_ROD, P_K_ROD, P_X_ANCHOR, S_THC, Y_F_ROD, Y_F_STRAIN

GRAVITY = 9.80665

# Joint parameters (H_*) and state (J_*) arrays of the compiled coupling.
(H_I_PITCH, H_I_ROLL, H_MGC, H_B_PITCH, H_B_ROLL) = range(5)
N_H = 5
(J_TP, J_TR, J_WP, J_WR, J_TAU_P, J_TAU_R, J_Z1, J_Z2, J_ZD1, J_ZD2, J_CA1, J_CA2,
 J_F1, J_F2, J_G00, J_G01, J_G10, J_G11) = range(18)
N_J = 18


@dataclass(frozen=True)
class LegBelow:
    """The leg below the thigh, held to it by its own servo-on joints (thesis 6.4.1: the
    robot on a crane, one leg servo-on): a rigid part of the hip's load. Masses from
    Table 6.1 (the link after the knee 4.67 kg, the foot 2.11 kg); the lengths are
    assumptions for a 180 cm robot (docs/hip.md): hip to knee 0.40 m, knee to ankle
    0.40 m, the shank's COM 0.15 m below the knee (its EHAs sit near the knee), the foot's
    0.05 m below the ankle. The knee and ankle loops' own compliance is not modelled: the
    leg moves with the thigh."""

    shank_kg: float = 4.67
    foot_kg: float = 2.11
    knee_m: float = 0.40                 # hip to knee; assumption
    shank_com_m: float = 0.15            # below the knee; assumption
    shank_gyration_m: float = 0.10       # about the shank's COM; assumption
    ankle_m: float = 0.40                # knee to ankle; assumption
    foot_com_m: float = 0.05             # below the ankle; assumption
    foot_gyration_m: float = 0.06        # about the foot's COM; assumption

    def inertia(self) -> float:
        """Inertia about the hip's axes (parallel axes), kg m^2."""
        c_s = self.knee_m + self.shank_com_m
        c_f = self.knee_m + self.ankle_m + self.foot_com_m
        return (self.shank_kg * (c_s ** 2 + self.shank_gyration_m ** 2)
                + self.foot_kg * (c_f ** 2 + self.foot_gyration_m ** 2))

    def mass_moment(self) -> float:
        """m c of the leg below the hip (kg m): its gravity torque is m c g sin(theta)."""
        return (self.shank_kg * (self.knee_m + self.shank_com_m)
                + self.foot_kg * (self.knee_m + self.ankle_m + self.foot_com_m))


@dataclass(frozen=True)
class ThighParams:
    """The thigh as the hip's load (SI). Thesis 6.2.2: 8.50 kg with its four EHAs; the
    1.59 kg intermediate link sits above the pitch axis on the hip-yaw output (held still
    in F9), so it is not part of the moving load. COM distance and radius of gyration are
    assumptions (docs/hip.md)."""

    mass_kg: float = 8.50
    com_m: float = 0.15                  # COM below the joint; assumption
    gyration_m: float = 0.10             # radius of gyration about the COM; assumption
    damping_nms_per_rad: float = 0.5     # joint bearings; assumption
    #: The leg below, when the experiment had it on the thigh (None: the thigh alone).
    leg: LegBelow | None = None

    def inertia(self) -> float:
        """Inertia about the joint axes (parallel axes), kg m^2, the leg's included."""
        inertia = self.mass_kg * (self.com_m ** 2 + self.gyration_m ** 2)
        if self.leg is not None:
            inertia += self.leg.inertia()
        return inertia

    def as_array(self) -> np.ndarray:
        h = np.zeros(N_H)
        h[H_I_PITCH] = h[H_I_ROLL] = self.inertia()
        h[H_MGC] = self.mass_kg * GRAVITY * self.com_m
        if self.leg is not None:
            h[H_MGC] += self.leg.mass_moment() * GRAVITY
        h[H_B_PITCH] = h[H_B_ROLL] = self.damping_nms_per_rad
        return h


@njit(cache=True)
def gravity_torque(h, tp, tr, out):
    """tau_g = -dV/dtheta of the hanging thigh, Nm."""
    out[0] = -h[H_MGC] * math.sin(tp) * math.cos(tr)
    out[1] = -h[H_MGC] * math.cos(tp) * math.sin(tr)


@njit(cache=True)
def set_pose(g, js, tp, tr, wp, wr):
    """Put the joint at (tp, tr) moving at (wp, wr): slider positions, rates, G, cos(alpha)
    into the state. False outside the workspace."""
    z = np.empty(2)
    G = np.empty((2, 2))
    ca = np.empty(2)
    if not joint_to_cylinder(g, tp, tr, z, G, ca):
        return False
    js[J_TP], js[J_TR], js[J_WP], js[J_WR] = tp, tr, wp, wr
    js[J_Z1], js[J_Z2] = z[0], z[1]
    js[J_ZD1] = G[0, 0] * wp + G[0, 1] * wr
    js[J_ZD2] = G[1, 0] * wp + G[1, 1] * wr
    js[J_CA1], js[J_CA2] = ca[0], ca[1]
    js[J_G00], js[J_G01], js[J_G10], js[J_G11] = G[0, 0], G[0, 1], G[1, 0], G[1, 1]
    return True


@njit(cache=True)
def place_pistons(js, x1, x2):
    """Pistons (plant states) where the rods end at the joint's pose, rods unloaded."""
    x1[S_THC] = js[J_Z1]
    x2[S_THC] = js[J_Z2]


@njit(cache=True)
def place_anchors(js, p1, p2):
    """The plants' conrod anchors from the joint state (relative-velocity damping)."""
    p1[P_X_ANCHOR] = js[J_Z1] + p1[P_C_ROD] * js[J_ZD1] / p1[P_K_ROD]
    p2[P_X_ANCHOR] = js[J_Z2] + p2[P_C_ROD] * js[J_ZD2] / p2[P_K_ROD]


@njit(cache=True)
def couple_tick(g, h, js, dt, p1, y1, p2, y2):
    """After both plants' tick: joint over the tick, then the anchors and the gauges."""
    f1, f2 = y1[Y_F_ROD], y2[Y_F_ROD]
    tau_p = js[J_G00] * f1 + js[J_G10] * f2
    tau_r = js[J_G01] * f1 + js[J_G11] * f2
    tg = np.empty(2)
    gravity_torque(h, js[J_TP], js[J_TR], tg)
    wp = js[J_WP] + dt * (tau_p + tg[0] - h[H_B_PITCH] * js[J_WP]) / h[H_I_PITCH]
    wr = js[J_WR] + dt * (tau_r + tg[1] - h[H_B_ROLL] * js[J_WR]) / h[H_I_ROLL]
    tp = js[J_TP] + dt * wp
    tr = js[J_TR] + dt * wr
    js[J_TAU_P], js[J_TAU_R], js[J_F1], js[J_F2] = tau_p, tau_r, f1, f2
    if not set_pose(g, js, tp, tr, wp, wr):
        # Out of the workspace: hold the last pose (the end stops of the cylinders keep a
        # real joint inside it).
        js[J_WP] = js[J_WR] = 0.0
    place_anchors(js, p1, p2)
    # The gauge on the leaning rod reads the rod-axis force.
    y1[Y_F_STRAIN] = y1[Y_F_STRAIN] / js[J_CA1]
    y2[Y_F_STRAIN] = y2[Y_F_STRAIN] / js[J_CA2]
