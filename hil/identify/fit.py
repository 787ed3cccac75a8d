"""Output-error fit of the fast model by simulation, with HAC confidence intervals.

The cost is the sum over channels and estimation samples of ``((y - y_hat) / sigma_c)^2``:
the model is simulated from the logged current alone (output error, no measured state fed
back), so what it fits is the whole input-to-output behaviour. ``sigma_c`` (the noise of
channel c) is unknown: a first fit weights each channel by its signal scale, then every
channel by the rms of its own residual, and the fit is repeated (maximum likelihood with
unknown per-channel variances, in two passes).

Positive physical parameters (d_s, d_p, d_c, k_s, K, k_rod, c_rod) are fitted as logarithms;
effect parameters linearly, scaled by their nominal size. A Levenberg-Marquardt on the normal
equations (box bounds, forward-difference Jacobian, columns simulated in parallel) does the work;
where the simulation runs an effect, the simulated columns' states come from one tangent-linear
simulation (:mod:`hil.identify.tangent`, :data:`TANGENT`) instead of one simulation each.

Confidence intervals come from the Jacobian ``J`` at the optimum: ``cov = H^-1 S H^-1`` with
``H = J'J`` and ``S`` the Newey-West long-run covariance of the per-sample scores (the sum
over channels of ``J_k' e_k``), so autocorrelated residuals widen the interval rather than
make it falsely tight. With white residuals this reduces to ``(J'J)^-1``.

A baseline parameter the data cannot pin down (relative standard error above 50 %, e.g. d_c
with the piston fixed, or k_s when the pressure barely moves) is held at the preset's value
and named in :attr:`FitResult.held`.
"""

from __future__ import annotations

import ctypes
import math
import platform
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hil.identify import stats
from hil.identify.experiment import Experiment, quantum
from hil.identify.model import (
    IDX,
    NUISANCE,
    OUTPUT_ONLY,
    PRESSURE_CHANNELS,
    SAT_PRESSURE,
    FastModel,
    channels_moved_by,
    fast_stop,
    map_threads,
)

if TYPE_CHECKING:  # (the consistency module imports this one)
    from hil.identify.consistency import Consistency

#: Computes a fit's consistency across parts of the record (``consistency(fit, exp, mask)``).
Judge = Callable[["FitResult", Experiment, np.ndarray], "Consistency"]

#: Baseline parameters that can be fitted per load kind (others have no effect there).
BASELINE_FREE: dict[str, tuple[str, ...]] = {
    "fixed": ("gain_n_per_a", "ds", "dp", "ks"),
    "free": ("gain_n_per_a", "ds", "dp", "dc", "ks"),
    "conrod": ("gain_n_per_a", "ds", "dp", "dc", "ks", "k_rod", "c_rod"),
}
LOG_PARAMS = frozenset({"gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod",
                        "pc_eps_m_per_s", "sf_vs_m_per_s", "sf_eps_m_per_s"})
#: Parameters with a physical sign and size whose confidence interval must not swallow
#: their value (the pulsation's sine/cosine parts, offsets and the skew may sit near zero).
CREDIBLE = LOG_PARAMS | {"pc_force_n", "sf_coulomb_n", "sf_static_n", "visc_coeff_per_c",
                         "drift_n_per_c", "delay_s"}
#: Log-parameters may move by at most this factor from their start: beyond it a fit has run
#: away (a diverging k_s), and the parameter counts as at its bound.
LOG_RANGE = 1e3
#: Relative standard error above which a baseline parameter is held at the preset value.
MAX_REL_SE = 0.5
Z95 = 1.959963984540054


#: Relative change of every channel's residual rms under which the weights count as settled
#: (a weighted least-squares optimum moves little with its weights; a pass costs a fit).
WEIGHTS_SETTLED = 0.5
#: Estimation samples a long record's fit iterates on before its last step on all of them.
ITERATION_SAMPLES = 30_000
#: Jacobians the first of several passes takes, on weights carried over from an earlier fit,
#: before they are re-estimated: a refit starts from a linearised guess, often far from the
#: optimum (a Coulomb friction's score-test size), where the residual is up to ten times its
#: final size; a few steps bring it near that, and the next pass goes on from there.
WEIGHTING_JACOBIANS = 3
#: A step that lowers the cost by less than this many residual variances ends the fit.
CONVERGED_GAIN = 1.0
#: Jacobians of a pass before :data:`CONVERGED_GAIN` may end it (one variance ends it
#: earlier): a pass's first steps, in a bend of the valley, may gain little before the
#: descent picks up (free piston, both frictions under slide, rig seed 2: the seal's refit
#: gained 20 and 5 variances in its first two steps, then thousands a step at a stop of 1)
LOOSE_AFTER_JACOBIANS = 2

#: Levels of the seal's friction law F(v) = (F_c + (F_s - F_c) exp(-(v/v_s)^2)) s(v): the
#: law dissipates (F(v) v >= 0 at every v) only with both levels >= 0. A negative static
#: level is a seal that pushes the piston along near rest, a stand-in for another effect
#: (a missing pump friction), never a seal: the fit keeps them >= 0.
NON_NEGATIVE = frozenset({"sf_coulomb_n", "sf_static_n"})

#: A Jacobian's simulated columns from one tangent-linear simulation of the states'
#: derivatives (:mod:`hil.identify.tangent`) rather than a simulation per column.
TANGENT = True
#: Fewest such columns worth the tangent's simulation (it costs more than one column's).
TANGENT_MIN_COLUMNS = 2
#: A linear model's simulated columns from the recursion of their states' differences
#: (:mod:`hil.identify.linear_columns`) rather than a simulation each. Off: the columns
#: lack the simulated ones' rounding noise (up to 1e-4 of a small column at the 1e-6
#: steps), which moves the baselines' paths along their flat valleys, and a row of the
#: identify-check matrix (conrod, k_rod 4x, null, seed 2) turned unexplained with it on
#: (docs/identify.md).
LINEAR_COLUMNS = False

#: Longest first-order sensor lag the baseline may fit (a 160 Hz sensor).
MAX_SENSOR_LAG_S = 1e-3
#: The timing skew is a sub-sample alignment: |skew| <= SKEW_LIMIT x the sample period.
SKEW_LIMIT = 0.5


def NUISANCE_SCALES(dt: float) -> dict[str, float]:  # noqa: N802 - a table, by sample period
    """Fit scales of the offset and the timing nuisances (about their typical size)."""
    return {"strain_offset_n": 1.0, "skew_s": dt, "lag_pressure_s": dt, "lag_strain_s": dt}


