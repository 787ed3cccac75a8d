"""The consistency test's sums as matrix products (:func:`hil.identify.consistency.consistency`):
the per-bin information and gradient as real batched products of the transforms' real and
imaginary parts, the rows' products of a part as one stacked product. Checked against the
sums written out as complex einsums over a small random Jacobian and residual (the values
the parts' estimates come from, to rounding)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from hil.identify import consistency as cons
from hil.identify import stats
from hil.identify.fit import FitResult
from hil.identify.model import IDX, N_PARAMS

FREE = ["gain_n_per_a", "ds", "dp", "ks", "skew_s"]


def _case(seed: int = 3):
    rng = np.random.default_rng(seed)
    fs, n = 5000.0, 2400
    channels = ["p_pump_a", "f_strain", "omega_m"]
    n_ch, p = len(channels), len(FREE)
    mask = np.ones(n, bool)
    mask[:40] = False  # the estimation part is a stretch of the record
    n_t = int(mask.sum())
    # white columns, some with a share of a slow (summed) part: unequal spectra
    jac = rng.normal(size=(n_ch, n_t, p))
    jac += np.cumsum(rng.normal(size=(n_ch, n_t, p)), axis=1) * (0.02 * np.arange(p))
    measured = {c: rng.normal(size=n) for c in channels}
    outputs = {c: np.zeros(n) for c in channels}
    theta = np.zeros(N_PARAMS)
    for name in FREE:
        theta[IDX[name]] = 2.0
    fit = FitResult(theta, list(FREE), {}, dict.fromkeys(channels, 1.0), outputs,
                    np.zeros((1, 1)), jac=jac.reshape(n_ch * n_t, p),
                    weights=dict.fromkeys(channels, 1.0))
    exp = SimpleNamespace(channels=channels, measured=measured, dt=1.0 / fs,
                          data=SimpleNamespace(t=np.arange(n) / fs), load="conrod")
    return fit, exp, mask, jac


def _reference_bands(fit, exp, mask, jac) -> dict[str, list[float]]:
    """The band estimates by the sums written out (complex einsums over channels)."""
    rows = np.flatnonzero(mask)
    n_ch, n_t, p = jac.shape
    res = np.stack([(exp.measured[c] - fit.outputs[c])[rows] for c in exp.channels])
    prior = cons.PRIOR_SHARE * np.maximum(np.diag(fit.jac.T @ fit.jac), 1e-300)
    jf = np.fft.rfft(jac, axis=1)
    rf = np.fft.rfft(res, axis=1)
    freqs = np.fft.rfftfreq(n_t, exp.dt)
    k_max = int(np.searchsorted(freqs, cons.MAX_BAND_SHARE * 0.5 / exp.dt))
    jf, rf = jf[:, :k_max], rf[:, :k_max]
    h_bins = np.einsum("ckp,ckq->kpq", jf.conj(), jf).real
    g_bins = np.einsum("ckp,ck->kp", jf.conj(), rf).real
    scale = float(np.trace(h_bins.sum(axis=0)) / np.trace(fit.jac.T @ fit.jac))
    out = {}
    for name in ("ds", "dp", "ks", "gain_n_per_a"):
        i = FREE.index(name)
        for parts in range(cons.N_BANDS, 1, -1):
            edges = cons._equal_information_edges(h_bins[:, i, i], 2, parts)
            if min(np.diff(edges)) >= cons.MIN_BAND_BINS:
                break
        else:
            continue
        xs = []
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            step, inv = cons._part_fit(h_bins[a:b].sum(axis=0), g_bins[a:b].sum(axis=0),
                                       prior * scale)
            e = rf[:, a:b] + np.einsum("ckp,p->ck", jf[:, a:b], step)
            scores = np.einsum("ckp,ck->kp", jf[:, a:b].conj(), e).real
            cov = inv @ stats.newey_west(scores, cons.BIN_LAGS) @ inv
            xs += [float(step[i]), math.sqrt(cov[i, i])]
        out[name] = xs
    return out


def _reference_rows(js, rs, prior):
    h = np.einsum("ctp,ctq->pq", js, js)
    g = np.einsum("ctp,ct->p", js, rs)
    step, inv = cons._part_fit(h, g, prior)
    e = rs + np.einsum("ctp,p->ct", js, step)
    scores = np.einsum("ctp,ct->tp", js, e)
    lags = stats.nw_lags(e.shape[1], stats.correlation_length(e.sum(axis=0), 400))
    return step, inv @ stats.newey_west(scores, lags) @ inv


def test_band_estimates_are_the_complex_sums():
    fit, exp, mask, jac = _case()
    c = cons.consistency(fit, exp, mask)
    ref = _reference_bands(fit, exp, mask, jac)
    bands = {s.name: s for s in c.splits if s.split == "frequency"}
    assert set(bands) == set(ref)
    for name, s in bands.items():
        # the parts' estimates and intervals, back from the log steps and their errors
        v = fit.value(name)
        got = [x for part in s.parts for x in (math.log(part.value / v),
                                               math.log(part.ci_high / part.value) / cons.Z95)]
        np.testing.assert_allclose(got, ref[name], rtol=1e-8, atol=1e-12)


def test_a_parts_rows_are_the_stacked_product():
    fit, exp, mask, jac = _case(5)
    rs = np.random.default_rng(9).normal(size=jac.shape[:2])
    prior = np.full(jac.shape[2], 1e-3)
    part = jac[[0, 2]][:, 100:900]
    step, cov = cons._rows_fit(part, rs[[0, 2]][:, 100:900], prior)
    ref_step, ref_cov = _reference_rows(part, rs[[0, 2]][:, 100:900], prior)
    np.testing.assert_allclose(step, ref_step, rtol=1e-9)
    np.testing.assert_allclose(cov, ref_cov, rtol=1e-9)
