"""Is the fitted model the same in every frequency band and every stretch of time?

A white residual says the model reproduces the record; it does not say the model has the
rig's structure. A model that lacks an effect can often whiten its residual by moving its
parameters (a series elasticity with a frequency-dependent part fitted as one stiffness),
and then the parameters it needs differ with the part of the data that pins them: the
stiffness the high band asks for is not the one the low band asks for. Parameters far from
the configured (datasheet) values are no such evidence: another rod, another hose, another
fixture make a different rig, whose parameters are the same in every band.

The test refits the fitted parameters on parts of the estimation data, linearised at the
whole-record optimum (one Gauss-Newton step on the fit's own weighted Jacobian and
residual, which costs no simulation), in three splits:

* **frequency bands**: per parameter, its information (the energy of its Jacobian column
  over frequency, all channels, up to :data:`MAX_BAND_SHARE` of the Nyquist frequency) is
  cut into :data:`N_BANDS` bands of equal share, so each
  band pins it about equally well; each band's fit keeps only the DFT bins in the band
  (the band-passed output error). Its covariance is a sandwich over the bins: neighbouring
  bins of a record that is not periodic in its window share leakage, so the scores' long-run
  covariance is a Bartlett sum over :data:`BIN_LAGS` bins; over frequency, unequal noise
  levels are what the sandwich is for;
* **time segments**: :data:`N_SEGMENTS` consecutive stretches of the estimation part (a
  parameter that drifts: a viscosity with the oil's temperature, air coming out of the oil).
  This split is judged by a *trend*, not by homogeneity: a weighted straight line through
  the segments' log-estimates against the segments' mid-times, its slope tested against its
  interval (chi^2 on one degree of freedom) and its change over the estimation part held
  against the material ratio. A record whose slow input gives each few-second segment a
  different operating point (the free piston's multisine: one segment mostly stuck in the
  seal's linear zone, the next mostly sliding) makes a consistent rig's dampers scatter
  between segments beyond their intervals without any drift; homogeneity rejected such a
  rig, a trend does not. A parameter that goes and comes back within the record is missed;
* **channel groups** (piston fixed or on the conrod): the pressures and the strain (the
  forces) against the encoders. Each sees the parameters through a different path (the
  rotor's equation with the measured force in it, the hydraulics that make that force), and
  a model lacking
  a part of that path reconciles them only with different values (a Maxwell branch in the
  series elasticity: the stiffness the rotor needs is not the one the pressures need).

Time segments and channel groups take the Newey-West covariance of the fit's own confidence
intervals. Every other fitted parameter is refitted in each part as well, with a weak pull
to its whole-record value (:data:`PRIOR_SHARE` of its whole-record information), so a part
that does not pin a parameter leaves it there instead of making the system singular.

A parameter is *inconsistent* when the parts disagree beyond their confidence intervals
(the chi^2 homogeneity statistic over the parts, or the time split's trend statistic,
Holm-corrected over the parameters and the
splits, below :data:`ALPHA`) by a material amount (the furthest parts at least
:data:`MATERIAL_RATIO` apart). The report names the parameter, the two parts furthest apart,
their estimates with 95 % intervals and the ratio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.stats as sps

from hil.identify import stats
from hil.identify.experiment import Experiment
from hil.identify.fit import LOG_PARAMS, Z95, FitResult

#: Parts of each split.
N_BANDS = 3
N_SEGMENTS = 3
#: Bartlett bandwidth over DFT bins for the bands' score covariance.
BIN_LAGS = 4
#: Fewest DFT bins in a band: a parameter whose information sits in a narrower peak (J_c at
#: a resonance near the top of the bands) gets fewer bands, or none, rather than a band of
#: a few bins on a resonance's flank.
MIN_BAND_BINS = 32
#: Weak pull of every parameter to its whole-record value in a part's fit, as a share of
#: its whole-record information: negligible where the part pins it, decisive where not.
PRIOR_SHARE = 1e-3
#: Family-wise level of the homogeneity tests: strong evidence only. A part's fit is one
#: linearised step and its covariance is estimated from that part alone, approximations
#: whose tails are not to be trusted at the 1 % level (weakly pinned parameters of
#: consistent rig records reach p = 1e-3, and p = 1e-4: the free piston with the viscosity's
#: law, rig seed 1, ``k_s`` 8.6x apart between bands with 95 % intervals of 2x either way,
#: at 1.00e-4 or 1.05e-4 after the Holm step as the fits' stop falls). A decade below the
#: highest such p, so that where a fit along a flat valley ends does not decide.
ALPHA = 1e-5
#: Highest frequency the bands reach, as a share of the Nyquist frequency: above it the
#: sampled model and a real log part ways by construction (the fit's zero-order-hold
#: sub-steps against a continuous plant, first-order sensor lags, no anti-aliasing filter),
#: so a band there would measure the sampling, not the plant (at 0.5, the flank of the free
#: piston's 1.3 kHz resonance put J_c 7 % apart in a consistent record).
MAX_BAND_SHARE = 0.4
#: Least ratio between the furthest parts for a disagreement to count. Records of the
#: independent rig without a missing effect (the model's integrator, sensors and friction
#: laws are not the rig's) show significant differences of up to about 1 % in the best-pinned
#: parameters (K to 0.02 %); a record grown longer makes them more significant, not larger.
MATERIAL_RATIO = 1.03
#: The same for the channel groups, which the rig and the model reconcile less well: the
#: encoder speeds are windowed differences of counts, and with the piston free the
#: leakage d_s is the small difference of two large speeds (the independent rig's null
#: records show up to 4 %).
MATERIAL_RATIO_CHANNELS = 1.06
#: Parameters the channel groups judge: those of the pump and the hydraulics, which both the
#: forces and the motor encoder pin. The piston's (d_c, J_c, k_rod, c_rod) reach the encoders
#: through the piston encoder alone, weakly (a heavy piston on a stiff rod: d_c 15 % apart
#: between the groups without any missing effect).
CHANNEL_JUDGED = ("gain_n_per_a", "ds", "dp", "ks", "jp")
#: Parameters judged: the linear model's physical ones (fitted as logarithms, so a part's
#: estimate and its interval are relative, and the ratio between parts is well defined),
#: but the rod's damping c_rod: on the strain channel a first-order sensor lag tau looks
#: like a damping -tau k_rod, so per band c_rod trades with the strain lag (a soft rod's
#: c_rod came out 29 and 167 N s/m in two bands of a consistent record).
JUDGED = ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod")
#: The encoder channels, each a group of its own; the forces are the other.
SPEEDS = ("omega_m", "v_piston")


@dataclass
class PartEstimate:
    """A parameter fitted on one part: value and 95 % interval (its own units)."""

    part: str
    value: float
    ci_low: float
    ci_high: float

    def as_dict(self) -> dict:
        return {"part": self.part, "value": self.value, "ci95": [self.ci_low, self.ci_high]}


@dataclass
class ParameterSplit:
    """One parameter over the parts of one split (``frequency`` or ``time``)."""

    name: str
    split: str
    parts: list[PartEstimate]
    statistic: float
    dof: int
    p_value: float
    p_holm: float = 1.0
    #: the two parts furthest apart (indices into ``parts``, the lower first) and their ratio
    #: (>= 1); for a trend the first and last segments and the line's change over the record
    far: tuple[int, int] = (0, 0)
    ratio: float = 1.0
    #: a trend's relative change per second (log-units/s), None for a homogeneity test
    slope_per_s: float | None = None

    @property
    def inconsistent(self) -> bool:
        material = MATERIAL_RATIO_CHANNELS if self.split == "channels" else MATERIAL_RATIO
        return self.p_holm < ALPHA and self.ratio >= material

    def describe(self, symbol: str) -> str:
        a, b = (self.parts[i] for i in self.far)
        if self.slope_per_s is not None:
            return (f"{symbol} drifts {100 * self.slope_per_s:+.2g} %/s "
                    f"({self.ratio:.2f}x over the record, p={self.p_holm:.2g}): "
                    f"{b.value:.4g} [{b.ci_low:.4g}, {b.ci_high:.4g}] at {b.part} vs "
                    f"{a.value:.4g} [{a.ci_low:.4g}, {a.ci_high:.4g}] at {a.part}")
        return (f"{symbol} {b.value:.4g} [{b.ci_low:.4g}, {b.ci_high:.4g}] at {b.part} vs "
                f"{a.value:.4g} [{a.ci_low:.4g}, {a.ci_high:.4g}] at {a.part} "
                f"({self.ratio:.2f}x, p={self.p_holm:.2g})")

    def as_dict(self) -> dict:
        out = {"parameter": self.name, "split": self.split, "statistic": self.statistic,
               "dof": self.dof, "p_value": self.p_value, "p_holm": self.p_holm,
               "ratio": self.ratio, "inconsistent": self.inconsistent,
               "parts": [p.as_dict() for p in self.parts]}
        if self.slope_per_s is not None:
            out["slope_per_s"] = self.slope_per_s
        return out


@dataclass
class Consistency:
    """The outcome of :func:`consistency`."""

    splits: list[ParameterSplit] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def inconsistent(self) -> list[ParameterSplit]:
        return [s for s in self.splits if s.inconsistent]

    def as_dict(self) -> dict:
        return {"tests": [s.as_dict() for s in self.splits], "notes": list(self.notes),
                "inconsistent": [f"{s.name} ({s.split})" for s in self.inconsistent]}


def _equal_information_edges(info: np.ndarray, k0: int, parts: int) -> list[int]:
    """Bin edges cutting ``info[k0:]`` into ``parts`` runs of equal sum."""
    cum = np.cumsum(info[k0:])
    total = float(cum[-1]) if cum.size else 0.0
    edges = [k0]
    for j in range(1, parts):
        edges.append(k0 + int(np.searchsorted(cum, total * j / parts)) + 1)
    edges.append(info.size)
    return edges


def _part_fit(h: np.ndarray, g: np.ndarray, prior: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """The Gauss-Newton step ``-(H + P)^-1 g`` and ``(H + P)^-1`` (None if singular).

    The fit's Jacobian is that of its residual, measured minus model (``J = -d y_hat/dx``),
    and ``g = J'r``: the step that lowers ``|r + J s|^2`` is ``-(J'J)^-1 J'r``. With the
    sign the other way round the test's statistic is the same (it is symmetric in the
    parts' deviations), but every part's estimate is mirrored about the whole-record value:
    a damper that falls as the oil warms up was reported rising."""
    a = h + np.diag(prior)
    try:
        inv = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return None
    return -(inv @ g), inv


def _rows_fit(js: np.ndarray, rs: np.ndarray, prior: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """A part's step and its Newey-West covariance from its rows: Jacobian ``js`` (channels x
    samples x parameters) and residual ``rs`` (channels x samples)."""
    # the products as matrix products of the rows stacked (BLAS, a few times faster than
    # the same sums by einsum; the same values but for the order of the additions)
    flat = js.reshape(-1, js.shape[-1])
    h = flat.T @ flat
    g = flat.T @ rs.reshape(-1)
    sol = _part_fit(h, g, prior)
    if sol is None:
        return None
    step, inv = sol
    e = rs + (flat @ step).reshape(rs.shape)  # the part's residual after its step
    scores = np.einsum("ctp,ct->tp", js, e)
    lags = stats.nw_lags(e.shape[1], stats.correlation_length(e.sum(axis=0), 400))
    return step, inv @ stats.newey_west(scores, lags) @ inv


def _homogeneity(name: str, split: str, x: np.ndarray, se: np.ndarray, labels: list[str],
                 value: float) -> ParameterSplit | None:
    """chi^2 test that the parts' log-estimates ``x`` (steps from the whole-record value) with
    standard errors ``se`` are one value; the parts in the parameter's units."""
    ok = np.isfinite(x) & np.isfinite(se) & (se > 0)
    if ok.sum() < 2:
        return None
    w = 1.0 / se[ok] ** 2
    mean = float(np.sum(w * x[ok]) / np.sum(w))
    q = float(np.sum(w * (x[ok] - mean) ** 2))
    dof = int(ok.sum()) - 1
    parts = [PartEstimate(lbl, value * _exp(xi), value * _exp(xi - Z95 * s),
                          value * _exp(xi + Z95 * s))
             for lbl, xi, s in zip(labels, x, se, strict=True)]
    idx = np.flatnonzero(ok)
    lo = int(idx[np.argmin(x[ok])])
    hi = int(idx[np.argmax(x[ok])])
    return ParameterSplit(name, split, parts, q, dof, float(sps.chi2.sf(q, dof)),
                          far=(lo, hi), ratio=_exp(float(x[hi] - x[lo])))


