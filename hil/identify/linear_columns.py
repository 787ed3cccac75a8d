"""A linear model's forward-difference Jacobian columns without a simulation each.

Where no effect runs, :func:`hil.identify.model._simulate` is a linear time-invariant map:
per sub-step ``z' = Ad z + Bd[:, 0] tau`` (the applied force), so over one sample of ``n``
sub-steps ``z(k+1) = Phi z(k) + sum_m Psi_m tau(k, m)`` with ``Phi = Ad^n`` and ``Psi_m =
Ad^(n-1-m) Bd[:, 0]``. A forward-difference column simulates the same record at a vector
``theta_j`` that moves ``Ad, Bd`` (a damper, a stiffness, an inertia), the start state, or
the force (the gain, the timing). Its states differ from the fit point's ``z`` by ``D_j =
z_j - z``, which obeys, exactly,

    D_j(k+1) = Phi_j D_j(k) + (Phi_j - Phi) z(k) + sum_m [(Psi_jm - Psi_m) tau(k, m)
                                                          + Psi_jm (tau_j - tau)(k, m)]

with ``D_j(0)`` the start states' difference. This is the finite difference itself (not
the derivative: a derivative differs from the forward difference by its truncation, a
millionth of a column, which moved the free piston's baseline to another end; see
docs/identify.md), computed without the cancellation of two simulated states. The forcing
of every column is one matrix product over all samples (BLAS), the recursion a few
multiply-adds per state and sample, independent across the columns (the innermost index):
a fifth of a simulation a column or less.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hil.identify.model import (
    _FAST,
    _LINEAR_IDX,
    IDX,
    FastModel,
    _initial_state,
    continuous,
    discretise,
)

#: The parameters a linear model's simulation reads: the continuous (A, B)'s, the gain and
#: the input's timing (a column moving anything else is simulated, or needs none).
_MOVES = frozenset((*_LINEAR_IDX, IDX["gain_n_per_a"], IDX["skew_s"], IDX["delay_s"]))


@njit(cache=True, nogil=True, fastmath=_FAST)
def _differences(phi, dphi, dpsi, z, tau, n_sub, psi_f, dtau, forced, scale, out):
    """``out[j, k] = scale[j] D_j(k)`` from ``D_j(0) = out[j, 0] / scale[j]`` by the
    module's recursion: ``phi`` (5 x 5 x P) the columns' sample maps, ``dphi`` and ``dpsi``
    (5 x n_sub x P) their differences from the point's, ``z`` the point's states, ``tau``
    its force per sub-step; the columns ``forced`` (F) move the force by ``dtau`` (F x
    sub-steps), mapped by their own ``psi_f`` (5 x n_sub x F). The columns are innermost:
    each state's update is a run of independent multiply-adds across them."""
    n = out.shape[1]
    p = out.shape[0]
    cur = np.empty((5, p))
    nxt = np.empty((5, p))
    for i in range(5):
        for j in range(p):
            cur[i, j] = out[j, 0, i] / scale[j]
    for k in range(n - 1):
        z0, z1, z2, z3, z4 = z[k, 0], z[k, 1], z[k, 2], z[k, 3], z[k, 4]
        for i in range(5):
            for j in range(p):
                nxt[i, j] = (phi[i, 0, j] * cur[0, j] + phi[i, 1, j] * cur[1, j]
                             + phi[i, 2, j] * cur[2, j] + phi[i, 3, j] * cur[3, j]
                             + phi[i, 4, j] * cur[4, j]
                             + dphi[i, 0, j] * z0 + dphi[i, 1, j] * z1 + dphi[i, 2, j] * z2
                             + dphi[i, 3, j] * z3 + dphi[i, 4, j] * z4)
            for s in range(n_sub):
                t = tau[k * n_sub + s]
                for j in range(p):
                    nxt[i, j] += dpsi[i, s, j] * t
        for f in range(forced.shape[0]):
            j = forced[f]
            for s in range(n_sub):
                d = dtau[f, k * n_sub + s]
                for i in range(5):
                    nxt[i, j] += psi_f[i, s, f] * d
        for i in range(5):
            for j in range(p):
                cur[i, j] = nxt[i, j]
                out[j, k + 1, i] = nxt[i, j] * scale[j]


