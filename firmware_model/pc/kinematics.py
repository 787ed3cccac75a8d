"""Cylinder <-> joint conversion of a two-DoF universal joint (thesis 6.2.1, Eq. 6.1-6.4).

* Inverse (joint -> cylinders), closed form: p_i(theta) (Eq. 6.1, in the arrangement of
  :mod:`firmware_model.pc.geometry`) and |p_i - z_i| = l (6.2) give the slider below p_i at
  z_iz = p_iz - sqrt(l^2 - (p_ix - z_i0x)^2 - (p_iy - z_i0y)^2).
* Jacobian G(theta) = dz/dtheta (6.3), analytic: with s_i = p_iz - z_iz = l cos(alpha_i),
  dz_iz = dp_iz + ((p_ix - z_i0x) dp_ix + (p_iy - z_i0y) dp_iy) / s_i.
* Forward (cylinders -> joint): no closed form; Newton on z(theta) = z_meas with G, from
  the last solution (the PC's previous cycle) or the middle of the range.
* Statics (6.4): tau = G^T f; commands the other way, f = G^-T tau.

Cylinder positions here are piston positions about mid-stroke, x_i = z_iz - z_mid_i (m);
f_i is the force the piston pushes its slider with along +z (N); tau is the generalised
force on theta (Nm). The kernels are numba-compiled on scalars so that the plant's per-tick
coupling and the 1 kHz PC loop share them; called from Python they run the same code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.pc.geometry import (
    G_L,
    G_ON_CHILD,
    G_P10X,
    G_Z10X,
    G_ZMID1,
)

NEWTON_TOL_RAD = 1e-12
NEWTON_MAX_ITER = 30


@njit(cache=True)
def _point(g, i, tp, tr, out):
    """p_i (Eq. 6.1) and its partials dp/dtheta_p, dp/dtheta_r into out[0:3], [3:6], [6:9]."""
    b = G_P10X + 3 * i
    x0, y0, z0 = g[b], g[b + 1], g[b + 2]
    cp, sp = math.cos(tp), math.sin(tp)
    cr, sr = math.cos(tr), math.sin(tr)
    if g[G_ON_CHILD] == 0.0:
        # p = R_y(tp) q, q = R_x(tr) p0; R_y(a) = [[c, 0, s], [0, 1, 0], [-s, 0, c]],
        # R_x(a) = [[1, 0, 0], [0, c, -s], [0, s, c]].
        qx, qy, qz = x0, cr * y0 - sr * z0, sr * y0 + cr * z0
        dqy, dqz = -sr * y0 - cr * z0, cr * y0 - sr * z0      # dq/dtr
        out[0] = cp * qx + sp * qz
        out[1] = qy
        out[2] = -sp * qx + cp * qz
        out[3] = -sp * qx + cp * qz                              # dp/dtp
        out[4] = 0.0
        out[5] = -cp * qx - sp * qz
        out[6] = sp * dqz                                        # dp/dtr
        out[7] = dqy
        out[8] = cp * dqz
    else:
        # p = R_x(-tr) q, q = R_y(-tp) p0 (the guides on the child link).
        qx, qy, qz = cp * x0 - sp * z0, y0, sp * x0 + cp * z0
        dqx, dqz = -sp * x0 - cp * z0, cp * x0 - sp * z0      # dq/dtp
        out[0] = qx
        out[1] = cr * qy + sr * qz
        out[2] = -sr * qy + cr * qz
        out[3] = dqx                                             # dp/dtp
        out[4] = sr * dqz
        out[5] = cr * dqz
        out[6] = 0.0                                             # dp/dtr
        out[7] = -sr * qy + cr * qz
        out[8] = -cr * qy - sr * qz


@njit(cache=True)
def joint_to_cylinder(g, tp, tr, z, G, cos_a):
    """Piston positions z[i] (m about mid-stroke), Jacobian G[i, j] = dz_i/dtheta_j (m/rad)
    and the rods' cos(alpha_i) at theta = (tp, tr). Returns False where a rod cannot reach
    its guide (outside the mechanism's workspace)."""
    buf = np.empty(9)
    l2 = g[G_L] * g[G_L]
    for i in range(2):
        _point(g, i, tp, tr, buf)
        ex = buf[0] - g[G_Z10X + 2 * i]
        ey = buf[1] - g[G_Z10X + 2 * i + 1]
        h2 = l2 - ex * ex - ey * ey
        if h2 <= 0.0:
            return False
        s = math.sqrt(h2)
        z[i] = buf[2] - s - g[G_ZMID1 + i]
        G[i, 0] = buf[5] + (ex * buf[3] + ey * buf[4]) / s
        G[i, 1] = buf[8] + (ex * buf[6] + ey * buf[7]) / s
        cos_a[i] = s / g[G_L]
    return True


@njit(cache=True)
def cylinder_to_joint(g, x1, x2, tp0, tr0, theta):
    """Joint angles from the piston positions (m about mid-stroke) by Newton from the guess
    (tp0, tr0); theta[0:2] = (theta_p, theta_r). Returns the number of iterations, or -1 if
    it did not converge (guess outside the workspace or too far)."""
    z = np.empty(2)
    G = np.empty((2, 2))
    ca = np.empty(2)
    tp, tr = tp0, tr0
    for k in range(NEWTON_MAX_ITER):
        if not joint_to_cylinder(g, tp, tr, z, G, ca):
            return -1
        r1, r2 = z[0] - x1, z[1] - x2
        det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
        if det == 0.0:
            return -1
        dp = (G[1, 1] * r1 - G[0, 1] * r2) / det
        dr = (-G[1, 0] * r1 + G[0, 0] * r2) / det
        tp -= dp
        tr -= dr
        if abs(dp) + abs(dr) < NEWTON_TOL_RAD:
            theta[0], theta[1] = tp, tr
            return k + 1
    return -1


@njit(cache=True)
def joint_torque(G, f1, f2, tau):
    """tau = G^T f (Eq. 6.4), Nm."""
    tau[0] = G[0, 0] * f1 + G[1, 0] * f2
    tau[1] = G[0, 1] * f1 + G[1, 1] * f2


@njit(cache=True)
def cylinder_force(G, tau_p, tau_r, f):
    """f = G^-T tau: the cylinder forces (N) that give the joint torques (Nm)."""
    det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
    f[0] = (G[1, 1] * tau_p - G[1, 0] * tau_r) / det
    f[1] = (-G[0, 1] * tau_p + G[0, 0] * tau_r) / det


class UJointKinematics:
    """The conversion with its buffers, for Python callers (the PC loop, scenarios, tests)."""

    def __init__(self, geometry) -> None:
        self.geometry = geometry
        self.g = geometry.as_array()
        lo, hi = geometry.pitch_range_rad
        self.theta = np.array([0.5 * (lo + hi), 0.0])  # Newton's first guess
        self.z = np.zeros(2)
        self.G = np.zeros((2, 2))
        self.cos_alpha = np.ones(2)
        self._tau = np.zeros(2)
        self._f = np.zeros(2)

    def inverse(self, theta_p: float, theta_r: float) -> np.ndarray:
        """Piston positions (m about mid-stroke) for the joint angles (rad); also updates
        ``G`` and ``cos_alpha`` there. ValueError outside the workspace."""
        if not joint_to_cylinder(self.g, theta_p, theta_r, self.z, self.G, self.cos_alpha):
            raise ValueError(f"theta = ({theta_p:.4f}, {theta_r:.4f}) rad: a rod cannot "
                             "reach its guide")
        return self.z.copy()

    def forward(self, x1: float, x2: float) -> np.ndarray:
        """Joint angles (rad) from piston positions, warm-started from the last solution;
        ``G`` and ``cos_alpha`` are left at the result. ValueError if Newton fails."""
        theta = np.empty(2)
        if cylinder_to_joint(self.g, x1, x2, self.theta[0], self.theta[1], theta) < 0:
            lo, hi = self.geometry.pitch_range_rad
            if cylinder_to_joint(self.g, x1, x2, 0.5 * (lo + hi), 0.0, theta) < 0:
                raise ValueError(f"pistons at ({x1:.5f}, {x2:.5f}) m: no joint angle found")
        self.theta[:] = theta
        joint_to_cylinder(self.g, theta[0], theta[1], self.z, self.G, self.cos_alpha)
        return theta

    def torque(self, f1: float, f2: float) -> np.ndarray:
        """tau = G^T f at the last solved pose (Nm)."""
        joint_torque(self.G, f1, f2, self._tau)
        return self._tau.copy()

    def forces(self, tau_p: float, tau_r: float) -> np.ndarray:
        """f = G^-T tau at the last solved pose (N)."""
        cylinder_force(self.G, tau_p, tau_r, self._f)
        return self._f.copy()
