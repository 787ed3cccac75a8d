"""The trochoid pump, seen from the piston:

    J_p dv_p/dt = tau_p - d_p v_p - F_cp(v_p) - g(theta) tau_q

``g = 1 + a sin(N theta_rotor + phi)`` is the displacement ripple (``effects.pulsation``);
it scales flow and reaction torque alike, so the pump converts power losslessly. The
meshing torque ripple (a constant part and one proportional to the pressure force) and the
shaft seal's Coulomb friction (``effects.pump_coulomb``) are the pump's friction F_cp.
"""

from __future__ import annotations

from numba import njit

from plant.blocks.lanemath import sin_r, tanh_r
from plant.layout import (
    P_JP,
    P_NUMERICS,
    P_PC_EPS,
    P_PC_FORCE,
    P_PC_ON,
    P_PULS_AMP,
    P_PULS_ON,
    P_PULS_ORDER,
    P_PULS_PHASE,
    P_PULS_TORQUE,
    P_PULS_TORQUE_REL,
    S_THP,
    S_VP,
)


@njit(cache=True, inline="always")
def ripple_and_friction(p, vp, theta_rotor, tq):
    """(g, F_cp): displacement ratio and pump friction force, piston N."""
    g = 1.0
    f_cp = 0.0
    if p[P_PC_ON] > 0.5:
        f_cp = p[P_PC_FORCE] * tanh_r(vp / p[P_PC_EPS], p[P_NUMERICS])
    if p[P_PULS_ON] > 0.5:
        ripple = sin_r(p[P_PULS_ORDER] * theta_rotor + p[P_PULS_PHASE], p[P_NUMERICS])
        g = 1.0 + p[P_PULS_AMP] * ripple
        # Meshing torque ripple: a load torque that depends on where the teeth mesh, a
        # constant part and one proportional to the pressure force the pump works against
        # (chamber pressures at the port edges, trapped volumes, tooth contact forces all
        # scale with the pressure). It stays in f_cp, so its work is booked with the pump
        # losses (zero on average).
        f_cp += (p[P_PULS_TORQUE] + p[P_PULS_TORQUE_REL] * tq) * ripple
    return g, f_cp


@njit(cache=True, inline="always")
def pump(p, dx, tau_p, vp, dp, f_cp, g, tq):
    """Write the pump's position and velocity derivatives."""
    dx[S_THP] = vp
    dx[S_VP] = (tau_p - dp * vp - f_cp - g * tq) / p[P_JP]