def _trend(name: str, x: np.ndarray, se: np.ndarray, times: np.ndarray, labels: list[str],
           value: float, duration: float) -> ParameterSplit | None:
    """Test that the segments' log-estimates ``x`` (standard errors ``se``, mid-times
    ``times``) lie on a flat line: the weighted least-squares slope against its own
    interval (chi^2 on 1 degree of freedom); the ratio is the line's change over
    ``duration`` seconds. Scatter about the line (a segment's operating point) is not a
    drift and does not count."""
    ok = np.isfinite(x) & np.isfinite(se) & (se > 0)
    if ok.sum() < 2:
        return None
    w = 1.0 / se[ok] ** 2
    tc = times[ok] - float(np.sum(w * times[ok]) / np.sum(w))
    sxx = float(np.sum(w * tc * tc))
    if not sxx > 0:
        return None
    slope = float(np.sum(w * tc * x[ok]) / sxx)
    q = slope * slope * sxx  # (slope / its standard error)^2
    parts = [PartEstimate(lbl, value * _exp(xi), value * _exp(xi - Z95 * s),
                          value * _exp(xi + Z95 * s))
             for lbl, xi, s in zip(labels, x, se, strict=True)]
    idx = np.flatnonzero(ok)
    first, last = int(idx[0]), int(idx[-1])
    far = (first, last) if slope >= 0 else (last, first)
    return ParameterSplit(name, "time", parts, q, 1, float(sps.chi2.sf(q, 1)), far=far,
                          ratio=_exp(abs(slope) * duration), slope_per_s=slope)