def _sample_map(ad: np.ndarray, bd: np.ndarray, n_sub: int) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Psi)``: the state map over one sample and the force's map from each of its
    sub-steps (5 x n_sub), for the sub-step map ``(ad, bd[:, 0])``."""
    psi = np.empty((5, n_sub))
    col = bd[:, 0].copy()
    phi = np.eye(5)
    for m in range(n_sub - 1, -1, -1):
        psi[:, m] = col
        col = ad @ col
        phi = ad @ phi
    return phi, psi


def linear(model: FastModel, theta: np.ndarray) -> bool:
    """True when ``theta``'s simulation runs no effect: the map is the linear one above."""
    from hil.identify.tangent import effects_on  # (it imports the model's kernels)

    return not effects_on(model, theta)


def applies(model: FastModel, theta: np.ndarray, column: np.ndarray) -> bool:
    """True when the column at ``column`` is a difference of two linear simulations that
    moves only what the linear map reads."""
    moved = np.flatnonzero(column != theta)
    return bool(moved.size) and all(int(i) in _MOVES for i in moved) and linear(model, column)


def state_differences(model: FastModel, theta: np.ndarray, z: np.ndarray,
                      columns: list[np.ndarray], steps: np.ndarray, n_stop: int | None
                      ) -> np.ndarray:
    """``(z_j - z) / steps[j]`` on the first ``n_stop`` samples (columns x samples x 5) for
    the linear simulations of the vectors ``columns`` (each :func:`applies`), ``z`` the
    states of ``theta``'s (at least ``n_stop`` samples of them)."""
    exp = model.exp
    n_sub = model.n_sub
    h = exp.dt / n_sub
    n_run = exp.n if n_stop is None else max(2, min(n_stop, exp.n))
    p = len(columns)
    ad, bd, _, _, z0, tau, _ = model.kernel_inputs(theta)
    phi, psi = _sample_map(ad, bd, n_sub)
    gain = theta[IDX["gain_n_per_a"]]
    delay = theta[IDX["delay_s"]] + theta[IDX["skew_s"]]
    phis = np.empty((5, 5, p))
    dphi = np.empty((5, 5, p))
    dpsi = np.empty((5, n_sub, p))
    out = np.empty((p, n_run, 5))
    n_tau = (n_run - 1) * n_sub
    forced, psi_f, dtau = [], [], []
    for j, th in enumerate(columns):
        # the sub-step's discretisation and the start state as the simulation's
        # (FastModel.kernel_inputs, without the half step no linear run reads)
        a, b = continuous(th, exp)
        ad_j, bd_j = discretise(a, b, h)
        phi_j, psi_j = _sample_map(ad_j, bd_j, n_sub)
        phis[:, :, j] = phi_j
        dphi[:, :, j] = phi_j - phi
        dpsi[:, :, j] = psi_j - psi
        timing = th[IDX["delay_s"]] + th[IDX["skew_s"]]
        moves_force = (th[IDX["gain_n_per_a"]] != gain or timing != delay)
        tau_j = model._applied_force(th[IDX["gain_n_per_a"]], timing) if moves_force else tau
        z0_j = _initial_state(a, b, np.array([tau_j[0], 0.0, 0.0, 0.0]), exp.load)
        out[j, 0] = (z0_j - z0) / steps[j]
        if moves_force:
            forced.append(j)
            psi_f.append(psi_j)
            dtau.append(tau_j[:n_tau] - tau[:n_tau])
    _differences(phis, dphi, dpsi, z[:n_run], tau, n_sub,
                 np.stack(psi_f, axis=2) if forced else np.zeros((5, n_sub, 0)),
                 np.array(dtau) if forced else np.zeros((0, n_tau)),
                 np.array(forced, dtype=np.int64), 1.0 / np.asarray(steps, dtype=float), out)
    return out


__all__ = ["applies", "linear", "state_differences"]
