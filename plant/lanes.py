"""The plant's RK4 over many actuators at once, one actuator per vector lane.

:func:`plant.kernel.rk4_tick` integrates one actuator; here the same arithmetic runs over
``n`` actuators whose states, parameters and inputs are stored transposed (structure of
arrays: state ``S_VP`` of lane ``i`` at ``X + S_VP * LW + i``), so that each statement
becomes one vector instruction over four actuators (AVX2). Per actuator it is the same
operations in the same order as :mod:`plant.blocks` under the arithmetic recipe 3 (its
own exp, sin/cos and tanh, :mod:`plant.blocks.lanemath`): bit for bit the scalar kernel's result
(``tests/plant/test_lanes.py``). Lanes may differ in everything: drive mode, load kind,
effects switched on or off, number of sub-steps. A branch of the scalar code becomes a
select between both sides, both computed on every lane (an unused side may divide by a
zero parameter: compiled with numpy's error model, that is an inf, not an exception, and
it is never selected). An effect that no lane of the batch has on is not computed at all
(:func:`batch_effects`, :func:`_effect_passes`): every lane would select the scalar code's
value for "off", which does not depend on what the other side computes.

Every loop over the lanes is large (or fused into one that is): numba runs LLVM's loop
vectoriser, not its straight-line one, and a small loop is fully unrolled into scalar code
before the loop vectoriser sees it (docs/robot-engine.md, "The plants in vector lanes").

The scalar blocks stay the readable reference; this module repeats their equations
lane-wise and says where each comes from.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant import layout as L
from plant.blocks.hydraulics import P_ATM_PA
from plant.blocks.lanemath import exp3, pick, sincos3, tanh3
from plant.blocks.motor_dq import SQRT3, SQRT3_2

#: Compile options of the lane loops: cached, no runtime, no division-by-zero checks (a
#: check is a branch per lane that stops the loop from vectorising; see the module doc).
LANES = {"cache": True, "_nrt": False, "error_model": "numpy", "nogil": True}

#: Lanes per batch. Every array of a batch lives in one flat buffer at offsets known when
#: the kernel is compiled (row ``k`` of a block at ``offset + k * LW``): the compiler then
#: sees that the derivatives it writes never overlap the states and parameters it reads,
#: and vectorises without run-time overlap checks (with separate arrays it needs one per
#: pair of rows, far more than it is willing to emit).
LW = 8
X = 0                               #: states (N_STATES rows)
PO = X + L.N_STATES * LW            #: parameters (N_PARAMS rows)
UO = PO + L.N_PARAMS * LW           #: inputs (N_INPUTS rows)
K1 = UO + L.N_INPUTS * LW           #: RK4 slopes k1..k4 and the intermediate state
K2 = K1 + L.N_STATES * LW
K3 = K2 + L.N_STATES * LW
K4 = K3 + L.N_STATES * LW
XT = K4 + L.N_STATES * LW
YO = XT + L.N_STATES * LW           #: plant outputs (N_OUTPUTS rows; plant.lane_outputs)
GO = YO + L.N_OUTPUTS * LW          #: the tick's seven standard normal noise samples
RG = GO + 7 * LW                    #: the noise streams' xorshift64* states (their bits)
#: The effects' terms, one row each (the passes of :func:`_effect_passes` write them, the
#: loop of the derivatives reads them): viscosity ratio, pump Coulomb friction, seal
#: friction, stiffness with entrained air, power lost in the load's dampers, power of the
#: external force.
VR = RG + LW
FC = VR + LW
FS = FC + LW
KA = FS + LW
LL = KA + LW
PE = LL + LW
SIZE = PE + LW


@njit(cache=True, inline="always")
def _ix(at, k, i):
    """Where row ``k`` of lane ``i`` of the block at ``at`` is in the lane buffer, as an
    unsigned index: numba then indexes without the wrap-around of negative indices (a
    select per access that hides from the compiler that the lanes are consecutive)."""
    return np.uint64(at + k * LW + i)


@njit(cache=True, inline="always")
def _p(B, k, i, at=PO):
    """Row ``k`` (a parameter by default) of lane ``i`` in the lane buffer."""
    return B[_ix(at, k, i)]


@njit(cache=True, inline="always")
def viscosity_lane(B, i, t_oil):
    """:func:`plant.blocks.thermal.viscosity_ratio` of lane ``i`` (recipe 3's exp)."""
    visc = exp3(-_p(B, L.P_VISC_COEFF, i) * (t_oil - _p(B, L.P_T_REF, i)))
    return visc if _p(B, L.P_TEMP_ON, i) > 0.5 else 1.0


@njit(cache=True, inline="always", error_model="numpy")
def series_stiffness_lane(B, i, x_c):
    """:func:`plant.blocks.hydraulics.series_stiffness` of lane ``i`` (k_s at x_c or the
    average), both sides computed and selected."""
    kc = _p(B, L.P_KC, i)
    k_pipe = _p(B, L.P_KS_PIPE, i)
    v1 = _p(B, L.P_SIDE_V0, i) + kc * (_p(B, L.P_HALF_STROKE, i) + x_c)
    v2 = _p(B, L.P_SIDE_V0, i) + kc * (_p(B, L.P_HALF_STROKE, i) - x_c)
    k_fluid = _p(B, L.P_KS_FLUID_GAIN, i) * (1.0 / v1 + 1.0 / v2)
    ks_x = k_fluid * k_pipe / (k_fluid + k_pipe)
    return ks_x if _p(B, L.P_KSX_ON, i) > 0.5 else _p(B, L.P_KS_AVG, i)


@njit(cache=True, inline="always", error_model="numpy")
def aerated_stiffness_lane(B, i, x_c, tq):
    """:func:`plant.blocks.hydraulics.aerated_stiffness` of lane ``i`` (fluid part at x_c
    or from the average), both sides computed and selected."""
    kc = _p(B, L.P_KC, i)
    k_pipe = _p(B, L.P_KS_PIPE, i)
    v1 = _p(B, L.P_SIDE_V0, i) + kc * (_p(B, L.P_HALF_STROKE, i) + x_c)
    v2 = _p(B, L.P_SIDE_V0, i) + kc * (_p(B, L.P_HALF_STROKE, i) - x_c)
    dpa = tq / kc
    p_low = _p(B, L.P_PRECHARGE, i) + P_ATM_PA
    p1 = p_low + (dpa if dpa > 0.0 else 0.0)
    p2 = p_low + (-dpa if dpa < 0.0 else 0.0)
    soft1 = 1.0 + _p(B, L.P_AIR_A, i) / (p1 * p1)
    soft2 = 1.0 + _p(B, L.P_AIR_A, i) / (p2 * p2)
    kf_x = _p(B, L.P_KS_FLUID_GAIN, i) * (1.0 / (v1 * soft1) + 1.0 / (v2 * soft2))
    k_side = 0.5 / (1.0 / _p(B, L.P_KS_AVG, i) - 1.0 / k_pipe)
    kf_avg = k_side / soft1 + k_side / soft2
    kf_air = kf_x if _p(B, L.P_KSX_ON, i) > 0.5 else kf_avg
    return kf_air * k_pipe / (kf_air + k_pipe)


@njit(cache=True, inline="always", error_model="numpy")
def line_stiffness_lane(B, i, x_c, tq):
    """:func:`plant.blocks.hydraulics.line_stiffness` of lane ``i``: both kinds computed
    and selected (the batch's loops compute the aerated one only where some lane has the
    air on: :func:`rk4_lanes`)."""
    ks_air = aerated_stiffness_lane(B, i, x_c, tq)
    ks_series = series_stiffness_lane(B, i, x_c)
    return ks_air if _p(B, L.P_AIR_ON, i) > 0.5 else ks_series


@njit(cache=True, inline="always")
def batch_effects(B):
    """Which effects some lane of the batch has on: (oil temperature, pump Coulomb
    friction, seal friction, entrained air, a load that moves (not ``fixed``)), and the
    most sub-steps a lane takes. An effect off in every lane is skipped in the batch's
    loops (its rows hold the value every lane would select: see :func:`rk4_lanes`)."""
    temp = False
    pc = False
    sf = False
    air = False
    moving = False
    n_sub = 0.0
    for i in range(LW):
        temp |= _p(B, L.P_TEMP_ON, i) > 0.5
        pc |= _p(B, L.P_PC_ON, i) > 0.5
        sf |= _p(B, L.P_SF_ON, i) > 0.5
        air |= _p(B, L.P_AIR_ON, i) > 0.5
        moving |= _p(B, L.P_LOAD_KIND, i) != L.LOAD_FIXED
        n = _p(B, L.P_N_SUB, i)
        n_sub = n if n > n_sub else n_sub
    return temp, pc, sf, air, moving, n_sub


@njit(cache=True, inline="always")
def _fill(B, at, v):
    """Every lane of the row at ``at`` := ``v``."""
    for i in range(LW):
        B[_ix(at, 0, i)] = v


@njit(cache=True, inline="always")
def _constant_rows(B, fx):
    """The rows of the effects switched off in every lane of the batch, once per call:
    what each lane selects then (viscosity ratio 1, no pump Coulomb or seal friction; with
    every load fixed, the piston's and cart's slopes and the load's powers 0). The
    computing passes never run for these in this call, so the rows keep their values."""
    temp, pc, sf, air, moving, _ = fx
    if not temp:
        _fill(B, VR, 1.0)
    if not pc:
        _fill(B, FC, 0.0)
    if not sf:
        _fill(B, FS, 0.0)
    if not moving:
        _fill(B, LL, 0.0)
        _fill(B, PE, 0.0)
        for ko in (K1, K2, K3, K4):
            for s in (L.S_THC, L.S_VC, L.S_XL, L.S_VL):
                _fill(B, ko + s * LW, 0.0)


@njit(cache=True, inline="always", error_model="numpy")
def _effect_passes(B, xo, do, fx):
    """The effects' terms of :func:`derivatives_lanes` with exp, tanh and divisions of
    their own, each a loop over the lanes of its own, run only where some lane of the batch
    has the effect on (a select takes the same bits as the scalar code's branch, computed
    or not): the viscosity ratio (``VR``), the pump's Coulomb friction (``FC``), the rod
    seal's friction (``FS``), the stiffness with entrained air (``KA``), and the piston's
    and cart's slopes with the load's powers (``LL``, ``PE``)."""
    temp, pc, sf, air, moving, _ = fx
    if temp:  # thermal.viscosity_ratio
        for i in range(LW):
            B[_ix(VR, 0, i)] = viscosity_lane(B, i, _p(B, L.S_TOIL, i, xo))
    if pc:  # the pump Coulomb part of pump.ripple_and_friction
        for i in range(LW):
            vp = _p(B, L.S_VP, i, xo)
            f_coul = _p(B, L.P_PC_FORCE, i) * tanh3(vp / _p(B, L.P_PC_EPS, i))
            B[_ix(FC, 0, i)] = f_coul if _p(B, L.P_PC_ON, i) > 0.5 else 0.0
    if sf:  # load.seal_friction
        for i in range(LW):
            vc = _p(B, L.S_VC, i, xo)
            vs = vc / _p(B, L.P_SF_VS, i)
            coulomb = _p(B, L.P_SF_COULOMB, i)
            level = coulomb + (_p(B, L.P_SF_STATIC, i) - coulomb) * exp3(-vs * vs)
            f_seal = level * tanh3(vc / _p(B, L.P_SF_EPS, i))
            B[_ix(FS, 0, i)] = f_seal if _p(B, L.P_SF_ON, i) > 0.5 else 0.0
    if air:  # hydraulics.aerated_stiffness
        for i in range(LW):
            B[_ix(KA, 0, i)] = aerated_stiffness_lane(B, i, _p(B, L.S_THC, i, xo),
                                                      _p(B, L.S_TQ, i, xo))
    if moving:  # load.piston_and_load, load.rod_force
        for i in range(LW):
            _load_lane(B, i, xo, do)


@njit(cache=True, inline="always", error_model="numpy")
def _load_lane(B, i, xo, do):
    """:func:`plant.blocks.load.piston_and_load` of lane ``i`` (the seal friction from
    ``FS``): the piston's and the cart's slopes into ``do``, the power lost in the load's
    dampers and the external force's power into ``LL`` and ``PE``."""
    kind = _p(B, L.P_LOAD_KIND, i)
    r = B[_ix(VR, 0, i)]
    dc = _p(B, L.P_DC, i) * r
    vc = _p(B, L.S_VC, i, xo)
    tq = _p(B, L.S_TQ, i, xo)
    x_c = _p(B, L.S_THC, i, xo)
    f_seal = B[_ix(FS, 0, i)]
    f_ext = _p(B, L.IN_F_EXT, i, UO)
    k_rod = _p(B, L.P_K_ROD, i)
    c_rod = _p(B, L.P_C_ROD, i)
    vl = _p(B, L.S_VL, i, xo)
    rod_conrod = k_rod * (x_c - _p(B, L.P_X_ANCHOR, i)) + c_rod * vc
    rod_cart = k_rod * (x_c - _p(B, L.S_XL, i, xo)) + c_rod * (vc - vl)
    cart = kind == L.LOAD_CART
    f_rod = rod_conrod if kind == L.LOAD_CONROD else (rod_cart if cart else 0.0)
    fixed = kind == L.LOAD_FIXED
    free = kind == L.LOAD_FREE
    dvc = (tq - dc * vc - f_seal - f_rod + (f_ext if free else 0.0)) / _p(B, L.P_JC, i)
    c_cart = _p(B, L.P_C_CART, i)
    dvl = (f_rod + f_ext - c_cart * vl) / _p(B, L.P_M_CART, i)
    rel = vc - vl
    loss_cart = c_rod * rel * rel + c_cart * vl * vl
    B[_ix(do, L.S_THC, i)] = 0.0 if fixed else vc
    B[_ix(do, L.S_VC, i)] = 0.0 if fixed else dvc
    B[_ix(do, L.S_XL, i)] = vl if cart else 0.0
    B[_ix(do, L.S_VL, i)] = dvl if cart else 0.0
    B[_ix(LL, 0, i)] = (loss_cart if cart else (c_rod * vc * vc if kind == L.LOAD_CONROD
                                                 else 0.0))
    B[_ix(PE, 0, i)] = f_ext * vl if cart else (f_ext * vc if free else 0.0)


@njit(cache=True, inline="always", error_model="numpy")
def _rates_lane(B, i, xo, do):
    """:func:`plant.kernel.derivatives` of lane ``i`` from the effect rows
    :func:`_effect_passes` (or :func:`_constant_rows`) left: the slopes into ``do``."""
    temp_on = _p(B, L.P_TEMP_ON, i) > 0.5
    t_oil = _p(B, L.S_TOIL, i, xo)
    r = B[_ix(VR, 0, i)]
    dp = _p(B, L.P_DP, i) * r
    ds = _p(B, L.P_DS, i) * r
    dc = _p(B, L.P_DC, i) * r
    vp = _p(B, L.S_VP, i, xo)
    vc = _p(B, L.S_VC, i, xo)
    tq = _p(B, L.S_TQ, i, xo)
    kc_kp = _p(B, L.P_KC_OVER_KP, i)
    theta_rotor = _p(B, L.S_THP, i, xo) * kc_kp
    mode = _p(B, L.IN_MODE, i, UO)
    # motor_dq.drive, DriveMode.DUTY (phase_angles of recipe >= 2, inverter legs)
    duty = mode == 0.0
    i_d = _p(B, L.S_ID, i, xo)
    i_q = _p(B, L.S_IQ, i, xo)
    pole_pairs = _p(B, L.P_POLE_PAIRS, i)
    th = pole_pairs * theta_rotor
    s, c = sincos3(th)
    c2 = -0.5 * c + SQRT3_2 * s
    s2 = -0.5 * s - SQRT3_2 * c
    i_a = i_d * c - i_q * s
    i_b = i_d * c2 - i_q * s2
    i_c = -i_a - i_b
    vdc = _p(B, L.P_VDC, i)
    d_min = _p(B, L.P_DUTY_MIN, i)
    d_max = _p(B, L.P_DUTY_MAX, i)
    dead_i = _p(B, L.P_DEAD_CURRENT, i)
    dead_f = _p(B, L.P_DEAD_FRAC, i)
    da = _p(B, L.IN_DA, i, UO)
    db = _p(B, L.IN_DB, i, UO)
    dd = _p(B, L.IN_DC, i, UO)
    da = d_min if da < d_min else (d_max if da > d_max else da)
    db = d_min if db < d_min else (d_max if db > d_max else db)
    dd = d_min if dd < d_min else (d_max if dd > d_max else dd)
    sa = i_a / dead_i
    sa = 1.0 if sa > 1.0 else (-1.0 if sa < -1.0 else sa)
    sb = i_b / dead_i
    sb = 1.0 if sb > 1.0 else (-1.0 if sb < -1.0 else sb)
    sc = i_c / dead_i
    sc = 1.0 if sc > 1.0 else (-1.0 if sc < -1.0 else sc)
    v_a = (da - 0.5) * vdc + -sa * dead_f * vdc
    v_b = (db - 0.5) * vdc + -sb * dead_f * vdc
    v_c = (dd - 0.5) * vdc + -sc * dead_f * vdc
    v_alpha = (2.0 * v_a - v_b - v_c) / 3.0
    v_beta = (v_b - v_c) / SQRT3
    v_d = v_alpha * c + v_beta * s
    v_q = -v_alpha * s + v_beta * c
    w_e = pole_pairs * vp * kc_kp
    res = _p(B, L.P_R, i)
    ind = _p(B, L.P_L, i)
    kt = _p(B, L.P_KT_EQ, i)
    did = (v_d - res * i_d + w_e * ind * i_q) / ind
    diq = (v_q - res * i_q - w_e * ind * i_d - w_e * _p(B, L.P_FLUX, i)) / ind
    B[_ix(do, L.S_ID, i)] = did if duty else 0.0
    B[_ix(do, L.S_IQ, i)] = diq if duty else 0.0
    p_elec = 1.5 * (v_d * i_d + v_q * i_q) if duty else 0.0
    p_copper = 1.5 * res * (i_d * i_d + i_q * i_q) if duty else 0.0
    tau_p = (kt * i_q if duty else (kt * _p(B, L.IN_IQ_REF, i, UO) if mode == 1.0 else (
        0.0 if mode == 3.0 else _p(B, L.IN_TAU_REF, i, UO))))
    # pump.ripple_and_friction (the Coulomb part from FC)
    f_cp = B[_ix(FC, 0, i)]
    ripple = sincos3(_p(B, L.P_PULS_ORDER, i) * theta_rotor + _p(B, L.P_PULS_PHASE, i))[0]
    puls = _p(B, L.P_PULS_ON, i) > 0.5
    g = 1.0 + _p(B, L.P_PULS_AMP, i) * ripple if puls else 1.0
    f_cp_puls = f_cp + (_p(B, L.P_PULS_TORQUE, i) + _p(B, L.P_PULS_TORQUE_REL, i) * tq) * ripple
    f_cp = f_cp_puls if puls else f_cp
    # pump.pump
    B[_ix(do, L.S_THP, i)] = vp
    B[_ix(do, L.S_VP, i)] = (tau_p - dp * vp - f_cp - g * tq) / _p(B, L.P_JP, i)
    # hydraulics.pressure_force (line_stiffness: the aerated one from KA)
    ks_series = series_stiffness_lane(B, i, _p(B, L.S_THC, i, xo))
    ks = pick(_p(B, L.P_AIR_ON, i) > 0.5, B[_ix(KA, 0, i)], ks_series)
    B[_ix(do, L.S_TQ, i)] = ks * (g * vp - tq / ds - vc)
    # load.piston_and_load: the seal friction from FS, the rest from LL and PE (the
    # slopes of the piston and the cart are in do already)
    f_seal = B[_ix(FS, 0, i)]
    loss_load = B[_ix(LL, 0, i)]
    p_ext = B[_ix(PE, 0, i)]
    # kernel.derivatives: heat into the oil; thermal.energy_and_heat
    heat_oil = dp * vp * vp + f_cp * vp + tq * tq / ds + dc * vc * vc + f_seal * vc
    B[_ix(do, L.S_EIN, i)] = p_elec if duty else tau_p * vp
    B[_ix(do, L.S_EDISS, i)] = heat_oil + loss_load + p_copper
    B[_ix(do, L.S_EEXT, i)] = p_ext
    t_amb = _p(B, L.IN_T_AMB, i, UO)
    d_toil = (heat_oil - _p(B, L.P_COOL_G, i) * (t_oil - t_amb)) / _p(B, L.P_HEAT_CAP, i)
    B[_ix(do, L.S_TOIL, i)] = d_toil if temp_on else 0.0
    B[_ix(do, L.S_TROD, i)] = (t_amb - _p(B, L.S_TROD, i, xo)) / _p(B, L.P_ROD_TAU, i)


@njit(cache=True, inline="always", error_model="numpy")
def derivatives_lanes(B, xo, do):
    """:func:`plant.kernel.derivatives` for every lane of the lane buffer ``B``: the
    states at ``xo``, the derivatives into ``do`` (offsets of :data:`X`, :data:`K1` ...)."""
    fx = batch_effects(B)
    _constant_rows(B, fx)
    _effect_passes(B, xo, do, fx)
    for i in range(LW):
        _rates_lane(B, i, xo, do)


@njit(cache=True, inline="always", error_model="numpy")
def rk4_stage(B, xo, do, fx, a):
    """One RK4 slope and the next intermediate state: the derivatives at ``xo`` into
    ``do``, then XT = X + (a h) k (a = 0.5: the scalar kernel's ``0.5 * h * k``; a = 1:
    ``h * k``, the product 1.0 * h being h exactly) in the same loop over the lanes (a loop
    over the states inside a loop over the lanes: LLVM vectorises the lanes; as loops of
    their own over the states, it unrolls them into scalar code)."""
    _effect_passes(B, xo, do, fx)
    for i in range(LW):
        _rates_lane(B, i, xo, do)
        ah = a * _p(B, L.P_H_SUB, i)
        for s in range(L.N_STATES):
            B[_ix(XT, s, i)] = B[_ix(X, s, i)] + ah * B[_ix(do, s, i)]


@njit(cache=True, inline="always", error_model="numpy")
def _rk4_last(B, fx, step):
    """The last slope of sub-step ``step``, the states' update (a lane with fewer sub-steps
    keeps its states) and the end stops, in the same loop over the lanes."""
    _effect_passes(B, XT, K4, fx)
    for i in range(LW):
        _rates_lane(B, i, XT, K4)
        h6 = _p(B, L.P_H_SUB, i) / 6.0
        live = step < _p(B, L.P_N_SUB, i)
        for s in range(L.N_STATES):
            x = B[_ix(X, s, i)]
            new = x + h6 * (B[_ix(K1, s, i)] + 2.0 * B[_ix(K2, s, i)]
                            + 2.0 * B[_ix(K3, s, i)] + B[_ix(K4, s, i)])
            B[_ix(X, s, i)] = new if live else x
        _end_stops_lane(B, i, live)


@njit(cache=True, inline="always", error_model="numpy")
def _end_stops_lane(B, i, live):
    """:func:`plant.blocks.load.end_stops` of lane ``i`` (not for a fixed load), if the
    lane takes this sub-step (``live``). Selects (:func:`~plant.blocks.lanemath.pick`)
    throughout: as conditional expressions LLVM keeps a branch around the dissipated
    energy's products and the loop over the lanes stays scalar."""
    on = live & (_p(B, L.P_LOAD_KIND, i) != L.LOAD_FIXED)
    half = _p(B, L.P_HALF_STROKE, i)
    v = B[_ix(X, L.S_VC, i)]
    x_c = B[_ix(X, L.S_THC, i)]
    e0 = B[_ix(X, L.S_EDISS, i)]
    hit = on & (((x_c > half) & (v > 0.0)) | ((x_c < -half) & (v < 0.0)))
    B[_ix(X, L.S_EDISS, i)] = pick(hit, e0 + 0.5 * _p(B, L.P_JC, i) * v * v, e0)
    B[_ix(X, L.S_VC, i)] = pick(hit, 0.0, v)
    clamped = pick(x_c > half, half, pick(x_c < -half, -half, x_c))
    B[_ix(X, L.S_THC, i)] = pick(on, clamped, x_c)


@njit(**LANES)
def rk4_lanes(B, n_sub_max):
    """:func:`plant.kernel.rk4_tick` for every lane of the lane buffer ``B`` (states at
    :data:`X`, parameters at :data:`PO`, inputs at :data:`UO`). All :data:`LW` lanes are
    computed, whether an actuator is in them or not (a loop of a fixed count of whole
    vectors, no scalar remainder; :func:`load_params` fills a free lane with a copy). A lane
    with fewer sub-steps than the batch's most (at most ``n_sub_max``) keeps its state
    through the extra ones (a select, so the others stay in one batch). An effect that no
    lane of the batch has on is not computed (:func:`batch_effects`): its lanes would all
    select the scalar code's value for it off, which :func:`_constant_rows` puts in its row
    once."""
    fx = batch_effects(B)
    _constant_rows(B, fx)
    for step in range(n_sub_max):
        if not step < fx[5]:
            break  # no lane takes this sub-step: every state would keep its value
        rk4_stage(B, X, K1, fx, 0.5)
        rk4_stage(B, XT, K2, fx, 0.5)
        rk4_stage(B, XT, K3, fx, 1.0)
        _rk4_last(B, fx, step)


@njit(**LANES)
def load_params(B, params, rows, n):
    """Parameters of the actuators ``rows[:n]`` (rows of ``params``) into lanes 0..n-1, and
    the last one's again into every free lane (computed, never stored back)."""
    for j in range(LW):
        i = min(j, n - 1)
        for k in range(L.N_PARAMS):
            B[_ix(PO, k, j)] = params[rows[i], k]


@njit(**LANES)
def load_states(B, x, u, rows, n):
    """States and inputs of the actuators ``rows[:n]`` into lanes 0..n-1 (and the last
    one's into the free lanes)."""
    for j in range(LW):
        r = rows[min(j, n - 1)]
        for k in range(L.N_STATES):
            B[_ix(X, k, j)] = x[r, k]
        for k in range(L.N_INPUTS):
            B[_ix(UO, k, j)] = u[r, k]


@njit(**LANES)
def store_states(B, x, rows, n):
    """The states of lanes 0..n-1 back into the rows ``rows[:n]`` of ``x``."""
    for i in range(n):
        r = rows[i]
        for k in range(L.N_STATES):
            x[r, k] = B[_ix(X, k, i)]


@njit(**LANES)
def store_inputs(B, u, rows, n):
    """The inputs of lanes 0..n-1 (the inverter's, :func:`hil.sim.actuator.drive_lanes`,
    writes them in the lanes) back into the rows ``rows[:n]`` of ``u``."""
    for i in range(n):
        r = rows[i]
        for k in range(L.N_INPUTS):
            u[r, k] = B[_ix(UO, k, i)]


def lane_buffer() -> np.ndarray:
    """A zeroed lane buffer (:data:`SIZE` doubles)."""
    return np.zeros(SIZE)


__all__ = ["LANES", "LW", "aerated_stiffness_lane", "batch_effects", "derivatives_lanes",
           "lane_buffer", "line_stiffness_lane", "load_params", "load_states", "rk4_lanes",
           "rk4_stage", "series_stiffness_lane", "store_inputs", "store_states",
           "viscosity_lane"]
