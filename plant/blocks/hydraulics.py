"""The closed hydraulic circuit between pump and piston: internal leakage (series damper
d_s) and series elasticity k_s (oil and pipes), one rate equation for the pressure force
tau_q = k_c p (thesis Eq. 2.29-2.30):

    d tau_q/dt = k_s(x) (g(theta) v_p - tau_q / d_s - v_c)

k_s(x) by Eq. 2.25-2.27 (``effects.ks_position``) or the constant average. With
``effects.entrained_air`` the fluid's part also depends on the pressure: each side's
compliance V_i / kappa gains the air's alpha V_i p_atm / p_i^2 (isothermal bubbles,
alpha the air's volume fraction at atmospheric pressure p_atm), with p_i the side's
absolute pressure, the low side held at the accumulator's precharge by the check valves:

    k_s^fluid = kappa k_c^2 sum_i 1 / (V_i (1 + alpha kappa p_atm / p_i^2))

in series with k_s^pipe as Eq. 2.25; it is the tangent stiffness of the pressure force,
so the rate equation below keeps its form.
"""

from __future__ import annotations

from numba import njit

from plant.layout import (
    P_AIR_A,
    P_AIR_ON,
    P_HALF_STROKE,
    P_KC,
    P_KS_AVG,
    P_KS_FLUID_GAIN,
    P_KS_PIPE,
    P_KSX_ON,
    P_PRECHARGE,
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


#: Atmospheric pressure, Pa: the gauge pressures of the model are read against it.
P_ATM_PA = 101325.0


@njit(cache=True, inline="always")
def aerated_stiffness(p, x_c, tq):
    """k_s in N/m with entrained air at the pressure force tq (module docstring). With
    ks_position off, the constant average stands for the two sides at mid-stroke: its
    fluid part 1 / (1/k_s - 1/k_s^pipe), half on each side."""
    kc = p[P_KC]
    k_pipe = p[P_KS_PIPE]
    dp = tq / kc
    p_low = p[P_PRECHARGE] + P_ATM_PA
    p1 = p_low + (dp if dp > 0.0 else 0.0)
    p2 = p_low + (-dp if dp < 0.0 else 0.0)
    soft1 = 1.0 + p[P_AIR_A] / (p1 * p1)
    soft2 = 1.0 + p[P_AIR_A] / (p2 * p2)
    if p[P_KSX_ON] > 0.5:
        v1 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] + x_c)
        v2 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] - x_c)
        k_fluid = p[P_KS_FLUID_GAIN] * (1.0 / (v1 * soft1) + 1.0 / (v2 * soft2))
    else:
        k_side = 0.5 / (1.0 / p[P_KS_AVG] - 1.0 / k_pipe)
        k_fluid = k_side / soft1 + k_side / soft2
    return k_fluid * k_pipe / (k_fluid + k_pipe)


@njit(cache=True, inline="always")
def line_stiffness(p, x_c, tq):
    """k_s in N/m at piston position x_c and pressure force tq: the entrained air's when
    that effect is on, else :func:`series_stiffness` (the same arithmetic as without it)."""
    if p[P_AIR_ON] > 0.5:
        return aerated_stiffness(p, x_c, tq)
    return series_stiffness(p, x_c)


@njit(cache=True, inline="always")
def pressure_force(x, p, dx, g, vp, ds, vc, tq):
    """Write d tau_q/dt."""
    ks = line_stiffness(p, x[S_THC], tq)
    dx[S_TQ] = ks * (g * vp - tq / ds - vc)
