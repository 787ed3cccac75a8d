"""The piston and what it drives:

    J_c dv_c/dt = tau_q - d_c v_c - F_seal(v_c) - f_rod + f_ext

with the load kind of ``load.kind``: ``fixed`` (piston held), ``free`` (external force on
the piston), ``conrod`` (rod to a fixed anchor through a stiffness and damping), ``cart``
(rod to a cart on guides, external force on the cart). Rod-seal friction (Coulomb +
Stribeck, ``effects.seal_friction``) and inelastic end stops at +/- stroke/2.
"""

from __future__ import annotations

from numba import njit

from plant.blocks import TICK
from plant.blocks.lanemath import exp_r, tanh_r
from plant.layout import (
    IN_F_EXT,
    LOAD_CART,
    LOAD_CONROD,
    LOAD_FIXED,
    LOAD_FREE,
    P_C_CART,
    P_C_ROD,
    P_HALF_STROKE,
    P_JC,
    P_K_ROD,
    P_LOAD_KIND,
    P_M_CART,
    P_NUMERICS,
    P_SF_COULOMB,
    P_SF_EPS,
    P_SF_ON,
    P_SF_STATIC,
    P_SF_VS,
    P_X_ANCHOR,
    S_EDISS,
    S_THC,
    S_VC,
    S_VL,
    S_XL,
)


@njit(cache=True, inline="always")
def seal_friction(p, v):
    """Rod-seal friction force in N opposing v: Coulomb + Stribeck, tanh-regularised."""
    if p[P_SF_ON] > 0.5:
        vs = v / p[P_SF_VS]
        level = p[P_SF_COULOMB] + (p[P_SF_STATIC] - p[P_SF_COULOMB]) * exp_r(-vs * vs,
                                                                            p[P_NUMERICS])
        return level * tanh_r(v / p[P_SF_EPS], p[P_NUMERICS])
    return 0.0


@njit(cache=True, inline="always")
def rod_force(p, x):
    """Force the rod (or the fixing) takes from the piston, N; compression positive."""
    kind = p[P_LOAD_KIND]
    if kind == LOAD_CONROD:
        return p[P_K_ROD] * (x[S_THC] - p[P_X_ANCHOR]) + p[P_C_ROD] * x[S_VC]
    if kind == LOAD_CART:
        return p[P_K_ROD] * (x[S_THC] - x[S_XL]) + p[P_C_ROD] * (x[S_VC] - x[S_VL])
    return 0.0


@njit(cache=True, inline="always")
def piston_and_load(x, p, u, dx, tq, vc, dc):
    """Write the piston's and the cart's derivatives; return (seal friction force, power
    lost in the load's dampers, power of the external force)."""
    kind = p[P_LOAD_KIND]
    f_seal = seal_friction(p, vc)
    f_ext = u[IN_F_EXT]
    loss_load = 0.0
    p_ext = 0.0
    if kind == LOAD_FIXED:
        dx[S_THC] = 0.0
        dx[S_VC] = 0.0
        dx[S_XL] = 0.0
        dx[S_VL] = 0.0
    else:
        f_rod = rod_force(p, x)
        dx[S_THC] = vc
        dx[S_VC] = (tq - dc * vc - f_seal - f_rod + (f_ext if kind == LOAD_FREE else 0.0)) / p[
            P_JC
        ]
        if kind == LOAD_CART:
            vl = x[S_VL]
            dx[S_XL] = vl
            dx[S_VL] = (f_rod + f_ext - p[P_C_CART] * vl) / p[P_M_CART]
            rel = vc - vl
            loss_load = p[P_C_ROD] * rel * rel + p[P_C_CART] * vl * vl
            p_ext = f_ext * vl
        else:
            dx[S_XL] = 0.0
            dx[S_VL] = 0.0
            if kind == LOAD_CONROD:
                loss_load = p[P_C_ROD] * vc * vc
            elif kind == LOAD_FREE:
                p_ext = f_ext * vc
    return f_seal, loss_load, p_ext


@njit(**TICK)
def end_stops(p, x):
    """Inelastic end stops at +/- stroke/2: hold the piston, drop its outward velocity."""
    half = p[P_HALF_STROKE]
    v = x[S_VC]
    if (x[S_THC] > half and v > 0.0) or (x[S_THC] < -half and v < 0.0):
        # The impact's kinetic energy is lost; book it so the energy balance still closes.
        x[S_EDISS] += 0.5 * p[P_JC] * v * v
        x[S_VC] = 0.0
    if x[S_THC] > half:
        x[S_THC] = half
    elif x[S_THC] < -half:
        x[S_THC] = -half
