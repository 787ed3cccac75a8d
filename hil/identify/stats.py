"""Statistics that stay valid when residuals are autocorrelated.

* :func:`newey_west` — heteroscedasticity- and autocorrelation-consistent (HAC) long-run
  covariance of per-sample score vectors, Bartlett kernel (Newey & West 1987);
* :func:`nw_lags` — its bandwidth: Newey-West's automatic rule ``4 (n/100)^(2/9)``, raised
  to the residual's own correlation length where that is longer;
* :func:`wald` — Wald test of a block of regression coefficients with a HAC covariance;
* :func:`holm` — Holm's step-down correction of p-values for testing many candidates;
* :func:`ljung_box` and :func:`acf` — whiteness of a residual.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps


def acf(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation at lags 1..max_lag (FFT, biased estimator)."""
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    n = x.size
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, nfft)
    r = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1]
    return r[1:] / r[0] if r[0] > 0 else np.zeros(max_lag)


def ccf(e: np.ndarray, u: np.ndarray, max_lag: int) -> np.ndarray:
    """Cross-correlation of residual ``e`` with input ``u`` at lags 0..max_lag
    (``e[k]`` against ``u[k - lag]``: the input leading, the causal direction)."""
    e = e - e.mean()
    u = u - u.mean()
    n = e.size
    den = np.sqrt(np.dot(e, e) * np.dot(u, u))
    if den == 0:
        return np.zeros(max_lag + 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    r = np.fft.irfft(np.fft.rfft(e, nfft) * np.conj(np.fft.rfft(u, nfft)), nfft)
    return r[: max_lag + 1] / den


def ljung_box(x: np.ndarray, lags: int) -> tuple[float, float]:
    """Ljung-Box Q over lags 1..``lags`` and its chi^2(lags) p-value."""
    n = x.size
    r = acf(x, lags)
    q = n * (n + 2) * float(np.sum(r * r / (n - np.arange(1, lags + 1))))
    return q, float(sps.chi2.sf(q, lags))


def correlation_length(x: np.ndarray, max_lag: int = 400) -> int:
    """First lag at which the autocorrelation of ``x`` drops below 0.05 (a decorrelation
    length, samples); ``max_lag`` if it never does."""
    r = acf(x, max_lag)
    below = np.flatnonzero(np.abs(r) < 0.05)
    return int(below[0]) + 1 if below.size else max_lag


def nw_lags(n: int, corr_len: int = 0) -> int:
    """Bartlett bandwidth: ``4 (n/100)^(2/9)``, at least twice the correlation length."""
    return int(max(np.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)), 2 * corr_len))


def newey_west(scores: np.ndarray, lags: int) -> np.ndarray:
    """Long-run covariance ``sum_l w_l Gamma_l`` of the rows of ``scores`` (n x p), with
    Bartlett weights ``w_l = 1 - |l|/(lags+1)``. Scores are used as given (their mean is zero
    at a least-squares optimum).

    Computed as the batch-mean form of the same kernel: with ``S_t`` the sum of the ``L + 1``
    scores from row ``t``, ``E[S_t S_t'] = (L+1) sum_l w_l gamma_l``, so
    ``n/((n-L)(L+1)) sum_t S_t S_t'`` estimates ``n sum_l w_l gamma_l`` in O(n p^2) whatever
    the bandwidth (the lag-by-lag sum costs O(n p^2 L), seconds at the bandwidths that
    correlated residuals need).
    """
    s = np.asarray(scores, dtype=float)
    if s.ndim == 1:
        s = s[:, None]
    n = s.shape[0]
    big_l = int(min(max(lags, 0), n - 1))
    if big_l == 0:
        return s.T @ s
    csum = np.concatenate([np.zeros((1, s.shape[1])), np.cumsum(s, axis=0)])
    win = csum[big_l + 1:] - csum[: n - big_l]
    return (win.T @ win) * (n / ((n - big_l) * (big_l + 1.0)))


def wald(beta: np.ndarray, cov: np.ndarray) -> tuple[float, float, int]:
    """Wald statistic ``beta' cov^-1 beta``, its chi^2 p-value and the degrees of freedom."""
    beta = np.atleast_1d(beta)
    k = beta.size
    try:
        w = float(beta @ np.linalg.solve(cov, beta))
    except np.linalg.LinAlgError:
        w = float(beta @ np.linalg.pinv(cov) @ beta)
    return w, float(sps.chi2.sf(w, k)), k


def holm(pvalues: list[float]) -> list[float]:
    """Holm-adjusted p-values (step-down Bonferroni), in the input order."""
    p = np.asarray(pvalues, dtype=float)
    m = p.size
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj.tolist()


__all__ = ["acf", "ccf", "correlation_length", "holm", "ljung_box", "newey_west", "nw_lags",
           "wald"]