def bounds_of(name: str, dt: float, skew_limit: float = SKEW_LIMIT) -> tuple[float, float]:
    """Bounds of a parameter in its own units (the log-parameters' are relative to the start):
    the skew is a sub-sample alignment (|skew| <= T/2), a delay is causal, a clip fraction
    lies in 0..1, a seal friction level is >= 0 (:data:`NON_NEGATIVE`)."""
    if name == "skew_s":
        return -skew_limit * dt, skew_limit * dt
    if name.startswith("lag_"):
        return 0.0, MAX_SENSOR_LAG_S
    if name == "delay_s" or name in NON_NEGATIVE:
        return 0.0, np.inf
    if name.startswith("sat_") or name.endswith("_shape"):
        return 0.0, 1.0
    return -np.inf, np.inf


@dataclass
class FitResult:
    """Outcome of one output-error fit."""

    theta: np.ndarray  # full parameter vector (model.PARAM_NAMES)
    free: list[str]
    se: dict[str, float]  # HAC standard errors of the free parameters
    sigma: dict[str, float]  # per-channel residual rms on the estimation part (weights)
    outputs: dict[str, np.ndarray]
    states: np.ndarray
    held: dict[str, str] = field(default_factory=dict)  # parameter -> reason
    n_sims: int = 0
    cov: np.ndarray | None = None  # HAC covariance of the free parameters (their units)
    jac: np.ndarray | None = None  # weighted Jacobian (estimation samples x free), x-space
    weights: dict[str, float] = field(default_factory=dict)  # sigma the Jacobian is scaled by
    #: the last pass stopped at its gain (False: at its Jacobian limit, still descending)
    converged: bool = True
    #: stopped where the fitter's :attr:`OutputErrorFit.leave` said the descent had left the
    #: region it was started to search (``theta`` is where: no optimum, no intervals)
    left: bool = False

    def value(self, name: str) -> float:
        return float(self.theta[IDX[name]])

    def ci95(self, name: str) -> tuple[float, float]:
        v = self.value(name)
        s = self.se.get(name, float("nan"))
        return v - Z95 * s, v + Z95 * s


