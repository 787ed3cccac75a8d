"""The fast model's tangent-linear simulation: the states and their derivatives with respect
to a fit's free parameters, in one run (forward sensitivities, discrete tangent).

:func:`_simulate` (hil.identify.model) advances the states over each sub-step by a map
``z' = Phi(z, p)``: the exactly discretised linear part, the effects' inputs from the state
at the sub-step's start, the Heun correction of a position-dependent k_s, and the frictions'
implicit solves. :func:`_tangent` runs the same map and beside it, for every column ``j``, the
derivative ``S_j = dz/dx_j`` by the chain rule through it:

    S_j' = dPhi/dz S_j + dPhi/dp dp/dx_j

differentiating what the code computes, not the ODE, so that ``z + h S_j`` is the forward
difference's simulation at ``x + h e_j`` to first order in ``h``. The frictions' roots are
differentiated implicitly (``v = v_free - b F(v)``: ``dv = (dv_free - db F - b F_p) /
(1 + b F'(v))``); a root the solve returned linearised is the root to the solve's tolerance,
and its derivative is taken at it.

The extra work per sub-step is independent multiply-adds across the columns (the innermost
loops run over them, contiguous), which fill the slots the state's serial chain leaves idle.
The parameter partials the map takes (of the discretised matrices, of the start state, of the
applied force, of the effect inputs) are computed outside, in Python, without a simulation
(:func:`state_sensitivities`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hil.identify.model import (
    _E_ALPHA,
    _E_H_SUB,
    _E_HALF,
    _E_K1,
    _E_K2,
    _E_KC_KP,
    _E_PC,
    _E_PC_EPS,
    _E_PC_SHAPE,
    _E_PULS,
    _E_SF_C,
    _E_SF_EPS,
    _E_SF_S,
    _E_SF_SHAPE,
    _E_SF_VS,
    _E_SOLVE_TOL,
    _E_VISC,
    _FAST,
    _LINEAR_IDX,
    IDX,
    FastModel,
    _initial_state,
    _solve_friction,
    continuous,
)


@njit(cache=True, nogil=True, fastmath=_FAST)
def _sign_partials(u, w):
    """The sign law of ``_friction_sign`` at ``u``: its value, its slope in ``u`` and its
    derivative in the shape ``w`` (the atan law less the tanh law)."""
    t = math.exp(-2.0 * abs(u))
    th = (1.0 - t) / (1.0 + t)
    if u < 0.0:
        th = -th
    q = 0.5 * math.pi * u
    at = (2.0 / math.pi) * math.atan(q)
    s = (1.0 - w) * th + w * at
    ds = (1.0 - w) * (1.0 - th * th) + w / (1.0 + q * q)
    return s, ds, at - th


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _columns_product(ad, bd, dz, du, dzn, npar):
    """``dzn = ad dz + bd du`` column by column (all five states: a fixed piston's last two
    rows and columns are those of the identity and zero, and so are their derivatives)."""
    a00, a01, a02, a03, a04 = ad[0, 0], ad[0, 1], ad[0, 2], ad[0, 3], ad[0, 4]
    a10, a11, a12, a13, a14 = ad[1, 0], ad[1, 1], ad[1, 2], ad[1, 3], ad[1, 4]
    a20, a21, a22, a23, a24 = ad[2, 0], ad[2, 1], ad[2, 2], ad[2, 3], ad[2, 4]
    a30, a31, a32, a33, a34 = ad[3, 0], ad[3, 1], ad[3, 2], ad[3, 3], ad[3, 4]
    a40, a41, a42, a43, a44 = ad[4, 0], ad[4, 1], ad[4, 2], ad[4, 3], ad[4, 4]
    b00, b01, b02, b03 = bd[0, 0], bd[0, 1], bd[0, 2], bd[0, 3]
    b10, b11, b12, b13 = bd[1, 0], bd[1, 1], bd[1, 2], bd[1, 3]
    b20, b21, b22, b23 = bd[2, 0], bd[2, 1], bd[2, 2], bd[2, 3]
    b30, b31, b32, b33 = bd[3, 0], bd[3, 1], bd[3, 2], bd[3, 3]
    b40, b41, b42, b43 = bd[4, 0], bd[4, 1], bd[4, 2], bd[4, 3]
    for j in range(npar):
        d0 = dz[0, j]
        d1 = dz[1, j]
        d2 = dz[2, j]
        d3 = dz[3, j]
        d4 = dz[4, j]
        w0 = du[0, j]
        w1 = du[1, j]
        w2 = du[2, j]
        w3 = du[3, j]
        dzn[0, j] = (a00 * d0 + a01 * d1 + a02 * d2 + a03 * d3 + a04 * d4
                     + b00 * w0 + b01 * w1 + b02 * w2 + b03 * w3)
        dzn[1, j] = (a10 * d0 + a11 * d1 + a12 * d2 + a13 * d3 + a14 * d4
                     + b10 * w0 + b11 * w1 + b12 * w2 + b13 * w3)
        dzn[2, j] = (a20 * d0 + a21 * d1 + a22 * d2 + a23 * d3 + a24 * d4
                     + b20 * w0 + b21 * w1 + b22 * w2 + b23 * w3)
        dzn[3, j] = (a30 * d0 + a31 * d1 + a32 * d2 + a33 * d3 + a34 * d4
                     + b30 * w0 + b31 * w1 + b32 * w2 + b33 * w3)
        dzn[4, j] = (a40 * d0 + a41 * d1 + a42 * d2 + a43 * d3 + a44 * d4
                     + b40 * w0 + b41 * w1 + b42 * w2 + b43 * w3)


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _linear_partials(dad, dbd, z, u, dzn, n_lin):
    """``dzn += dad z + dbd u`` for the columns that move the linear part (the first
    ``n_lin``)."""
    z0, z1, z2, z3, z4 = z[0], z[1], z[2], z[3], z[4]
    u0, u1, u2, u3 = u[0], u[1], u[2], u[3]
    for i in range(5):
        for j in range(n_lin):
            dzn[i, j] += (dad[i, 0, j] * z0 + dad[i, 1, j] * z1 + dad[i, 2, j] * z2
                          + dad[i, 3, j] * z3 + dad[i, 4, j] * z4 + dbd[i, 0, j] * u0
                          + dbd[i, 1, j] * u1 + dbd[i, 2, j] * u2 + dbd[i, 3, j] * u3)


@njit(cache=True, nogil=True, fastmath=_FAST)
def _tangent(ad, bd, z0, tau_p, ks, ds, dp, dc, eff, angle, has_angle, xs, has_x, temp,
             has_temp, t_ref, n_sub, fixed, adh, bdh, dad, dbd, dadh, dbdh, dks, dds, ddp,
             ddc, dz0, dtau, tau_cols, sel, sens):
    """Run the model over ``sens.shape[0]`` samples, ``sens[k, :, j]`` getting the derivative
    of the state at sample ``k`` along column ``j`` (``P = sens.shape[2]`` columns).

    The first arguments are :func:`_simulate`'s. Per column ``j``: ``dad, dbd, dadh, dbdh``
    (5 x 5 or 5 x 4 x L) the discretised matrices' derivatives, for the first ``L`` columns
    only (the columns are ordered so that those moving the linear part come first);
    ``dks, dds, ddp, ddc`` (P) the scalars' derivatives; ``dz0`` (5 x P) the start state's;
    ``dtau`` (T x sub-steps) the applied force's for the columns ``tau_cols`` (T); ``sel``
    (effect inputs x P) the effect inputs' derivatives.
    """
    n = sens.shape[0]
    npar = sens.shape[2]
    n_lin = dad.shape[2]
    n_tau = tau_cols.shape[0]
    ns = 3 if fixed else 5
    z = z0.copy()
    zn = np.zeros(5)
    u = np.zeros(4)
    dz = dz0.copy()
    dzn = np.zeros((5, npar))
    du = np.zeros((4, npar))
    doff = np.zeros(npar)
    dg = np.zeros(npar)
    dr = np.zeros(npar)
    dkse = np.zeros(npar)
    dqr = np.zeros(npar)
    ddq = np.zeros(npar)
    dfp = np.zeros(npar)
    dvm = np.zeros(npar)
    dfs = np.zeros(npar)
    sm = np.zeros(8)
    cm = np.zeros(8)
    n_ord = 0
    for m in range(8):
        for i in range(4):
            if eff[_E_PULS + 4 * m + i] != 0.0:
                n_ord = m + 1
    # columns that move a pulsation coefficient directly (their direct term is skipped
    # otherwise: 32 products per column and sub-step)
    puls_cols = False
    for e in range(32):
        for j in range(npar):
            if sel[_E_PULS + e, j] != 0.0:
                puls_cols = True
    pc = eff[_E_PC]
    sf_c = eff[_E_SF_C]
    sf_s = eff[_E_SF_S]
    sf_on = (sf_c != 0.0 or sf_s != 0.0) and not fixed
    k1 = eff[_E_K1]
    k2 = eff[_E_K2]
    ksx_on = k1 != 0.0 or k2 != 0.0
    visc = eff[_E_VISC]
    kc_kp = eff[_E_KC_KP]
    half = eff[_E_HALF]
    h_sub = eff[_E_H_SUB]
    alpha = eff[_E_ALPHA]
    solve_tol = eff[_E_SOLVE_TOL]
    visc_on = visc != 0.0 and has_temp
    inputs_on = n_ord > 0 or ksx_on or visc_on
    offset = angle[0] - z[0] * kc_kp if has_angle else 0.0
    if has_angle:
        for j in range(npar):
            doff[j] = -kc_kp * dz[0, j]
    fp = 0.0
    fs = 0.0
    fp_prev = 0.0
    fs_prev = 0.0
    for k in range(n):
        for i in range(5):
            for j in range(npar):
                sens[k, i, j] = dz[i, j]
        if k == n - 1:
            break
        r = 1.0
        if visc_on:
            r = math.exp(-visc * (temp[k] - t_ref))
            dtr = -(temp[k] - t_ref) * r
            for j in range(npar):
                dr[j] = dtr * sel[_E_VISC, j]
        for jj in range(n_sub):
            vp = z[1]
            tq = z[2]
            vc = z[4]
            f_pump = 0.0
            f_pist = 0.0
            g = 1.0
            for j in range(npar):
                du[1, j] = 0.0
                du[3, j] = 0.0
            if n_ord > 0:
                th = (z[0] + 0.5 * h_sub * vp) * kc_kp + offset
                s1 = math.sin(th)
                c1 = math.cos(th)
                s = s1
                c = c1
                ripple = 0.0
                torque = 0.0
                d_ripple = 0.0  # their slopes in the angle
                d_torque = 0.0
                for m in range(n_ord):
                    base = _E_PULS + 4 * m
                    ripple += eff[base] * s + eff[base + 1] * c
                    torque += eff[base + 2] * s + eff[base + 3] * c
                    d_ripple += (m + 1) * (eff[base] * c - eff[base + 1] * s)
                    d_torque += (m + 1) * (eff[base + 2] * c - eff[base + 3] * s)
                    sm[m] = s
                    cm[m] = c
                    s, c = s * c1 + c * s1, c * c1 - s * s1
                g = 1.0 + ripple
                f_pump -= ripple * tq + torque
                for j in range(npar):
                    dth = (dz[0, j] + 0.5 * h_sub * dz[1, j]) * kc_kp + doff[j]
                    dg[j] = d_ripple * dth
                    du[1, j] = -(d_torque * dth)
                if puls_cols:
                    for m in range(n_ord):
                        base = _E_PULS + 4 * m
                        for j in range(npar):
                            dg[j] += sel[base, j] * sm[m] + sel[base + 1, j] * cm[m]
                            du[1, j] -= sel[base + 2, j] * sm[m] + sel[base + 3, j] * cm[m]
                for j in range(npar):
                    du[1, j] -= dg[j] * tq + ripple * dz[2, j]
            if r != 1.0:
                f_pump -= dp * (r - 1.0) * vp
                f_pist -= dc * (r - 1.0) * vc
                for j in range(npar):
                    du[1, j] -= (ddp[j] * (r - 1.0) * vp + dp * dr[j] * vp
                                 + dp * (r - 1.0) * dz[1, j])
                    du[3, j] = -(ddc[j] * (r - 1.0) * vc + dc * dr[j] * vc
                                 + dc * (r - 1.0) * dz[4, j])
            ks_eff = ks
            q_rate = 0.0
            if ksx_on or g != 1.0 or r != 1.0:
                if ksx_on:
                    xpos = xs[k] if has_x else z[3]
                    xn = xpos / half
                    den = 1.0 + k1 * xn + k2 * xn * xn
                    ks_eff = ks / max(den, 0.05)
                    if den > 0.05:
                        slope = (k1 + 2.0 * k2 * xn) / half
                        for j in range(npar):
                            dden = sel[_E_K1, j] * xn + sel[_E_K2, j] * xn * xn
                            if not has_x:
                                dden += slope * dz[3, j]
                            dkse[j] = dks[j] / den - ks * dden / (den * den)
                    else:
                        for j in range(npar):
                            dkse[j] = dks[j] / 0.05
                else:
                    for j in range(npar):
                        dkse[j] = dks[j]
                q_rate = ks_eff * (g * vp - tq / (ds * r) - vc) - ks * (vp - tq / ds - vc)
                a1 = g * vp - tq / (ds * r) - vc
                a2 = vp - tq / ds - vc
                dsr = ds * r
                for j in range(npar):
                    da1 = (dg[j] * vp + g * dz[1, j] - dz[2, j] / dsr
                           + tq * (dds[j] * r + ds * dr[j]) / (dsr * dsr) - dz[4, j])
                    da2 = dz[1, j] - dz[2, j] / ds + tq * dds[j] / (ds * ds) - dz[4, j]
                    dqr[j] = dkse[j] * a1 + ks_eff * da1 - dks[j] * a2 - ks * da2
            else:
                for j in range(npar):
                    dqr[j] = 0.0
            u[0] = tau_p[k * n_sub + jj]
            u[1] = f_pump
            u[2] = q_rate
            u[3] = f_pist
            for j in range(npar):
                du[0, j] = 0.0
                du[2, j] = dqr[j]
            for t in range(n_tau):
                du[0, tau_cols[t]] = dtau[t, k * n_sub + jj]
            for i in range(ns):
                acc = 0.0
                for m in range(ns):
                    acc += ad[i, m] * z[m]
                acc += bd[i, 0] * u[0]
                if inputs_on:
                    for m in range(1, 4):
                        acc += bd[i, m] * u[m]
                zn[i] = acc
            # the columns' products: one pass along the columns (contiguous, vectorised)
            # with the matrices' entries in registers, every state row written once
            _columns_product(ad, bd, dz, du, dzn, npar)
            if n_lin > 0:
                _linear_partials(dad, dbd, z, u, dzn, n_lin)
            dq = 0.0
            if ksx_on:
                q_end = (ks_eff * (g * zn[1] - zn[2] / (ds * r) - zn[4])
                         - ks * (zn[1] - zn[2] / ds - zn[4]))
                dq = 0.5 * (q_end - q_rate)
                b1 = g * zn[1] - zn[2] / (ds * r) - zn[4]
                b2 = zn[1] - zn[2] / ds - zn[4]
                dsr = ds * r
                for j in range(npar):
                    db1 = (dg[j] * zn[1] + g * dzn[1, j] - dzn[2, j] / dsr
                           + zn[2] * (dds[j] * r + ds * dr[j]) / (dsr * dsr) - dzn[4, j])
                    db2 = dzn[1, j] - dzn[2, j] / ds + zn[2] * dds[j] / (ds * ds) - dzn[4, j]
                    ddq[j] = 0.5 * (dkse[j] * b1 + ks_eff * db1 - dks[j] * b2 - ks * db2
                                    - dqr[j])
                for i in range(ns):
                    zn[i] += bd[i, 2] * dq
                    for j in range(npar):
                        dzn[i, j] += bd[i, 2] * ddq[j]
                    for j in range(n_lin):
                        dzn[i, j] += dbd[i, 2, j] * dq
            if pc != 0.0:
                f_start = 2.0 * fp - fp_prev
                fp_prev = fp
                vnew, fp = _solve_friction(zn[1], bd[1, 1], pc, pc, 0.0, eff[_E_PC_EPS],
                                           eff[_E_PC_SHAPE], f_start, solve_tol)
                eps = eff[_E_PC_EPS]
                uu = vnew / eps
                sg, dsg, dsw = _sign_partials(uu, eff[_E_PC_SHAPE])
                fprime = pc * dsg / eps
                f_eps = -pc * dsg * uu / eps
                f_w = pc * dsw
                b = bd[1, 1]
                den_v = 1.0 + b * fprime
                for j in range(npar):
                    direct = sg * sel[_E_PC, j] + f_eps * sel[_E_PC_EPS, j] + f_w * sel[
                        _E_PC_SHAPE, j]
                    dvf = dzn[1, j] - b * direct
                    if j < n_lin:
                        dvf -= dbd[1, 1, j] * fp
                    dfp[j] = fprime * (dvf / den_v) + direct
                for i in range(ns):
                    zn[i] -= bd[i, 1] * fp
                    for j in range(npar):
                        dzn[i, j] -= bd[i, 1] * dfp[j]
                    for j in range(n_lin):
                        dzn[i, j] -= dbd[i, 1, j] * fp
            else:
                for j in range(npar):
                    dfp[j] = 0.0
            if sf_on:
                vmid = -bdh[4, 1] * fp
                for m in range(ns):
                    vmid += adh[4, m] * z[m]
                vmid += bdh[4, 0] * u[0]
                if inputs_on:
                    for m in range(1, 4):
                        vmid += bdh[4, m] * u[m]
                if ksx_on:
                    vmid += bdh[4, 2] * 0.5 * dq
                for j in range(npar):
                    dvm[j] = -bdh[4, 1] * dfp[j] + bdh[4, 0] * du[0, j]
                for m in range(ns):
                    a_m = adh[4, m]
                    for j in range(npar):
                        dvm[j] += a_m * dz[m, j]
                if inputs_on:
                    for m in range(1, 4):
                        b_m = bdh[4, m]
                        for j in range(npar):
                            dvm[j] += b_m * du[m, j]
                if ksx_on:
                    for j in range(npar):
                        dvm[j] += bdh[4, 2] * 0.5 * ddq[j]
                for j in range(n_lin):
                    dvm[j] -= dbdh[4, 1, j] * fp
                for m in range(ns):
                    zm = z[m]
                    for j in range(n_lin):
                        dvm[j] += dadh[4, m, j] * zm
                for m in range(4):
                    um = u[m]
                    for j in range(n_lin):
                        dvm[j] += dbdh[4, m, j] * um
                if ksx_on:
                    for j in range(n_lin):
                        dvm[j] += dbdh[4, 2, j] * 0.5 * dq
                f_start = 2.0 * fs - fs_prev
                fs_prev = fs
                vs = eff[_E_SF_VS]
                eps = eff[_E_SF_EPS]
                vnew, fs = _solve_friction(vmid, bdh[4, 3], sf_c, sf_s, vs, eps,
                                           eff[_E_SF_SHAPE], f_start, solve_tol)
                uu = vnew / eps
                sg, dsg, dsw = _sign_partials(uu, eff[_E_SF_SHAPE])
                q = vnew / vs
                ex = math.exp(-q * q)
                lev = sf_c + (sf_s - sf_c) * ex
                fprime = lev * dsg / eps + sg * (sf_s - sf_c) * ex * (-2.0 * q / vs)
                f_c = (1.0 - ex) * sg
                f_s = ex * sg
                f_vs = sg * (sf_s - sf_c) * ex * 2.0 * q * q / vs
                f_eps = -lev * dsg * uu / eps
                f_w = lev * dsw
                b = bdh[4, 3]
                den_v = 1.0 + b * fprime
                for j in range(npar):
                    direct = (f_c * sel[_E_SF_C, j] + f_s * sel[_E_SF_S, j]
                              + f_vs * sel[_E_SF_VS, j] + f_eps * sel[_E_SF_EPS, j]
                              + f_w * sel[_E_SF_SHAPE, j])
                    dvf = dvm[j] - b * direct
                    if j < n_lin:
                        dvf -= dbdh[4, 3, j] * fs
                    dfs[j] = fprime * (dvf / den_v) + direct
                for i in range(ns):
                    zn[i] -= bd[i, 3] * fs
                    b_i = bd[i, 3]
                    for j in range(npar):
                        dzn[i, j] -= b_i * dfs[j]
                    for j in range(n_lin):
                        dzn[i, j] -= dbd[i, 3, j] * fs
            for i in range(ns):
                z[i] = zn[i]
            # (a copy: swapping the two arrays' names costs reference counting every
            # sub-step, a fifth of a linear model's tangent)
            for i in range(5):
                for j in range(npar):
                    dz[i, j] = dzn[i, j]
        if has_angle:
            offset += alpha * (angle[k + 1] - z[0] * kc_kp - offset)
            for j in range(npar):
                doff[j] += alpha * (-kc_kp * dz[0, j] - doff[j])


# --- the parameter partials and the call ---------------------------------------------------


#: Parameters that reach the simulation through the applied force.
_FORCE_IDX = (IDX["gain_n_per_a"], IDX["skew_s"], IDX["delay_s"])


def expm_derivatives(m: np.ndarray, dms: np.ndarray, h: float) -> np.ndarray:
    """The derivatives of ``expm(m h)`` along each ``dms[j]`` (``dms``: P x n x n): the
    Taylor series of the exponential and its derivative, ``S_k = (S_{k-1} a + T_{k-1} da)
    / k`` beside ``T_k = T_{k-1} a / k``, on ``h / 2^s`` with ``|m h / 2^s|_1 <= 1/2``, then
    the squarings ``D <- D E + E D``, ``E <- E E``. (scipy's Pade exponential takes ~8 ms
    on a free piston's Van Loan block, its intermediate powers running into subnormal
    numbers: a Jacobian's eight linear columns would spend a tenth of a second in it.)"""
    a = m * h
    norm = float(np.abs(a).sum(axis=0).max())
    squarings = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 0.5 ** squarings
    a = a * scale
    da = dms * (h * scale)
    e = np.eye(m.shape[0])
    t = e.copy()
    d = np.zeros_like(da)
    s = np.zeros_like(da)
    for k in range(1, 15):  # (1/2)^15 / 15! = 2e-17
        s = (s @ a + t @ da) / k
        t = t @ a / k
        e = e + t
        d = d + s
    for _ in range(squarings):
        d = d @ e + e @ d
        e = e @ e
    return d


def _switches(model: FastModel, theta: np.ndarray) -> tuple:
    """The kernel's code paths for ``theta``: which effects run, how many pulsation orders,
    which friction shapes come from the preset. A column whose step changes one of them is
    no derivative of the path (a friction switched on by its step): it is simulated."""
    eff = model.effect_array(theta)
    n_ord = max((m + 1 for m in range(8) if np.any(eff[4 * m: 4 * m + 4] != 0.0)), default=0)
    return (n_ord, eff[_E_PC] != 0.0, eff[_E_SF_C] != 0.0 or eff[_E_SF_S] != 0.0,
            eff[_E_K1] != 0.0 or eff[_E_K2] != 0.0, eff[_E_VISC] != 0.0,
            theta[IDX["pc_eps_m_per_s"]] == 0.0, theta[IDX["sf_vs_m_per_s"]] == 0.0,
            theta[IDX["sf_eps_m_per_s"]] == 0.0)


def effects_on(model: FastModel, theta: np.ndarray) -> bool:
    """True when the simulation of ``theta`` runs an effect (a friction's solve, the
    pulsation, k_s(x), a viscosity law): only then does one tangent simulation cost less
    than the columns' simulations; the linear model's sub-step is a few multiply-adds,
    and its columns are cheaper simulated."""
    n_ord, pc, sf, ksx, visc = _switches(model, theta)[:5]
    return n_ord > 0 or pc or sf or ksx or visc

def on_path(model: FastModel, theta: np.ndarray, plus: np.ndarray, minus: np.ndarray) -> bool:
    """True when the column from ``minus`` to ``plus`` keeps ``theta``'s code paths."""
    here = _switches(model, theta)
    return _switches(model, plus) == here and _switches(model, minus) == here


def state_sensitivities(model: FastModel, theta: np.ndarray, plus: list[np.ndarray],
                        minus: list[np.ndarray], steps: np.ndarray, n_stop: int | None
                        ) -> list[np.ndarray]:
    """``S[j] = dz/dx_j`` (samples x 5, a view each) along the columns that move ``theta`` to
    ``plus[j]`` and ``minus[j]`` by ``+-steps[j]`` in their coordinate: the parameter
    partials as central differences of the kernel's inputs (no simulation; the input's
    timing forward, to ``plus[j]`` only), the states' by one tangent-linear simulation of
    the first ``n_stop`` samples."""
    exp = model.exp
    h = exp.dt / model.n_sub
    ad, bd, adh, bdh, z0, tau_p, eff = model.kernel_inputs(theta)
    n_col = len(plus)
    lin_idx = list(_LINEAR_IDX)
    moves_lin = [bool(np.any(plus[j][lin_idx] != minus[j][lin_idx])) for j in range(n_col)]
    moves_force = [bool(np.any(plus[j][list(_FORCE_IDX)] != minus[j][list(_FORCE_IDX)]))
                   for j in range(n_col)]
    order = [j for j in range(n_col) if moves_lin[j]] + [j for j in range(n_col)
                                                          if not moves_lin[j]]
    n_lin = sum(moves_lin)
    dad = np.zeros((5, 5, n_lin))
    dbd = np.zeros((5, 4, n_lin))
    dadh = np.zeros((5, 5, n_lin))
    dbdh = np.zeros((5, 4, n_lin))
    dks = np.zeros(n_col)
    dds = np.zeros(n_col)
    ddp = np.zeros(n_col)
    ddc = np.zeros(n_col)
    dz0 = np.zeros((5, n_col))
    sel = np.zeros((eff.size, n_col))
    tau_cols = []
    dtau = []
    # the continuous (A, B)'s derivatives, as Van Loan blocks, of the linear part's columns
    d_big = np.zeros((n_lin, 9, 9))

    def force(th: np.ndarray) -> np.ndarray:
        return th[IDX["gain_n_per_a"]] * model.applied_current(
            th[IDX["delay_s"]] + th[IDX["skew_s"]])

    for c, j in enumerate(order):
        tp, tm, two = plus[j], minus[j], 2.0 * steps[j]
        if moves_lin[j]:
            ap, bp = continuous(tp, exp)
            am, bm = continuous(tm, exp)
            d_big[c, :5, :5] = (ap - am) / two
            d_big[c, :5, 5:] = (bp - bm) / two
        timing = moves_force[j] and (tp[IDX["delay_s"]] + tp[IDX["skew_s"]]
                                     != theta[IDX["delay_s"]] + theta[IDX["skew_s"]])
        if timing:
            # the input's timing forward only, as the simulated column had it: the
            # band-limited sub-step average is 10-15 ms a delay, a second one per
            # Jacobian was a twentieth of a free piston's record
            fp = force(tp)
            tau_cols.append(c)
            dtau.append((fp - tau_p) / steps[j])
            ap, bp = continuous(tp, exp)
            zp = _initial_state(ap, bp, np.array([fp[0], 0.0, 0.0, 0.0]), exp.load)
            dz0[:, c] = (zp - z0) / steps[j]
        elif moves_lin[j] or moves_force[j]:
            if moves_force[j]:  # the gain: the force is linear in it
                fp, fm = force(tp), force(tm)
                tau_cols.append(c)
                dtau.append((fp - fm) / two)
                u0p, u0m = fp[0], fm[0]
            else:
                u0p = u0m = tau_p[0]
            ap, bp = continuous(tp, exp)
            am, bm = continuous(tm, exp)
            zp = _initial_state(ap, bp, np.array([u0p, 0.0, 0.0, 0.0]), exp.load)
            zm = _initial_state(am, bm, np.array([u0m, 0.0, 0.0, 0.0]), exp.load)
            dz0[:, c] = (zp - zm) / two
        for arr, name in ((dks, "ks"), (dds, "ds"), (ddp, "dp"), (ddc, "dc")):
            arr[c] = (tp[IDX[name]] - tm[IDX[name]]) / two
        sel[:, c] = (model.effect_array(tp) - model.effect_array(tm)) / two
    if n_lin:
        a, b = continuous(theta, exp)
        big = np.zeros((9, 9))
        big[:5, :5] = a
        big[:5, 5:] = b
        d_half = expm_derivatives(big, d_big, 0.5 * h)
        dadh[:] = d_half[:, :5, :5].transpose(1, 2, 0)
        dbdh[:] = d_half[:, :5, 5:].transpose(1, 2, 0)
        # the full sub-step is the half one's square ([Ad Bd; 0 I] = [Adh Bdh; 0 I]^2)
        dad[:] = (d_half[:, :5, :5] @ adh + adh @ d_half[:, :5, :5]).transpose(1, 2, 0)
        dbd[:] = (d_half[:, :5, :5] @ bdh + adh @ d_half[:, :5, 5:]
                  + d_half[:, :5, 5:]).transpose(1, 2, 0)
    n_run = exp.n if n_stop is None else max(2, min(n_stop, exp.n))
    sens = np.empty((n_run, 5, n_col))  # (every sample is written)
    e = np.zeros(1)
    _tangent(ad, bd, z0, tau_p, theta[IDX["ks"]], theta[IDX["ds"]], theta[IDX["dp"]],
             theta[IDX["dc"]], eff,
             exp.angle if exp.angle is not None else e, exp.angle is not None,
             exp.position if exp.position is not None else e, exp.position is not None,
             exp.temperature if exp.temperature is not None else e,
             exp.temperature is not None, exp.t_ref, model.n_sub, exp.load == "fixed",
             adh, bdh, dad, dbd, dadh, dbdh, dks, dds, ddp, ddc, dz0,
             np.array(dtau) if dtau else np.zeros((0, 1)),
             np.array(tau_cols, dtype=np.int64), sel, sens)
    # the callers' columns, as views (a transposing copy of every column was half the
    # kernel's time on a linear model)
    where = {j: c for c, j in enumerate(order)}
    return [sens[:, :, where[j]] for j in range(n_col)]
