"""The closed hydraulic circuit between pump and piston: internal leakage (series damper
d_s) and series elasticity k_s (oil and pipes), one rate equation for the pressure force
tau_q = k_c p (thesis Eq. 2.29-2.30):

    d tau_q/dt = k_s(x) (g(theta) v_p - tau_q / d_s - v_c)

k_s(x) by Eq. 2.25-2.27 (``effects.ks_position``) or the constant average.
"""

from __future__ import annotations

from numba import njit

from plant.layout import (
    P_HALF_STROKE,
    P_KC,
    P_KS_AVG,
    P_KS_FLUID_GAIN,
    P_KS_PIPE,
    P_KSX_ON,
    P_SIDE_V0,
    S_THC,
    S_TQ,
)


@njit(cache=True, inline="always")
def series_stiffness(p, x_c):
    """k_s in N/m: Eq. 2.25-2.27 at piston position x_c when ks_position is on."""
    if p[P_KSX_ON] > 0.5:
        kc = p[P_KC]
        v1 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] + x_c)
        v2 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] - x_c)
        k_fluid = p[P_KS_FLUID_GAIN] * (1.0 / v1 + 1.0 / v2)
        return k_fluid * p[P_KS_PIPE] / (k_fluid + p[P_KS_PIPE])
    return p[P_KS_AVG]


@njit(cache=True, inline="always")
def pressure_force(x, p, dx, g, vp, ds, vc, tq):
    """Write d tau_q/dt."""
    ks = series_stiffness(p, x[S_THC])
    dx[S_TQ] = ks * (g * vp - tq / ds - vc)