def _exp(v: float) -> float:
    """``exp(v)``, infinite beyond the floats' range: a part that barely pins a parameter
    can take a linearised step of hundreds of e-folds (the baseline's fit on its way, before
    a weakly pinned parameter is held), which is reported as such, not raised."""
    return math.exp(v) if not v >= 709.0 else math.inf  # (a NaN stays NaN)


def _band(f_lo: float, f_hi: float) -> str:
    return f"{f_lo:.3g}-{f_hi:.3g} Hz"


def consistency(fit: FitResult, exp: Experiment, mask: np.ndarray,
                n_bands: int = N_BANDS, n_segments: int = N_SEGMENTS) -> Consistency:
    """Refit ``fit``'s parameters on frequency bands, time segments and channel groups of the
    estimation samples ``mask`` (the fit's own) and test that they agree (module docstring)."""
    out = Consistency()
    judged = [p for p in JUDGED if p in fit.free and p in LOG_PARAMS]
    if fit.jac is None or not judged:
        out.notes.append("no fitted physical parameter to judge")
        return out
    rows = np.flatnonzero(mask)
    n_ch = len(exp.channels)
    n_t = rows.size
    p = len(fit.free)
    if fit.jac.shape != (n_ch * n_t, p):
        out.notes.append("the fit's Jacobian does not cover the estimation samples")
        return out
    jac = fit.jac.reshape(n_ch, n_t, p)
    w = fit.weights or fit.sigma
    res = np.stack([np.nan_to_num((exp.measured[c] - fit.outputs[c])[rows] / w[c])
                    for c in exp.channels])
    h_all = fit.jac.T @ fit.jac
    prior = PRIOR_SHARE * np.maximum(np.diag(h_all), 1e-300)
    col = {n: fit.free.index(n) for n in judged}
    splits: list[ParameterSplit] = []

    # --- frequency bands ------------------------------------------------------------------
    span = rows[-1] - rows[0] + 1
    freqs = np.fft.rfftfreq(span, exp.dt)
    k0 = 2  # the mean and the slowest bin carry the start-up transient and the offsets
    k_max = int(np.searchsorted(freqs, MAX_BAND_SHARE * 0.5 / exp.dt))
    freqs = freqs[:k_max]
    # each column's transform along its own contiguous row, then the bins kept as
    # (bin, channel, parameter), their real and imaginary parts apart: every per-bin sum
    # below is then a batched real matrix product (BLAS) in place of a complex einsum
    # (one channel at a time: a tenth of a record's Jacobian in flight, not all of it)
    jr = np.empty((k_max, n_ch, p))
    ji = np.empty((k_max, n_ch, p))
    col_t = np.zeros((p, span))
    for c in range(n_ch):
        col_t[:, rows - rows[0]] = jac[c].T
        jf = np.fft.rfft(col_t, axis=-1)[:, :k_max]
        jr[:, c, :] = jf.real.T
        ji[:, c, :] = jf.imag.T
    del col_t, jf
    rf_t = np.zeros((n_ch, span))
    rf_t[:, rows - rows[0]] = res
    rf = np.fft.rfft(rf_t, axis=-1)[:, :k_max]
    del rf_t
    rr = np.ascontiguousarray(rf.real.T)
    ri = np.ascontiguousarray(rf.imag.T)
    # per bin: information (p x p) and gradient, summed over channels (Re J^H J, Re J^H r)
    jr_t, ji_t = jr.transpose(0, 2, 1), ji.transpose(0, 2, 1)
    h_bins = np.matmul(jr_t, jr) + np.matmul(ji_t, ji)
    g_bins = np.matmul(jr_t, rr[:, :, None])[:, :, 0] + np.matmul(ji_t, ri[:, :, None])[:, :, 0]
    h_cum = np.concatenate([np.zeros((1, p, p)), np.cumsum(h_bins, axis=0)])
    g_cum = np.concatenate([np.zeros((1, p)), np.cumsum(g_bins, axis=0)])
    scale = float(np.trace(h_cum[-1]) / max(np.trace(h_all), 1e-300))
    for name in judged:
        i = col[name]
        for parts in range(n_bands, 1, -1):
            edges = _equal_information_edges(h_bins[:, i, i], k0, parts)
            if min(np.diff(edges)) >= MIN_BAND_BINS:
                break
        else:
            continue  # the information sits in a few bins: nothing to compare
        xs, ses, labels = [], [], []
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            sol = _part_fit(h_cum[b] - h_cum[a], g_cum[b] - g_cum[a], prior * scale)
            if sol is None:
                xs.append(np.nan)
                ses.append(np.nan)
            else:
                step, inv = sol
                # the band's residual after its step, and its scores Re(J^H e) per bin
                er = rr[a:b] + jr[a:b] @ step
                ei = ri[a:b] + ji[a:b] @ step
                scores = (np.matmul(jr_t[a:b], er[:, :, None])[:, :, 0]
                          + np.matmul(ji_t[a:b], ei[:, :, None])[:, :, 0])
                meat = stats.newey_west(scores, BIN_LAGS)
                cov = inv @ meat @ inv
                xs.append(float(step[i]))
                ses.append(float(math.sqrt(max(cov[i, i], 0.0))))
            labels.append(_band(freqs[a], freqs[min(b, freqs.size - 1)]))
        s = _homogeneity(name, "frequency", np.array(xs), np.array(ses), labels,
                         fit.value(name))
        if s is not None:
            splits.append(s)

    # --- time segments and channel groups ---------------------------------------------------
    bounds = np.linspace(0, n_t, n_segments + 1).astype(int)
    t = exp.data.t
    segments = [(slice(None), slice(a, b), f"{t[rows[a]]:.3g}-{t[rows[b - 1]]:.3g} s")
                for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    mid_times = np.array([float(np.mean(t[rows[a:b]]))
                          for a, b in zip(bounds[:-1], bounds[1:], strict=True)])
    duration = float(t[rows[-1]] - t[rows[0]])
    groups = [([k for k, c in enumerate(exp.channels) if c not in SPEEDS], "the forces"),
              ([k for k, c in enumerate(exp.channels) if c in SPEEDS], "the encoders")]
    # with the piston free the forces are the few newtons the piston needs: they pin little,
    # and d_s there is the small difference of two large speeds (a consistent rig with a 4x
    # heavier piston: d_s 11 % apart between the groups); the split is for the loads that
    # carry the force
    channel_parts = ([(g, slice(None), label) for g, label in groups if g]
                     if exp.load != "free" else [])
    for split, parts in (("time", segments), ("channels", channel_parts)):
        fits = [_rows_fit(jac[ch][:, tt], res[ch][:, tt], prior) for ch, tt, _ in parts]
        if len(fits) < 2 or any(f is None for f in fits):
            continue
        for name in judged:
            if split == "channels" and name not in CHANNEL_JUDGED:
                continue
            i = col[name]
            x = np.array([f[0][i] for f in fits])
            se = np.array([math.sqrt(max(f[1][i, i], 0.0)) for f in fits])
            labels = [lbl for _, _, lbl in parts]
            if split == "time":
                s = _trend(name, x, se, mid_times, labels, fit.value(name), duration)
            else:
                s = _homogeneity(name, split, x, se, labels, fit.value(name))
            if s is not None:
                splits.append(s)

    for s, ph in zip(splits, stats.holm([s.p_value for s in splits]), strict=True):
        s.p_holm = ph
    out.splits = splits
    return out


__all__ = ["ALPHA", "MATERIAL_RATIO", "Consistency", "ParameterSplit", "PartEstimate",
           "consistency"]
