"""The motor: a surface-magnet machine in the dq frame (amplitude-invariant transform),

    L di_d/dt = v_d - R i_d + w_e L i_q
    L di_q/dt = v_q - R i_q - w_e L i_d - w_e psi
    torque    = 1.5 p psi i_q           (motor Nm; times k_c/k_p -> piston N: K_t,eq i_q)

fed by the inverter's leg voltages (:mod:`plant.blocks.inverter`) in ``DriveMode.DUTY``; in
``CURRENT`` the currents follow their references exactly, in ``FORCE`` the pump force is
given directly, in ``OFF`` the gates are open and the currents are zero.
"""

from __future__ import annotations

import math

from numba import njit

from plant.blocks.inverter import leg_voltages
from plant.blocks.lanemath import sincos3
from plant.layout import (
    IN_IQ_REF,
    IN_TAU_REF,
    P_FLUX,
    P_KT_EQ,
    P_L,
    P_NUMERICS,
    P_POLE_PAIRS,
    P_R,
    S_ID,
    S_IQ,
    DriveMode,
)

TWO_PI_3 = 2.0 * math.pi / 3.0
SQRT3 = math.sqrt(3.0)
SQRT3_2 = 0.5 * SQRT3


@njit(cache=True, inline="always")
def phase_angles(th, numerics):
    """(cos th, sin th, cos(th - 2 pi/3), sin(th - 2 pi/3)). Plant recipe 2
    (``sim.plant_numerics``) turns phase a's pair by -120 deg (two libm calls instead of
    four; equal to within a rounding), recipe 1 calls libm for each; recipe 3 takes the pair from
    its own :func:`~plant.blocks.lanemath.sincos3` (one argument reduction, vectorisable)."""
    if numerics >= 3.0:
        s, c = sincos3(th)
        return c, s, -0.5 * c + SQRT3_2 * s, -0.5 * s - SQRT3_2 * c
    c = math.cos(th)
    s = math.sin(th)
    if numerics >= 2.0:
        return c, s, -0.5 * c + SQRT3_2 * s, -0.5 * s - SQRT3_2 * c
    return c, s, math.cos(th - TWO_PI_3), math.sin(th - TWO_PI_3)


@njit(cache=True, inline="always")
def drive(x, p, u, dx, mode, theta_rotor, vp, kc_kp):
    """Write di_d/dt, di_q/dt; return (pump force tau_p in piston N, electrical power in,
    copper losses), both powers 0 outside ``DriveMode.DUTY``."""
    p_elec = 0.0
    p_copper = 0.0
    if mode == DriveMode.DUTY:
        i_d = x[S_ID]
        i_q = x[S_IQ]
        th = p[P_POLE_PAIRS] * theta_rotor
        c, s, c2, s2 = phase_angles(th, p[P_NUMERICS])
        i_a = i_d * c - i_q * s
        i_b = i_d * c2 - i_q * s2
        i_c = -i_a - i_b
        v_a, v_b, v_c = leg_voltages(p, u, i_a, i_b, i_c)
        # Clarke (amplitude invariant); the common-mode voltage of a star winding drops out.
        v_alpha = (2.0 * v_a - v_b - v_c) / 3.0
        v_beta = (v_b - v_c) / SQRT3
        v_d = v_alpha * c + v_beta * s
        v_q = -v_alpha * s + v_beta * c
        w_e = p[P_POLE_PAIRS] * vp * kc_kp
        res = p[P_R]
        ind = p[P_L]
        dx[S_ID] = (v_d - res * i_d + w_e * ind * i_q) / ind
        dx[S_IQ] = (v_q - res * i_q - w_e * ind * i_d - w_e * p[P_FLUX]) / ind
        p_elec = 1.5 * (v_d * i_d + v_q * i_q)
        p_copper = 1.5 * res * (i_d * i_d + i_q * i_q)
        tau_p = p[P_KT_EQ] * i_q
    elif mode == DriveMode.CURRENT:
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = p[P_KT_EQ] * u[IN_IQ_REF]
    elif mode == DriveMode.OFF:
        # Gates off: the winding current has already decayed through the diodes (see
        # DriveMode.OFF in plant.layout), so there is no torque.
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = 0.0
    else:
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = u[IN_TAU_REF]
    return tau_p, p_elec, p_copper
