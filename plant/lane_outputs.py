"""The plant's outputs and sensor noise over many actuators at once, one per vector lane.

:func:`plant.kernel.outputs` fills one actuator's output row (its physical values, then
:func:`plant.sensors.readings.sense`: noise and converter resolution); here the same
arithmetic runs over the lanes of :mod:`plant.lanes`'s buffer, right after
:func:`plant.lanes.rk4_lanes` (the states, parameters and inputs are already there). Per
actuator it is the same operations in the same order: bit for bit the scalar call's result
(``tests/plant/test_lane_outputs.py``). Branches of the scalar code (drive mode, load kind,
drift, noise, quantisation) become selects between both sides, as in :mod:`plant.lanes`.

The noise: under recipe 4 (``sim.plant_numerics = 4``) each lane draws its seven samples
with :func:`plant.sensors.readings.gauss7_4` (Box-Muller with the recipe's own log and
sin/cos, a fixed count of operations), so that loop vectorises too; each lane's xorshift64*
state sits in the buffer (its bits, :data:`plant.lanes.RG`) for the call. Under recipes 2
and 3 the polar method's rejection loop runs a different number of times in each lane and
calls libm's log, so those lanes draw their samples one after the other with the scalar
:func:`~plant.sensors.readings._gauss_pair` (the same call as the scalar kernel); the rest
of the outputs stays in lanes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant import layout as L
from plant.blocks.lanemath import _bits, _from_bits, pick
from plant.blocks.motor_dq import phase_angles
from plant.lanes import (
    GO,
    KA,
    LANES,
    LW,
    RG,
    UO,
    VR,
    YO,
    _ix,
    _p,
    aerated_stiffness_lane,
    series_stiffness_lane,
    viscosity_lane,
)
from plant.lanes import X as XO
from plant.sensors.readings import _gauss_pair, gauss7_4

_DUTY = float(L.DriveMode.DUTY)
_CURRENT = float(L.DriveMode.CURRENT)
_FORCE = float(L.DriveMode.FORCE)


@njit(cache=True, inline="always")
def _x(B, k, i):
    """State ``k`` of lane ``i``."""
    return B[_ix(XO, k, i)]


@njit(cache=True, inline="always")
def _put(B, k, i, v):
    """Output ``k`` of lane ``i``."""
    B[_ix(YO, k, i)] = v


@njit(cache=True, inline="always", error_model="numpy")
def _physical_lanes(B):
    """:func:`plant.kernel.physical_outputs` (with :func:`~plant.kernel.stored_energy`) of
    every lane, into the output rows at :data:`plant.lanes.YO`. The viscosity ratio and the
    stiffness with entrained air are loops of their own into their rows of the buffer
    (``VR``, ``KA``), run only where some lane of the batch has the effect on (else every
    lane selects 1 and the series stiffness, the scalar code's values)."""
    temp = False
    air = False
    for i in range(LW):
        temp |= _p(B, L.P_TEMP_ON, i) > 0.5
        air |= _p(B, L.P_AIR_ON, i) > 0.5
    if temp:
        for i in range(LW):
            B[_ix(VR, 0, i)] = viscosity_lane(B, i, _x(B, L.S_TOIL, i))
    else:
        for i in range(LW):
            B[_ix(VR, 0, i)] = 1.0
    if air:
        for i in range(LW):
            B[_ix(KA, 0, i)] = aerated_stiffness_lane(B, i, _x(B, L.S_THC, i),
                                                      _x(B, L.S_TQ, i))
    for i in range(LW):
        kc = _p(B, L.P_KC, i)
        kc_kp = _p(B, L.P_KC_OVER_KP, i)
        kt = _p(B, L.P_KT_EQ, i)
        r = B[_ix(VR, 0, i)]
        mode = _p(B, L.IN_MODE, i, UO)
        current = mode == _CURRENT
        force = mode == _FORCE
        tau_ref = _p(B, L.IN_TAU_REF, i, UO)
        x_id = _x(B, L.S_ID, i)
        x_iq = _x(B, L.S_IQ, i)
        i_q = _p(B, L.IN_IQ_REF, i, UO) if current else (tau_ref / kt if force else x_iq)
        i_d = _p(B, L.IN_ID_REF, i, UO) if current else (0.0 if force else x_id)
        tau_p = tau_ref if force else kt * i_q
        theta_rotor = _x(B, L.S_THP, i) * kc_kp
        c, s, c2, s2 = phase_angles(_p(B, L.P_POLE_PAIRS, i) * theta_rotor, 3.0)
        i_a = i_d * c - i_q * s
        i_b = i_d * c2 - i_q * s2

        tq = _x(B, L.S_TQ, i)
        vc = _x(B, L.S_VC, i)
        x_c = _x(B, L.S_THC, i)
        vl = _x(B, L.S_VL, i)
        f_cyl = tq - _p(B, L.P_DC, i) * r * vc
        kind = _p(B, L.P_LOAD_KIND, i)
        conrod = kind == L.LOAD_CONROD
        cart = kind == L.LOAD_CART
        k_rod = _p(B, L.P_K_ROD, i)
        c_rod = _p(B, L.P_C_ROD, i)
        # load.rod_force
        rod_conrod = k_rod * (x_c - _p(B, L.P_X_ANCHOR, i)) + c_rod * vc
        rod_cart = k_rod * (x_c - _x(B, L.S_XL, i)) + c_rod * (vc - vl)
        rod = rod_conrod if conrod else (rod_cart if cart else 0.0)
        f_rod = f_cyl if kind == L.LOAD_FIXED else rod

        pre = _p(B, L.P_PRECHARGE, i)
        dp_pump = tq / kc
        dp_cyl = f_cyl / kc
        _put(B, L.Y_P_ACC, i, pre)
        _put(B, L.Y_P_PUMP_A, i, pre + (dp_pump if dp_pump > 0.0 else 0.0))
        _put(B, L.Y_P_PUMP_B, i, pre + (-dp_pump if dp_pump < 0.0 else 0.0))
        _put(B, L.Y_P_CYL_A, i, pre + (dp_cyl if dp_cyl > 0.0 else 0.0))
        _put(B, L.Y_P_CYL_B, i, pre + (-dp_cyl if dp_cyl < 0.0 else 0.0))
        t_rod = _x(B, L.S_TROD, i)
        drift = f_rod + _p(B, L.P_DRIFT_K, i) * (t_rod - _p(B, L.P_T_REF, i))
        _put(B, L.Y_F_STRAIN, i, drift if _p(B, L.P_DRIFT_ON, i) > 0.5 else f_rod)
        t_oil = _x(B, L.S_TOIL, i)
        vp = _x(B, L.S_VP, i)
        _put(B, L.Y_TEMP, i, t_oil)
        _put(B, L.Y_THETA_M, i, theta_rotor)
        _put(B, L.Y_OMEGA_M, i, vp * kc_kp)
        _put(B, L.Y_X_PISTON, i, x_c)
        _put(B, L.Y_V_PISTON, i, vc)
        _put(B, L.Y_TAU_P, i, tau_p)
        _put(B, L.Y_TAU_Q, i, tq)
        _put(B, L.Y_F_ROD, i, f_rod)
        _put(B, L.Y_IQ, i, i_q)
        _put(B, L.Y_ID, i, i_d)
        _put(B, L.Y_IA, i, i_a)
        _put(B, L.Y_IB, i, i_b)
        _put(B, L.Y_IC, i, -i_a - i_b)
        _put(B, L.Y_VP, i, vp)
        _put(B, L.Y_T_OIL, i, t_oil)
        _put(B, L.Y_T_ROD, i, t_rod)
        _put(B, L.Y_X_CART, i, _x(B, L.S_XL, i))
        _put(B, L.Y_E_IN, i, _x(B, L.S_EIN, i))
        _put(B, L.Y_E_DISS, i, _x(B, L.S_EDISS, i))
        _put(B, L.Y_E_EXT, i, _x(B, L.S_EEXT, i))
        # kernel.stored_energy (x ** 2 is x * x; the sums in the scalar code's order)
        e = 0.5 * _p(B, L.P_JP, i) * (vp * vp) + 0.5 * _p(B, L.P_JC, i) * (vc * vc)
        ks = pick(_p(B, L.P_AIR_ON, i) > 0.5, B[_ix(KA, 0, i)],
                  series_stiffness_lane(B, i, x_c))
        e += tq * tq / (2.0 * ks)
        d_anchor = x_c - _p(B, L.P_X_ANCHOR, i)
        d_cart = x_c - _x(B, L.S_XL, i)
        e_conrod = e + 0.5 * k_rod * (d_anchor * d_anchor)
        e_cart = e + (0.5 * k_rod * (d_cart * d_cart) + 0.5 * _p(B, L.P_M_CART, i) * (vl * vl))
        e = e_conrod if conrod else (e_cart if cart else e)
        e_duty = e + 0.75 * _p(B, L.P_L, i) * (x_id * x_id + x_iq * x_iq)
        _put(B, L.Y_E_STORED, i, e_duty if mode == _DUTY else e)


@njit(cache=True, inline="always", error_model="numpy")
def _noise_lanes(B):
    """Recipe 4's seven samples of every lane into the rows at :data:`plant.lanes.GO`; a
    lane's stream state moves on only where its noise is on under recipe 4. Not drawn at
    all where no lane has it on (no lane would read a sample or move its stream on)."""
    draw = False
    for i in range(LW):
        draw |= (_p(B, L.P_NOISE_ON, i) > 0.5) & (_p(B, L.P_NUMERICS, i) >= 4.0)
    if not draw:
        return
    for i in range(LW):
        s0 = np.uint64(_bits(B[RG + i]))
        s, g0, g1, g2, g3, g4, g5, g6 = gauss7_4(s0)
        on = (_p(B, L.P_NOISE_ON, i) > 0.5) & (_p(B, L.P_NUMERICS, i) >= 4.0)
        B[RG + i] = _from_bits(np.int64(s if on else s0))
        B[GO + i] = g0
        B[GO + LW + i] = g1
        B[GO + 2 * LW + i] = g2
        B[GO + 3 * LW + i] = g3
        B[GO + 4 * LW + i] = g4
        B[GO + 5 * LW + i] = g5
        B[GO + 6 * LW + i] = g6


@njit(cache=True, inline="always")
def _quantise(v, lsb):
    """:func:`plant.sensors.readings._quantise`'s arithmetic."""
    return math.floor(v / lsb + 0.5) * lsb


@njit(cache=True, inline="always", error_model="numpy")
def _sensed(B, k, g, i, sigma, noise, lsb, quant):
    """Output ``k`` of lane ``i`` with its noise sample (row ``g`` at :data:`plant.lanes.GO`)
    of size ``sigma`` added where the noise is on, then rounded to its converter's ``lsb``
    where quantisation is on."""
    v = B[_ix(YO, k, i)]
    noisy = v + sigma * B[_ix(GO, g, i)]
    v = noisy if noise else v
    B[_ix(YO, k, i)] = _quantise(v, lsb) if quant else v


@njit(cache=True, inline="always", error_model="numpy")
def _sense_lanes(B):
    """:func:`plant.sensors.readings.sense` of every lane: the samples at
    :data:`plant.lanes.GO` scaled onto their outputs where the noise is on, then the
    encoders' and converters' resolution where quantisation is on."""
    for i in range(LW):
        noise = _p(B, L.P_NOISE_ON, i) > 0.5
        quant = _p(B, L.P_QUANT_ON, i) > 0.5
        qm = _p(B, L.P_Q_MOTOR, i)
        qx = _p(B, L.P_Q_PISTON, i)
        th = B[_ix(YO, L.Y_THETA_M, i)]
        xp = B[_ix(YO, L.Y_X_PISTON, i)]
        B[_ix(YO, L.Y_THETA_M, i)] = math.floor(th / qm) * qm if quant else th
        B[_ix(YO, L.Y_X_PISTON, i)] = math.floor(xp / qx) * qx if quant else xp
        sp = _p(B, L.P_NOISE_P, i)
        lsb = _p(B, L.P_Q_PRESSURE, i)
        _sensed(B, L.Y_P_ACC, 0, i, sp, noise, lsb, quant)
        _sensed(B, L.Y_P_PUMP_A, 1, i, sp, noise, lsb, quant)
        _sensed(B, L.Y_P_PUMP_B, 2, i, sp, noise, lsb, quant)
        _sensed(B, L.Y_P_CYL_A, 3, i, sp, noise, lsb, quant)
        _sensed(B, L.Y_P_CYL_B, 4, i, sp, noise, lsb, quant)
        _sensed(B, L.Y_F_STRAIN, 5, i, _p(B, L.P_NOISE_F, i), noise, _p(B, L.P_Q_STRAIN, i),
                quant)
        _sensed(B, L.Y_TEMP, 6, i, _p(B, L.P_NOISE_T, i), noise, _p(B, L.P_Q_TEMP, i), quant)


@njit(**LANES)
def load_outputs(B, y, rng, rows, n):
    """The output rows ``rows[:n]`` of ``y`` and their noise streams (rows of ``rng``,
    (actuators, 1) uint64) into lanes 0..n-1 (the last one's into the free lanes): where
    the outputs stay from tick to tick for a kernel call (:func:`outputs_in_lanes` renews
    them, the sensor chips read them there)."""
    for j in range(LW):
        r = rows[min(j, n - 1)]
        for k in range(L.N_OUTPUTS):
            B[_ix(YO, k, j)] = y[r, k]
        B[RG + j] = _from_bits(np.int64(rng[r, 0]))


@njit(**LANES)
def outputs_in_lanes(B, rng, rows, n):
    """:func:`plant.kernel.outputs` of every lane of the lane buffer ``B`` (states,
    parameters and inputs where :func:`plant.lanes.rk4_lanes` left them), the outputs into
    the rows at :data:`plant.lanes.YO`, the noise streams' states kept at
    :data:`plant.lanes.RG`. A lane of the actuator ``rows[j]`` under recipe 2 or 3 draws on
    its row of ``rng`` (its state moved there and back)."""
    _physical_lanes(B)
    _noise_lanes(B)
    for j in range(n):  # recipes 2 and 3: the polar method, lane by lane (see module doc)
        if _p(B, L.P_NOISE_ON, j) > 0.5 and _p(B, L.P_NUMERICS, j) < 4.0:
            r = rng[rows[j]]
            r[0] = np.uint64(_bits(B[RG + j]))
            for q in range(3):
                a, b = _gauss_pair(r)
                B[_ix(GO, 2 * q, j)] = a
                B[_ix(GO, 2 * q + 1, j)] = b
            B[_ix(GO, 6, j)] = _gauss_pair(r)[0]
            B[RG + j] = _from_bits(np.int64(r[0]))
    _sense_lanes(B)


@njit(**LANES)
def store_outputs(B, y, rng, rows, n):
    """The outputs and noise streams of lanes 0..n-1 back into the rows ``rows[:n]`` of
    ``y`` and ``rng`` (:func:`load_outputs`'s reverse)."""
    for j in range(n):
        r = rows[j]
        for k in range(L.N_OUTPUTS):
            y[r, k] = B[_ix(YO, k, j)]
        rng[r, 0] = np.uint64(_bits(B[RG + j]))


@njit(**LANES)
def outputs_lanes(B, y, rng, rows, n):
    """:func:`plant.kernel.outputs` of lanes 0..n-1 of the lane buffer ``B`` (states,
    parameters and inputs where :func:`plant.lanes.rk4_lanes` left them) into the rows
    ``rows[:n]`` of ``y``; the noise streams are the rows ``rows[:n]`` of ``rng``
    ((actuators, 1) uint64). Every lane is computed; the free ones are never stored. (The
    robot kernel keeps outputs and streams in the lanes for a whole call instead:
    :func:`load_outputs`, :func:`outputs_in_lanes`, :func:`store_outputs`.)"""
    load_outputs(B, y, rng, rows, n)
    outputs_in_lanes(B, rng, rows, n)
    store_outputs(B, y, rng, rows, n)


__all__ = ["load_outputs", "outputs_in_lanes", "outputs_lanes", "store_outputs"]