class OutputErrorFit:
    """Fits a :class:`FastModel` to its experiment (see the module docstring)."""

    def __init__(self, model: FastModel, scales: dict[str, float] | None = None) -> None:
        self.model = model
        self.exp: Experiment = model.exp
        self.scales = scales or {}
        self.n_sims = 0
        self.skew_limit = SKEW_LIMIT
        #: residual variances a step must gain for a pass to go on (:func:`levenberg_marquardt`)
        self.converged_gain = CONVERGED_GAIN
        #: ``leave(theta)`` True: a descent that reached ``theta`` has left the region it was
        #: started in to search, and the fit stops there (``FitResult.left``); None: never
        self.leave: Callable[[np.ndarray], bool] | None = None
        # Samples on a channel's clip plateau say only "at least the level": until the
        # saturation effect models the clip, they count only where the model is below it
        # (a censored residual), so the clip does not bias the linear fit.
        self._clipped = {
            c: self.exp.measured[c] >= level - 0.5 * quantum(self.exp.measured[c])
            for c, level in self.exp.plateaus.items() if c in self.exp.channels}

    # --- parameter transforms ------------------------------------------------------------
    def _to_theta(self, x: np.ndarray, free: list[str], base: np.ndarray) -> np.ndarray:
        theta = base.copy()
        for xi, name in zip(x, free, strict=True):
            if name in LOG_PARAMS:
                theta[IDX[name]] = self._ref[name] * np.exp(xi)
            else:
                theta[IDX[name]] = xi * self.scales.get(name, 1.0)
        return theta

    def _to_x(self, theta: np.ndarray, free: list[str]) -> np.ndarray:
        x = []
        for name in free:
            if name in LOG_PARAMS:
                x.append(np.log(theta[IDX[name]] / self._ref[name]))
            else:
                x.append(theta[IDX[name]] / self.scales.get(name, 1.0))
        return np.array(x)

    def _dtheta_dx(self, theta: np.ndarray, free: list[str]) -> np.ndarray:
        return np.array([theta[IDX[n]] if n in LOG_PARAMS else self.scales.get(n, 1.0)
                         for n in free])

    # --- residuals -------------------------------------------------------------------------
    def residual_channels(self, outputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Measured minus model, per channel, full length (NaN where undefined)."""
        return {c: self.exp.measured[c] - outputs[c] for c in self.exp.channels}

    def _stack(self, theta: np.ndarray, sigma: dict[str, float], mask: np.ndarray,
               states: np.ndarray | None = None, only: frozenset[str] | None = None,
               base: np.ndarray | None = None, into: np.ndarray | None = None) -> np.ndarray:
        """The weighted residual on ``mask``; ``states``: the simulation of ``theta`` when
        the caller has it (only :data:`OUTPUT_ONLY` parameters differ from the ones that
        made it). ``only``: the channels ``theta`` changes from the point whose residual is
        ``base``; the others' rows are ``base``'s (the same computation on the same
        states: the same bits, without their outputs and sensor lags). ``into``: the array
        to write it into (of the residual's size), else a new one; the result is that
        array unless the residual had a non-finite value (then a cleaned copy)."""
        n_stop, lo, hi = self._span(mask)
        if states is None:
            self.n_sims += 1
            states = self.model.states(theta, n_stop)
        # the outputs of the samples up to n_stop only (the mask has none after them)
        out = self.model.outputs(theta, states, n_stop=n_stop, channels=only)
        n = next(iter(out.values())).size
        channels = self.exp.channels
        if lo is None:
            head = mask[:n]
            m = int(head.sum())
        else:
            # the compared samples are one run (a fit's, a cost's): the residual is written
            # channel by channel into one array, no masked copy and concatenation of each
            m = hi - lo
        if into is None:
            r = np.empty(len(channels) * m) if only is None else base.copy()
        else:
            r = into
            if only is not None:
                np.copyto(r, base)
        for i, c in enumerate(channels):
            if only is not None and c not in only:
                continue
            seg = r[i * m:(i + 1) * m]
            if lo is None:
                e = self.exp.measured[c][:n] - out[c]
            else:
                e = np.subtract(self.exp.measured[c][lo:hi], out[c][lo:hi], out=seg)
            clipped = self._clipped.get(c)
            if clipped is not None and theta[IDX[f"sat_{c}"]] == 0.0 and (
                    c not in PRESSURE_CHANNELS or theta[IDX[SAT_PRESSURE]] == 0.0):
                e = np.where(clipped[:n] if lo is None else clipped[lo:hi],
                             np.maximum(e, 0.0), e)
            if lo is None:
                e = e[head]
            np.divide(e, sigma[c], out=seg)
        return _finite(r)

    def _span(self, mask: np.ndarray) -> tuple[int, int | None, int | None]:
        """``(n_stop, lo, hi)`` of a mask of compared samples: the samples to simulate (the
        model is causal: none after the last one compared), and ``lo:hi`` the compared
        samples where they are one run (None, None where not: a gap of undefined
        samples)."""
        where = np.flatnonzero(mask)
        n_stop = fast_stop(int(where[-1]) + 1, self.exp.n)
        lo, hi = int(where[0]), int(where[-1]) + 1
        return (n_stop, lo, hi) if hi - lo == where.size else (n_stop, None, None)

    def _problem(self, free: list[str], theta0: np.ndarray, sigma: dict[str, float],
                 mask: np.ndarray):
        """Residual function and its forward-difference Jacobian (columns in parallel; the
        simulated columns' states from the tangent where :meth:`_tangent_columns` gives
        them: ``z + step dz/dx``, mapped to outputs and residuals as a simulated column's)."""
        cache: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        n_stop = self._span(mask)[0]

        def fun(x: np.ndarray) -> np.ndarray:
            theta = self._to_theta(x, free, theta0)
            self.n_sims += 1
            z = self.model.states(theta, n_stop)
            r = self._stack(theta, sigma, mask, z)
            cache["last"] = (x.copy(), r, z)
            return r

        def jac(x: np.ndarray) -> np.ndarray:
            last = cache.get("last")
            if last is None or not np.array_equal(last[0], x):
                fun(x)
                last = cache["last"]
            _, r0, z0 = last
            steps = 1e-6 * np.maximum(1.0, np.abs(x))
            tangent = (self._tangent_columns(x, free, theta0, steps, n_stop)
                       or self._linear_columns(x, free, theta0, steps, n_stop, z0))

            # one row per column, then one transposing copy: writing each column into
            # the (rows x columns) array strides across all of it once per column (both
            # arrays kept from earlier Jacobians: _BUFFERS)
            out_t = _BUFFERS.take((x.size, r0.size))

            def fill(i: int) -> None:
                xx = x.copy()
                xx[i] += steps[i]
                theta = self._to_theta(xx, free, theta0)
                only = None
                # an offset, a drift, a lag, a clip: the same states, new outputs, and
                # only on the channels it moves (the others' rows of the column are 0)
                if free[i] in OUTPUT_ONLY:
                    z = z0
                    only = channels_moved_by(free[i]) & set(self.exp.channels)
                    if not only:
                        out_t[i] = 0.0
                        return
                elif i in tangent:
                    # the simulation at the step, to first order: the tangent's states,
                    # on the samples the outputs read (elementwise: the same bits)
                    sens = tangent[i]
                    n_out = min(fast_stop(n_stop, self.exp.n), z0.shape[0])
                    m = min(sens.shape[0], n_out)
                    # z0 + step dz/dx into a kept array (the column's states are done with
                    # once its residual is; the same bits as a copy of z0 stepped in place)
                    z = _COLUMN_STATES.take((n_out, *z0.shape[1:]))
                    np.multiply(sens[:m], steps[i], out=z[:m])
                    np.add(z0[:m], z[:m], out=z[:m])
                    z[m:] = z0[m:n_out]
                else:
                    self.n_sims += 1
                    z = self.model.states(theta, n_stop, keep=False)
                # the residual written into the column's row, then (r - r0) / step in place:
                # no temporaries
                row = out_t[i]
                np.subtract(self._stack(theta, sigma, mask, z, only, r0, into=row), r0,
                            out=row)
                np.divide(row, steps[i], out=row)

            list(map_threads(fill, range(x.size)))
            return _transposed(out_t, _BUFFERS.take((r0.size, x.size)))

        return fun, jac

    def _tangent_columns(self, x: np.ndarray, free: list[str], theta0: np.ndarray,
                         steps: np.ndarray, n_stop: int) -> dict[int, np.ndarray]:
        """``{column: dz/dx}`` of the simulated columns one tangent-linear simulation gives
        (:mod:`hil.identify.tangent`): every column that keeps the kernel's code paths
        over its step, when the simulation runs an effect and there are at least
        :data:`TANGENT_MIN_COLUMNS` such columns; the others are simulated one by one
        (empty: all of them)."""
        if not TANGENT:
            return {}
        from hil.identify.tangent import effects_on, on_path, state_sensitivities

        theta = self._to_theta(x, free, theta0)
        if not effects_on(self.model, theta):
            return {}
        cols, plus, minus = [], [], []
        for i, name in enumerate(free):
            if name in OUTPUT_ONLY:
                continue
            xp = x.copy()
            xp[i] += steps[i]
            xm = x.copy()
            xm[i] -= steps[i]
            tp = self._to_theta(xp, free, theta0)
            tm = self._to_theta(xm, free, theta0)
            if on_path(self.model, theta, tp, tm):
                cols.append(i)
                plus.append(tp)
                minus.append(tm)
        if len(cols) < TANGENT_MIN_COLUMNS:
            return {}
        self.n_sims += 1
        sens = state_sensitivities(self.model, theta, plus, minus, steps[cols], n_stop)
        return dict(zip(cols, sens, strict=True))

    def _linear_columns(self, x: np.ndarray, free: list[str], theta0: np.ndarray,
                        steps: np.ndarray, n_stop: int, z0: np.ndarray
                        ) -> dict[int, np.ndarray]:
        """``{column: (z_j - z0) / step}`` of the simulated columns of a linear model
        (:mod:`hil.identify.linear_columns`: the forward difference's states by a recursion
        of their difference, no simulation), where :data:`LINEAR_COLUMNS` is on and the
        point and every such column simulate no effect; the others are simulated (empty:
        all of them)."""
        if not LINEAR_COLUMNS:
            return {}
        from hil.identify import linear_columns

        theta = self._to_theta(x, free, theta0)
        if not linear_columns.linear(self.model, theta):
            return {}
        cols, vectors = [], []
        for i, name in enumerate(free):
            if name in OUTPUT_ONLY:
                continue
            xp = x.copy()
            xp[i] += steps[i]
            tp = self._to_theta(xp, free, theta0)
            if linear_columns.applies(self.model, theta, tp):
                cols.append(i)
                vectors.append(tp)
        if not cols:
            return {}
        diff = linear_columns.state_differences(self.model, theta, z0, vectors, steps[cols],
                                                n_stop)
        return dict(zip(cols, diff, strict=True))

    def fit_mask(self) -> np.ndarray:
        """Estimation samples where every channel is defined."""
        mask = self.exp.est.copy()
        for c in self.exp.channels:
            mask &= np.isfinite(self.exp.measured[c])
        return mask

    def _x_bounds(self, free: list[str]) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = [], []
        for name in free:
            if name in LOG_PARAMS:
                lo.append(-np.log(LOG_RANGE))
                hi.append(np.log(LOG_RANGE))
            else:
                b_lo, b_hi = bounds_of(name, self.exp.dt, self.skew_limit)
                sc = self.scales.get(name, 1.0)
                lo.append(b_lo / sc)
                hi.append(b_hi / sc)
        return np.array(lo), np.array(hi)

    def at_bound(self, result: FitResult, name: str) -> bool:
        """True when ``name`` ended on (or within 0.1 % of the range near) its bound.

        A friction law's shape (0 tanh .. 1 atan) at either end is that law, and a clip
        fraction of 1 is a sensor that clips outright: neither is a runaway."""
        if name.endswith("_shape") or name.startswith("sat_"):
            return False
        lo, hi = (a[0] for a in self._x_bounds([name]))
        if name in LOG_PARAMS:
            ref = getattr(self, "_ref", {}).get(name)
            if ref is None:
                return False
            x = float(np.log(result.value(name) / ref))
        else:
            x = result.value(name) / self.scales.get(name, 1.0)
        width = hi - lo if np.isfinite(hi - lo) else max(abs(x), 1.0)
        tol = 1e-3 * width
        # a causal delay or a clip fraction resting at 0 is "absent", not "at a bound"
        rest_at_zero = name == "delay_s" or name.startswith("lag_")
        return bool(x - lo < tol and not (rest_at_zero and lo == 0.0)) or bool(hi - x < tol)

    def cost(self, theta: np.ndarray, sigma: dict[str, float]) -> float:
        """Weighted sum of squares on the estimation samples."""
        r = self._stack(theta, sigma, self.fit_mask())
        return float(r @ r)

    def fit(self, theta0: np.ndarray, free: list[str], sigma: dict[str, float] | None = None,
            passes: int = 2, max_nfev: int = 40) -> FitResult:
        """Fit the parameters ``free`` starting from ``theta0``; others stay as given.

        ``max_nfev`` bounds the Jacobians (each one simulation per free parameter) per pass.
        A parameter named twice in ``free`` is fitted once (two equal columns would make the
        normal equations singular and every Jacobian one column dearer).
        """
        free = list(dict.fromkeys(free))
        self._ref = {n: max(abs(theta0[IDX[n]]), 1e-12) for n in free if n in LOG_PARAMS}
        mask = self.fit_mask()
        # weights carried over from a fit without the effect now in are stale: re-estimated
        # after a short first pass (a fit's own start residual is close enough to run on)
        carried = sigma is not None
        if sigma is None:
            # weights from the start's own residual: near the final ones, so one pass usually
            # settles them (signal scales would weight a 2 kPa-noise pressure like a speed)
            res0 = self.residual_channels(self.model.outputs(theta0))
            sigma = {c: float(np.sqrt(np.nanmean(res0[c][mask] ** 2))) or self.exp.sigma0[c]
                     for c in self.exp.channels}
        sigma = dict(sigma)
        x = self._to_x(theta0.copy(), free)
        lo, hi = self._x_bounds(free)
        x = np.clip(x, lo, hi)
        used = sigma
        r = j = None
        # A long record iterates on the first ITERATION_SAMPLES estimation samples (every
        # simulation stops there) and takes one last step on all of them, for the optimum
        # and the covariance; a record of up to ~8 s at 5 kHz uses all of them throughout.
        where = np.flatnonzero(mask)
        iter_mask = mask
        if where.size > ITERATION_SAMPLES:
            iter_mask = mask.copy()
            iter_mask[where[ITERATION_SAMPLES]:] = False
        converged = False
        stop = None if self.leave is None else (
            lambda xx: self.leave(self._to_theta(xx, free, theta0)))
        for k in range(passes):
            if k > 0:
                if converged and all(abs(sigma[c] / used[c] - 1.0) < WEIGHTS_SETTLED
                                     for c in sigma):
                    break  # weights settled: a second pass would not move the optimum
                # re-weight the last residual and Jacobian instead of simulating them again
                n_t = int(iter_mask.sum())
                scale = np.repeat([used[c] / sigma[c] for c in self.exp.channels], n_t)
                r = r * scale
                j = np.multiply(j, scale[:, None], out=_BUFFERS.take(j.shape))
            fun, jac = self._problem(free, theta0, sigma, iter_mask)
            max_jac = max(3, max_nfev // 3)
            if carried and k < passes - 1:
                max_jac = min(max_jac, WEIGHTING_JACOBIANS)
            # the last pass's Jacobian at its optimum is needed only if no step on all the
            # samples follows (that step takes its own)
            final_jac = iter_mask is mask or k < passes - 1
            try:
                x, r, j, converged = levenberg_marquardt(fun, jac, x, lo, hi, max_jac=max_jac,
                                                         r0=r, j0=j, final_jac=final_jac,
                                                         converged_gain=self.converged_gain,
                                                         leave=stop)
            except LeftRegion as gone:
                theta = self._to_theta(gone.x, free, theta0)
                states = self.model.states(theta)
                return FitResult(theta, list(free), {}, sigma,
                                 self.model.outputs(theta, states), states,
                                 n_sims=self.n_sims, weights=dict(sigma), converged=False,
                                 left=True)
            used = sigma
            theta = self._to_theta(x, free, theta0)
            out = self.model.outputs(theta)
            res = self.residual_channels(out)
            sigma = {c: float(np.sqrt(np.nanmean(res[c][mask] ** 2))) or 1.0
                     for c in self.exp.channels}
        descended_to_end = converged
        if iter_mask is not mask:
            fun, jac = self._problem(free, theta0, sigma, mask)
            x, r, j, _ = levenberg_marquardt(fun, jac, x, lo, hi, max_jac=1, final_jac=False)
            used = sigma
        theta = self._to_theta(x, free, theta0)
        states = self.model.states(theta)
        out = self.model.outputs(theta, states)
        se, cov = self.hac_se(j, r, mask.sum(), theta, free)
        return FitResult(theta, list(free), se, sigma, out, states, n_sims=self.n_sims, cov=cov,
                         jac=j, weights=dict(used), converged=descended_to_end)

    def standard_errors(self, theta: np.ndarray, free: list[str], sigma: dict[str, float]
                        ) -> dict[str, float]:
        """HAC standard errors of ``free`` at ``theta`` as they stand, from one Jacobian on
        the estimation samples (no step): the intervals a fit of them would report if it
        stopped there, at the cost of one simulation per parameter."""
        self._ref = {n: max(abs(theta[IDX[n]]), 1e-12) for n in free if n in LOG_PARAMS}
        mask = self.fit_mask()
        fun, jac = self._problem(free, theta, sigma, mask)
        x = self._to_x(theta, free)
        se, _ = self.hac_se(jac(x), fun(x), int(mask.sum()), theta, free)
        return se

    def offenders(self, result: FitResult, names: list[str] | None = None
                  ) -> list[tuple[str, str, float]]:
        """Parameters of ``result`` that are not credible, worst first: (name, why, badness).

        A parameter is not credible when it ran to a bound, or (for parameters with a
        physical size, :data:`CREDIBLE`) when its 95 % confidence interval is wider than its
        value, i.e. the data cannot tell it from a value twice as large or from zero.
        """
        out = []
        for n in names if names is not None else result.free:
            if n not in result.free or n in NUISANCE:
                # timing nuisances: at a bound they are reported, not held
                continue
            v = result.value(n)
            if self.at_bound(result, n):
                out.append((n, f"ran to its bound ({v:.4g})", np.inf))
                continue
            width = 2.0 * Z95 * result.se.get(n, 0.0)
            if n in CREDIBLE and not width <= abs(v):
                out.append((n, f"95 % confidence interval {width:.3g} wider than the value "
                               f"{v:.4g}", width / max(abs(v), 1e-300)))
        return sorted(out, key=lambda o: -o[2])

    def hac_se(self, jac: np.ndarray, e: np.ndarray, n_t: int, theta: np.ndarray,
               free: list[str]) -> tuple[dict[str, float], np.ndarray]:
        """HAC standard errors in parameter units (see the module docstring)."""
        n_ch = len(self.exp.channels)
        p = jac.shape[1]
        j3 = jac.reshape(n_ch, n_t, p)
        e2 = e.reshape(n_ch, n_t)
        scores = np.einsum("ctp,ct->tp", j3, e2)
        corr = stats.correlation_length(e2.sum(axis=0), 400)
        lags = stats.nw_lags(n_t, corr)
        s = stats.newey_west(scores, lags)
        h = jac.T @ jac
        try:
            hinv = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            hinv = np.linalg.pinv(h)
        cov_x = hinv @ s @ hinv
        d = self._dtheta_dx(theta, free)
        cov = cov_x * np.outer(d, d)
        se = {n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(free)}
        return se, cov


#: A Jacobian, its rows before the transposing copy and a tangent column's states are
#: written into arrays kept from earlier ones that nothing else holds any more
#: (:class:`_Kept`), not into new ones. A new array of tens of MB comes from the kernel as
#: fresh pages (numpy asks for huge ones), each zeroed by the kernel on its first write:
#: on the conrod's three effects at rig seed 1 (184 Jacobians of 35-90 MB, twice: rows and
#: transpose) that was ~1 s of system CPU (docs/identify.md). Off: new arrays, as before
#: (the same bits either way: every element is written before it is read).
REUSE_BUFFERS = True


class _Kept:
    """Float arrays kept for reuse: :meth:`take` hands out a view of a kept buffer that no
    one else references any more (a Jacobian a fit result holds, or one the caller still
    holds from the previous call, keeps its buffer busy: CPython's reference count, which
    every view of the buffer raises), else of a new one, which it keeps (the ``keep`` most
    recently used; an older idle one is dropped first). Thread-safe (a lock around the
    choice: a tangent column's states are taken on the fill's threads)."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self._kept: list[np.ndarray] = []
        #: arrays handed out, and of those the ones in a new buffer
        self.taken = self.made = 0
        self._lock = threading.Lock()

    def take(self, shape: tuple[int, ...]) -> np.ndarray:
        size = math.prod(int(n) for n in shape)
        if not REUSE_BUFFERS:
            return np.empty(shape)
        with self._lock:
            kept = self._kept
            best = -1
            for k in range(len(kept)):
                # idle: referenced by the list and getrefcount's argument only
                if (kept[k].size >= size and sys.getrefcount(kept[k]) == 2
                        and (best < 0 or kept[k].size < kept[best].size)):
                    best = k
            self.taken += 1
            if best >= 0:
                buf = kept.pop(best)
            else:
                self.made += 1
                buf = np.empty(max(size, 1))
                if len(kept) >= self.keep:
                    idle = [k for k in range(len(kept)) if sys.getrefcount(kept[k]) == 2]
                    kept.pop(idle[0] if idle else 0)
            kept.append(buf)  # the most recently used last
            return buf[:size].reshape(shape)


#: The Jacobians and their rows (a fit's iterations and its last step take two sizes, and
#: a fit result holds its last Jacobian)
_BUFFERS = _Kept(6)
#: A tangent column's states, one per thread filling columns at a time
_COLUMN_STATES = _Kept(8)


#: glibc's malloc as an identification sets it (:func:`keep_freed_memory`, called by
#: :func:`hil.identify.pipeline.identify`, not at import): arrays up to its largest mmap
#: threshold (32 MB) come from the heap, freed memory up to 256 MB stays there for the next
#: array, and the threads share one arena. By default glibc gives an array above a moving
#: threshold (128 kB at first) its own fresh pages and trims the heap's top as it frees:
#: the sensor lags' transforms, the simulations' states and outputs (tenths of MB to a
#: few MB each, thousands per record) each came back as new pages to zero (docs/identify.md).
#: Off: glibc's defaults.
KEEP_FREED_MEMORY = True
#: mallopt's parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_ARENA_MAX = -1, -3, -8


def keep_freed_memory() -> bool:
    """Set glibc's malloc as :data:`KEEP_FREED_MEMORY` says, for the rest of the process;
    False where the C library is not glibc's (nothing set) or it refused a setting."""
    if not KEEP_FREED_MEMORY or platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return all(mallopt(p, v) == 1 for p, v in ((_M_MMAP_THRESHOLD, 32 << 20),
                                               (_M_TRIM_THRESHOLD, 256 << 20),
                                               (_M_ARENA_MAX, 1)))


#: numpy asks the kernel to back each array of 4 MB or more with 2 MB pages (``madvise``
#: ``MADV_HUGEPAGE``). Where transparent huge pages are on for such requests, with direct
#: defragmentation (this machine kind's ``madvise``/``madvise`` setting), each array's first
#: touch has the kernel compact memory into huge pages: on the conrod triple's 16 s record at
#: rig seed 2, 2.3 s of system CPU in 22.6 s; without the advice 0.8 s, and the same bits
#: (docs/identify.md). An identification turns the advice off for the rest of the process
#: (:func:`small_pages`); False: numpy's default.
SMALL_PAGES = True


def small_pages() -> bool:
    """Turn numpy's huge-page advice off for the rest of the process, as :data:`SMALL_PAGES`
    says; False where it is not asked for or this numpy has no switch for it."""
    if not SMALL_PAGES:
        return False
    core = getattr(np, "_core", None) or getattr(np, "core", None)
    switch = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if switch is None:
        return False
    switch(False)
    return True


#: Rows of the Jacobian transposed at a time (:func:`_transposed`): a block of the
#: columns' rows and its transpose stay in the cache.
TRANSPOSE_BLOCK = 4096


def _transposed(a: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``np.ascontiguousarray(a.T)`` (the same values: a copy), block by block of
    :data:`TRANSPOSE_BLOCK` columns of ``a``, into ``out`` (C-contiguous, of ``a.T``'s shape)
    where given. One transposing copy of a Jacobian (20 rows of 210,000 values) strides
    across the whole output once per row and misses the cache on every write: 19 ms,
    against 5 ms by blocks (a fit takes one per Jacobian, 1.0 s of the conrod's two
    frictions' 16 s record)."""
    rows, cols = a.shape
    if out is None:
        out = np.empty((cols, rows), dtype=a.dtype)
    for lo in range(0, cols, TRANSPOSE_BLOCK):
        out[lo:lo + TRANSPOSE_BLOCK] = a[:, lo:lo + TRANSPOSE_BLOCK].T
    return out


def _finite(x: np.ndarray) -> np.ndarray:
    """``np.nan_to_num(x)``, without its passes over an array that is finite already."""
    return x if np.isfinite(x).all() else np.nan_to_num(x)


#: Broyden updates of the Jacobian between exact ones (0: an exact Jacobian after every
#: accepted step, the same bits as before the updates existed). A Jacobian costs one
#: simulation (or a tangent-linear pass and a residual) per free parameter, an update one
#: product with it. Off: at 2 the conrod triple at rig seed 1 took 107 Jacobians for 178
#: and 22 s of CPU for 29, but the fits' other paths flipped five rows of the
#: identify-check matrix and a record of the 16 s table, and doubled others' CPU
#: (docs/identify.md, "Broyden updates of the Jacobian: measured, not taken").
BROYDEN_UPDATES = 0
#: An accepted step that gained less than this fraction of what its linearisation
#: predicted is followed by an exact Jacobian, not an update (the model was poor there).
BROYDEN_MIN_RATIO = 0.25


def _broyden(j: np.ndarray, dx: np.ndarray, dr: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Broyden's rank-1 update of the Jacobian ``j`` after the step ``dx`` changed the
    residual by ``dr``, in the variables scaled by the columns' norms ``d`` (as MINPACK's
    hybrd): ``j + (dr - j dx) (D^2 dx)' / (dx' D^2 dx)``, so the secant condition
    ``j_new dx = dr`` holds. Written block by block into a kept array (a new one: the
    caller may still hold ``j``)."""
    w = d * d * dx
    v = w / float(dx @ w)
    u = dr - j @ dx
    out = _BUFFERS.take(j.shape)
    for lo in range(0, j.shape[0], TRANSPOSE_BLOCK):
        hi = lo + TRANSPOSE_BLOCK
        np.add(j[lo:hi], np.multiply.outer(u[lo:hi], v), out=out[lo:hi])
    return out


class LeftRegion(Exception):
    """A descent left the region its caller started it to search (``x``: where)."""

    def __init__(self, x: np.ndarray) -> None:
        super().__init__("the descent left the region searched")
        self.x = x


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    max_jac: int = 12,
    r0: np.ndarray | None = None,
    j0: np.ndarray | None = None,
    final_jac: bool = True,
    converged_gain: float | None = None,
    updates: int | None = None,
    leave: Callable[[np.ndarray], bool] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Minimise ``|fun(x)|^2`` within the box ``lo <= x <= hi``; returns ``(x, r, J,
    converged)``, ``converged`` False when it stopped at ``max_jac`` linearisations.

    Levenberg-Marquardt on the normal equations: the residual has hundreds of thousands of
    rows and the parameters a dozen, so each step costs one product ``J'J`` (a library solver
    takes an SVD of ``J`` per step, and most of the fit's time with it). Steps leaving the box
    are clipped to it. Stops when no step lowers the cost, an accepted one lowers it by no
    more than ``converged_gain`` residual variances (default :data:`CONVERGED_GAIN`; within
    the first :data:`LOOSE_AFTER_JACOBIANS` steps: one variance), the step is below
    1e-8, or after ``max_jac`` linearisations (steps from a Jacobian, exact or updated).

    After an accepted step the Jacobian is updated (Broyden, :func:`_broyden`) rather than
    computed, up to ``updates`` times in a row (default :data:`BROYDEN_UPDATES`) and while
    the last step gained at least :data:`BROYDEN_MIN_RATIO` of its predicted gain. Only an
    exact Jacobian decides the end: a step from an updated one that is refused, or whose
    gain would end the pass, is followed by an exact Jacobian at the point it reached; the
    pass then ends there only if the step that Jacobian gives is predicted to gain no more
    than the stop's limit (else it goes on from there). The returned ``J`` is the exact
    Jacobian at the returned point unless ``final_jac=False``, which returns the last
    linearisation (exact or updated) rather than compute one there (for a last small step).

    ``leave(x)`` True after an accepted step raises :class:`LeftRegion` with that ``x``: the
    descent has left the region the caller started it to search.
    """
    if converged_gain is None:
        converged_gain = CONVERGED_GAIN
    if updates is None:
        updates = BROYDEN_UPDATES
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    r = fun(x) if r0 is None else r0
    j = jac(x) if j0 is None else j0
    cost = float(r @ r)
    lam = 1e-3
    n_lin = 1  # linearisations the steps came from (the budget)
    in_row = 0  # updates since the last exact Jacobian (0: ``j`` is exact at ``x``)
    judge = False  # ``j`` was refreshed after an updated step's small gain: judge the end
    budget_left = True
    gain = 0.0

    def stop_limit(c: float) -> float:
        """The gain that ends the pass at cost ``c``, in residual variances (one within the
        first :data:`LOOSE_AFTER_JACOBIANS` steps)."""
        return (c / r.size) * (converged_gain if n_lin > LOOSE_AFTER_JACOBIANS
                               else min(converged_gain, 1.0))

    while True:
        a = j.T @ j
        g = j.T @ r
        d = np.sqrt(np.maximum(np.diag(a), 1e-300))
        an = a / np.outer(d, d)
        gn = g / d
        improved = False
        # parameters on a bound that the gradient pushes outward stay there for this step:
        # a step computed with them and then clipped is no descent step, and LM would shrink
        # its steps around it (zig-zagging through a dozen Jacobians)
        span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
        at_lo = (x - lo <= 1e-9 * span) & (gn > 0)
        at_hi = (hi - x <= 1e-9 * span) & (gn < 0)
        move = ~(at_lo | at_hi)
        if not move.any():
            if in_row:
                j, in_row = jac(x), 0
                continue
            return x, r, j, True
        an_m = an[np.ix_(move, move)]
        limit = stop_limit(cost)
        for _ in range(12):
            step = np.zeros_like(x)
            try:
                step[move] = -np.linalg.solve(an_m + lam * np.eye(an_m.shape[0]),
                                              gn[move]) / d[move]
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            x_new = np.clip(x + step, lo, hi)
            dx = x_new - x
            # the gain the linearisation predicts: cost - |r + J dx|^2
            predicted = -float(2.0 * (g @ dx) + dx @ (a @ dx))
            if judge:
                judge = False
                if predicted <= limit:
                    # the exact Jacobian here says the next step would end the pass
                    return x, r, j, True
                if not budget_left:
                    return x, r, j, False
            r_new = fun(x_new)
            cost_new = float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new < cost:
                gain = cost - cost_new
                dr = r_new - r if updates else None  # (for a Broyden update only)
                x, r, cost = x_new, r_new, cost_new
                if leave is not None and leave(x):
                    raise LeftRegion(x)
                if not in_row:
                    # (a step from an updated Jacobian leaves the damping as it was: its
                    # success says less of the linearisation's; relaxing it there made the
                    # next exact step fail several trials first)
                    lam = max(lam / 5.0, 1e-9)
                improved = True
                break
            if in_row:
                break  # the update's fault, not the damping's: an exact Jacobian first
            lam *= 8.0
        if not improved:
            if in_row:
                j, in_row = jac(x), 0
                continue
            return x, r, j, True
        # a cost change below one residual variance moves no parameter by more than about
        # one standard error of white residuals: a fraction of the real one, the residuals
        # being correlated over tens of samples (the covariance is HAC for that reason).
        # (a looser stop only after LOOSE_AFTER_JACOBIANS: a slow start is no end)
        small = gain <= stop_limit(cost)
        small = small or np.max(np.abs(step)) < 1e-8
        if small and in_row:
            # from an updated Jacobian a small gain may be the update's: an exact one here
            # judges it (the Jacobian the caller needs if the pass ends here)
            j, in_row, judge = jac(x), 0, True
            budget_left = n_lin < max_jac
            n_lin += 1
            continue
        if small or n_lin >= max_jac:
            if final_jac:
                j = jac(x)  # the Jacobian at the returned point, for the covariance
            return x, r, j, small
        n_lin += 1
        if in_row < updates and gain >= BROYDEN_MIN_RATIO * predicted:
            j = _broyden(j, dx, dr, d)
            in_row += 1
        else:
            j, in_row = jac(x), 0


def guarded_fit(fitter: OutputErrorFit, theta0: np.ndarray, free: list[str],
                credible: np.ndarray, sigma: dict[str, float] | None = None,
                passes: int = 2, guard: list[str] | None = None, max_nfev: int = 40,
                configured: np.ndarray | None = None, first: FitResult | None = None,
                refuse: frozenset[str] = frozenset(), run_on: bool = False,
                ) -> tuple[FitResult, dict[str, str]]:
    """Fit, then hold every non-credible parameter (of ``guard``, default all free) at its
    last credible value (from ``credible``), worst first, refitting after each hold.

    With ``configured`` (the preset's values), a parameter that has one (non-zero, unlike
    an effect's) may be held there instead: at whichever of the two the rest of the fit
    has the lower cost. The last credible value can be credible only because an effect the
    model lacked pushed the parameter there (a damper taking a friction's dissipation);
    once that effect is in, it contradicts the other parameters, the configured value
    does not.

    ``first``: that first fit, when the caller has made it already.

    ``refuse``: parameters whose hold refuses the fit for the caller (an effect's own
    parameter not credible): the guard stops at the first such hold and returns the fit it
    held it in, the hold named; the further holds and refits would be thrown away with it.

    ``run_on``: where the first fit stopped at its budget, not converged, each refit after a
    hold has a pass of that budget (``max_nfev``) in place of the short one: a search whose
    end is refitted elsewhere, where the hold's jump leaves that end off its valley floor.

    Returns the fit and ``{parameter: why it was held}``.
    """
    free = list(free)
    result = first if first is not None else fitter.fit(theta0, free, sigma=sigma,
                                                        passes=passes, max_nfev=max_nfev)
    if result.left:
        return result, {}  # no optimum to judge the parameters' credibility at
    after_hold = max_nfev if run_on and not result.converged else 9
    held: dict[str, str] = {}
    for _ in range(len(free)):
        bad = fitter.offenders(result, guard)
        if not bad:
            break
        name, why, _ = bad[0]
        value = credible[IDX[name]]
        where = ""
        if configured is not None:
            alt = configured[IDX[name]]
            if alt != 0.0 and alt != value:
                trial = result.theta.copy()
                trial[IDX[name]] = value
                cost_last = fitter.cost(trial, result.sigma)
                trial[IDX[name]] = alt
                if fitter.cost(trial, result.sigma) < cost_last:
                    where = f" (the configured value: the last fit's {value:.4g} fits worse)"
                    value = alt
        held[name] = f"{why}; held at {value:.4g}{where}"
        if name in refuse:
            break
        free.remove(name)
        theta = result.theta.copy()
        theta[IDX[name]] = value
        if not free:
            break
        result = fitter.fit(theta, free, sigma=result.sigma, passes=1, max_nfev=after_hold)
        if result.left:
            break
    return result, held


#: What :func:`hold_unsupported` says of a far parameter it holds for absorbed structure
#: (the identification loop's slow-first step keeps such a hold: ``restart_slow_first``).
ABSORBED = "where it disagrees between parts of the record"
#: Factor from a parameter's configured value beyond which the baseline checks that the
#: data, not the optimiser's path, put it there (:func:`hold_unsupported`).
PROFILE_FACTOR = 1.5
#: 95 % point of chi^2 with one degree of freedom: the likelihood-ratio test of one
#: parameter held at a value.
CHI2_1_95 = Z95 * Z95


def lr_threshold(result: FitResult, name: str) -> float:
    """The cost rise that holding ``name`` must cause to be significant (5 %): chi^2_1 scaled
    by how much the residual's autocorrelation widens that parameter's variance (its HAC
    variance over the white-noise one, at least 1), the same inflation the confidence
    intervals carry."""
    if result.jac is None or result.cov is None or name not in result.free:
        return CHI2_1_95
    i = result.free.index(name)
    try:
        naive = float(np.linalg.inv(result.jac.T @ result.jac)[i, i])
    except np.linalg.LinAlgError:
        return CHI2_1_95
    d = float(result.theta[IDX[name]]) if name in LOG_PARAMS else 1.0
    hac = float(result.cov[i, i]) / (d * d) if d else 0.0
    ratio = hac / naive if naive > 0 and np.isfinite(hac) else 1.0
    return CHI2_1_95 * max(1.0, ratio)


def _far(result: FitResult, configured: np.ndarray, factor: float) -> dict[str, float]:
    """Free physical parameters of ``result`` beyond ``factor`` of their configured values:
    ``{name: fitted / configured}``."""
    out = {}
    for n in result.free:
        ref = configured[IDX[n]]
        if n in LOG_PARAMS and ref > 0:
            ratio = result.value(n) / ref
            if not 1.0 / factor <= ratio <= factor:
                out[n] = ratio
    return out


def hold_unsupported(fitter: OutputErrorFit, result: FitResult, configured: np.ndarray,
                     factor: float = PROFILE_FACTOR, judge: Judge | None = None
                     ) -> tuple[FitResult, dict[str, str]]:
    """Hold at its configured value every free physical parameter that the fit moved beyond
    ``factor`` of it where the data do not ask for that value, one at a time, the fit
    repeated after each hold:

    1. *absorbed structure*: a far parameter that disagrees between parts of the record
       (:func:`~hil.identify.consistency.consistency`, bands, segments, channel groups)
       went there to stand in for structure the linear model lacks (a friction taken into
       the piston's mass), and held there it would keep the library's effects from being
       seen; its far value is no finding about the rig;
    2. *not supported*: every far parameter not tested yet is refitted held at its
       configured value, each from the same fit; one is held when its held fit costs less
       than the likelihood-ratio threshold (:func:`lr_threshold`) above the lowest cost any
       of these fits reached, the free one included (each held fit is a restricted fit of
       the same model, so the lowest of them bounds what the free one could reach: a free
       fit that stopped on a flat valley is no reference). Of those that qualify, the one
       whose held fit costs least is held; fits that tie within the threshold go by the
       distance from the configuration (furthest first).

    A weakly pinned parameter (k_s with its resonance above Nyquist) wanders along a flat
    valley, and where the optimiser stops on it depends on its path, down to the last bits of
    the arithmetic (another CPU's kernels). Comparing a held refit against that stop made
    the hold hang on those bits (free piston, pump and seal friction: J_c held at 40x on one
    BLAS kernel, k_s at 0.07x on another, after which the frictions were not found). The
    comparisons here are between fits that all end near their optima (the held refits
    differ by thousands, the threshold is a few units), and the consistency test has
    p-values of 1e-14 where it decides: the far value is kept only where the data support it
    over the configured one consistently, and then it is a finding about the rig.
    ``judge``: computes the consistency in place of
    :func:`~hil.identify.consistency.consistency` (the identification loop's, which keeps
    the one of the fit returned: it judges that fit again).
    Returns the fit and ``{parameter: why held}``.
    """
    from hil.identify.consistency import consistency  # (it imports this module)

    if judge is None:
        judge = consistency

    held: dict[str, str] = {}
    tested: set[str] = set()
    mask = fitter.fit_mask()

    def held_at_configured(fit: FitResult, name: str) -> FitResult:
        theta = fit.theta.copy()
        theta[IDX[name]] = configured[IDX[name]]
        rest = [n for n in fit.free if n != name]
        return fitter.fit(theta, rest, sigma=fit.sigma, passes=1, max_nfev=9)

    while len(result.free) >= 2:
        far = _far(result, configured, factor)
        if not far:
            break
        spread = [s for s in judge(result, fitter.exp, mask).inconsistent
                  if s.name in far]
        if spread:
            s = max(spread, key=lambda s: (abs(np.log(far[s.name])), s.name))
            name = s.name
            why = (f"the fit moved it to {far[name]:.2f}x the configured value, {ABSORBED}"
                   f" ({s.describe(name)}): structure "
                   f"the linear model lacks, taken into it")
            alt = held_at_configured(result, name)
        else:
            untested = sorted(n for n in far if n not in tested)
            if not untested:
                break
            tested.update(untested)
            alts = {n: held_at_configured(result, n) for n in untested}
            costs = {n: fitter.cost(a.theta, result.sigma) for n, a in alts.items()}
            floor = min(fitter.cost(result.theta, result.sigma), *costs.values())
            limits = {n: lr_threshold(result, n) for n in untested}
            ok = [n for n in untested if costs[n] - floor < limits[n]]
            if not ok:
                break
            least = min(costs[n] for n in ok)
            name = max((n for n in ok if costs[n] - least < limits[n]),
                       key=lambda n: (abs(np.log(far[n])), n))
            alt = alts[name]
            why = (f"the fit moved it to {far[name]:.2f}x the configured value, but held "
                   f"there the cost is {costs[name] - floor:+.3g} above the lowest of the "
                   f"free fit and the far parameters held one at a time (significant above "
                   f"{limits[name]:.3g})")
        held[name] = f"{why}; held at {configured[IDX[name]]:.4g}"
        alt.held = {**result.held, name: held[name]}
        result = alt
    return result, held


def baseline_free(exp: Experiment) -> list[str]:
    """The baseline's fitted parameters for this record: the linear model of the load kind,
    J_p where the motor encoder pins the rotor's inertia, J_c where the piston encoder pins
    the piston's, the strain offset, and the input/output timing skew (a nuisance)."""
    free = list(BASELINE_FREE[exp.load])
    if "omega_m" in exp.channels:
        free.append("jp")
    if exp.load != "fixed" and "v_piston" in exp.channels:
        free.append("jc")
    if "f_strain" in exp.channels:
        free.append("strain_offset_n")
    free.append("skew_s")
    # the sensors' own lags: told apart from the input's skew by the encoder, which has none
    if any(c in exp.channels for c in PRESSURE_CHANNELS):
        free.append("lag_pressure_s")
    if "f_strain" in exp.channels:
        free.append("lag_strain_s")
    return free


def fit_baseline(model: FastModel, theta0: np.ndarray | None = None,
                 extra_free: tuple[str, ...] = (), scales: dict[str, float] | None = None,
                 judge: Judge | None = None) -> FitResult:
    """Fit the linear model of thesis ch. 2 (plus ``extra_free`` effect parameters).

    Parameters that are not credible (a bound reached, or a confidence interval wider than
    the value) are held at the preset's values, one at a time, and the fit is repeated;
    so are those far from the configuration that the data do not ask for
    (:func:`hold_unsupported`, its consistency computed by ``judge``).
    """
    exp = model.exp
    theta = model.start_vector() if theta0 is None else theta0.copy()
    free = baseline_free(exp)
    free += [p for p in extra_free if p not in free]
    scales = {**NUISANCE_SCALES(exp.dt), **(scales or {})}
    fitter = OutputErrorFit(model, scales)
    result, held = guarded_fit(fitter, theta, free, model.start_vector())
    result, profiled = hold_unsupported(fitter, result, model.start_vector(), judge=judge)
    held.update(profiled)
    result.held = {n: f"not identifiable from this record: {why}" for n, why in held.items()}
    result.n_sims = fitter.n_sims
    return result


__all__ = ["BASELINE_FREE", "CREDIBLE", "FitResult", "OutputErrorFit", "baseline_free",
           "bounds_of", "fit_baseline", "guarded_fit", "hold_unsupported", "lr_threshold"]
