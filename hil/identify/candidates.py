"""The test of each candidate effect against the residual (the library itself, one class per
effect, is :mod:`hil.identify.effects`).

Each candidate is a set of parameters of the fast model (:mod:`hil.identify.model`) that are
zero in the linear model. Its *signature* is the sensitivity of every output channel to those
parameters, taken by simulating the current model with each parameter stepped by a quarter
of its nominal size (so the effect acts through the model's own dynamics, feedback included).
The test is a score-type regression of the weighted output-error residual on the signature:

1. **Partial out** what the model already declares: the signature is projected off the
   Jacobian of the fitted parameters (Frisch-Waugh), so an effect that a refit of d_s, d_p,
   k_s ... would absorb explains nothing.
2. **Refuse** what the data cannot identify: a column that keeps less than 1 % of its norm
   after the projection is *collinear* with a declared parameter (named); a candidate whose
   realistic-size effect would stand less than 3 standard errors out of the noise is
   *not excited*; columns of one candidate that are collinear with each other are dropped.
3. **Test**: least-squares coefficients ``beta`` of the residual on the projected signature,
   their covariance by Newey-West (HAC) on the per-sample scores, Wald chi^2 and its p-value;
   Holm's correction over all candidates tested in a round.
   A candidate that *takes over a nuisance at its bound* (``input_delay``: the fit's timing
   skew pinned at +T/2) is judged at its own fit instead (Wald test of the estimate beyond
   the nuisance's reach, validation share by the refit): the restricted fit that a score
   test linearises at has already bent other parameters (sensor lags, gains, k_s and J_c) to
   imitate it, so its local signature is small or collinear there. That fit is the refit it
   gets if selected, so it is *deferred*: done only in a round where no score-tested
   candidate is selected (another effect's structure can pin the skew too; once that effect
   is in, the skew may come off its bound, and the delay is then not applicable).
4. **Rank**: by the share of the *held-out validation* residual variance the effect removes
   (with ``beta`` from the estimation part), then by the Wald statistic.

A candidate is *selected* when its Holm-adjusted p-value is below ``alpha`` (0.01) and it
removes at least 0.5 % of the validation residual's variance and its estimated size is at
least a fifth of the realistic size for one of its parameters: with long records a
statistically significant but negligible term (a delay of a fraction of a microsecond, a
ripple of a hundredth of a newton) would otherwise soak up the model's own small
imperfections.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.identify import stats
from hil.identify.experiment import Experiment
from hil.identify.model import OUTPUT_ONLY, map_threads

ALPHA = 0.01
#: Retained norm share below which a signature column is collinear with declared terms.
MIN_RETAINED = 0.01
#: A realistic-size effect must stand this many standard errors out to be identifiable.
MIN_DETECTABLE_Z = 3.0
MAX_SELF_COND = 1e3
#: Practical significance: least share of the validation residual variance removed.
MIN_SHARE = 0.005
#: ... and least size relative to the realistic (nominal) one, for at least one parameter.
MIN_MAGNITUDE = 0.2
#: Where the friction laws' shape starts its refit: between tanh (0) and atan (1), so the
#: data, not the start, picks the law.
FRICTION_SHAPE_START = 0.5
#: Why a candidate judged at its own fit is not judged yet.
DEFERRED = "judged at its own fit, in a round where no other candidate is selected"


@dataclass(frozen=True)
class EffectDef:
    """One library entry: the model parameters it switches on and their nominal sizes."""

    name: str  # library name, e.g. "pump_pulsation"
    label: str  # instance label, e.g. "pump_pulsation[order=4]"
    params: tuple[str, ...]
    nominal: tuple[float, ...]  # realistic magnitude of each parameter (its unit)
    description: str
    applicable: Callable[[Experiment], str | None] = field(default=lambda exp: None,
                                                           compare=False)
    #: shape parameters freed only in the refit once the effect is in (their signature is
    #: zero while the effect is off): (parameter, start value from the experiment)
    refit_extra: tuple[tuple[str, Callable[[Experiment], float]], ...] = ()
    #: judged at its own fit (the module docstring, step 3), not by a score test
    judged_at_fit: bool = False
    #: most of the signature is, by construction, a change of declared parameters (the
    #: viscosity law referred to the preset's temperature rescales the dampers by the
    #: record's mean offset from it): identifiability is judged by the detectability of
    #: what the projection leaves, not by the share of the signature it leaves
    rescales_declared: bool = False


@dataclass(frozen=True)
class FitJudgement:
    """A candidate judged at its own fit: the estimates beyond the restricted model's reach
    (``excess``), their standard errors, and the shares of the estimation and validation
    residual variance the fit removed; or, in ``refused``, why the fit is not credible."""

    beta: dict[str, float] = field(default_factory=dict)
    excess: dict[str, float] = field(default_factory=dict)
    se: dict[str, float] = field(default_factory=dict)
    share_est: float = 0.0
    share_val: float = 0.0
    refused: str = ""


@dataclass
class CandidateTest:
    """The outcome of testing one candidate against the current residual."""

    label: str
    name: str
    params: list[str]
    status: str  # "tested" | "collinear" | "not_excited" | "not_applicable" | "deferred"
    reason: str = ""
    beta: dict[str, float] = field(default_factory=dict)
    se: dict[str, float] = field(default_factory=dict)
    nominal: dict[str, float] = field(default_factory=dict)
    wald: float = 0.0
    dof: int = 0
    p_value: float = 1.0
    p_holm: float = 1.0
    share_est: float = 0.0
    share_val: float = 0.0
    selected: bool = False

    @property
    def significant(self) -> bool:
        return self.status == "tested" and self.p_holm < ALPHA


def _pinv(a: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a tall matrix by its small Gram matrix (columns scaled to unit norm,
    then an SVD of the p x p Gram matrix): the same as ``np.linalg.pinv`` for the few
    well-scaled columns here, without an SVD of hundreds of thousands of rows."""
    if a.shape[1] == 0:
        return np.zeros((0, a.shape[0]))
    norms = np.linalg.norm(a, axis=0)
    norms[norms == 0.0] = 1.0
    an = a / norms
    gram_inv = np.linalg.pinv(an.T @ an, rcond=1e-12)
    return (gram_inv @ an.T) / norms[:, None]


def _weighted(outputs: dict[str, np.ndarray], exp: Experiment, sigma: dict[str, float],
              mask: np.ndarray) -> np.ndarray:
    parts = []
    for c in exp.channels:
        x = outputs[c][mask] / sigma[c]
        parts.append(x if np.isfinite(x).all() else np.nan_to_num(x))
    return np.concatenate(parts)


def test_candidates(
    defs: list[EffectDef],
    simulate: Callable[[np.ndarray], dict[str, np.ndarray]],
    theta: np.ndarray,
    index: dict[str, int],
    exp: Experiment,
    sigma: dict[str, float],
    residual: dict[str, np.ndarray],
    est_mask: np.ndarray,
    val_mask: np.ndarray,
    jac_names: list[str],
    judge_at_fit: Callable[[EffectDef], FitJudgement] | None = None,
    states: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[CandidateTest]:
    """Test every candidate in ``defs`` against ``residual`` (measured - model per channel).

    ``simulate(theta)`` returns the model channels; ``jac_names`` are the fitted (declared)
    parameters whose sensitivities are projected off each signature, on the estimation
    samples ``est_mask`` and, with the same coefficients, on the validation samples.
    A candidate marked :attr:`EffectDef.judged_at_fit` is judged by ``judge_at_fit(d)``; without
    it, it is left ``deferred`` for :func:`judge_deferred`. With ``states(theta)`` (the
    simulation alone, ``simulate(theta, states)`` mapping it to channels), a parameter that
    acts on the outputs only (:data:`~hil.identify.model.OUTPUT_ONLY`) is perturbed on the
    base states, without a simulation of its own.
    """
    base_z = states(theta) if states is not None else None
    base_out = simulate(theta) if base_z is None else simulate(theta, base_z)
    r_est = _weighted(residual, exp, sigma, est_mask)
    r_val = _weighted(residual, exp, sigma, val_mask)
    n_ch = len(exp.channels)
    n_t = int(est_mask.sum())
    # every perturbed simulation at once, on all cores: declared parameters, then signatures
    jobs: list[tuple[str, float]] = [(p, 1e-4 * abs(theta[index[p]]) or 1e-4)
                                     for p in jac_names]
    for d in defs:
        if not d.applicable(exp) and d.params and not d.judged_at_fit:
            jobs += [(p, 0.25 * nom) for p, nom in zip(d.params, d.nominal, strict=True)]

    def sens(job: tuple[str, float]) -> tuple[np.ndarray, np.ndarray]:
        p, step = job
        th = theta.copy()
        th[index[p]] += step
        out = simulate(th, base_z) if base_z is not None and p in OUTPUT_ONLY else simulate(th)
        diff = {c: (out[c] - base_out[c]) / step for c in exp.channels}
        return _weighted(diff, exp, sigma, est_mask), _weighted(diff, exp, sigma, val_mask)

    done = dict(zip(jobs, map_threads(sens, jobs), strict=True))
    j_est = [done[j][0] for j in jobs[: len(jac_names)]]
    j_val = [done[j][1] for j in jobs[: len(jac_names)]]
    jac = np.column_stack(j_est) if j_est else np.zeros((r_est.size, 0))
    jac_v = np.column_stack(j_val) if j_val else np.zeros((r_val.size, 0))
    jac_pinv = _pinv(jac)
    results: list[CandidateTest] = []
    for d in defs:
        t = CandidateTest(d.label, d.name, list(d.params), "tested")
        reason = d.applicable(exp)
        if reason or not d.params:
            t.status, t.reason = "not_applicable", reason or "no parameters"
            results.append(t)
            continue
        if d.judged_at_fit:
            if judge_at_fit is None:
                t.status, t.reason = "deferred", DEFERRED
            else:
                _judged(t, d, judge_at_fit(d))
            results.append(t)
            continue
        cols_est, cols_val, steps = [], [], []
        for p, nom in zip(d.params, d.nominal, strict=True):
            col_e, col_v = done[(p, 0.25 * nom)]
            cols_est.append(col_e)
            cols_val.append(col_v)
            steps.append(nom)
        x = np.column_stack(cols_est)
        xv = np.column_stack(cols_val)
        norms = np.linalg.norm(x, axis=0)
        jac_d, jac_vd, names_d, pinv_d = jac, jac_v, jac_names, jac_pinv
        proj = pinv_d @ x
        xp = x - jac_d @ proj
        xvp = xv - jac_vd @ proj
        kept_norm = np.linalg.norm(xp, axis=0)
        keep = []
        for j, p in enumerate(d.params):
            if norms[j] == 0.0:
                continue
            if kept_norm[j] ** 2 < MIN_RETAINED * norms[j] ** 2 and not d.rescales_declared:
                corr = (np.abs(jac_d.T @ x[:, j])
                        / (np.linalg.norm(jac_d, axis=0) * norms[j] + 1e-300))
                who = names_d[int(np.argmax(corr))] if names_d else "the model"
                t.reason = f"{p} collinear with declared {who} (|corr| {corr.max():.3f})"
                continue
            keep.append(j)
        if not keep:
            t.status = "collinear" if t.reason else "not_excited"
            t.reason = t.reason or "signature is zero: the data do not excite it"
            results.append(t)
            continue
        # drop columns collinear with each other inside the candidate
        gram_all = xp.T @ xp
        while len(keep) > 1:
            # condition of the unit-norm columns from their small Gram matrix
            g = gram_all[np.ix_(keep, keep)] / np.outer(kept_norm[keep], kept_norm[keep])
            ev = np.linalg.eigvalsh(g)
            if np.sqrt(ev[-1] / max(ev[0], 1e-300)) < MAX_SELF_COND:
                break
            keep.remove(min(keep, key=lambda j: kept_norm[j] / norms[j]))
        xk = xp[:, keep]
        gram = gram_all[np.ix_(keep, keep)]
        beta = np.linalg.solve(gram, xk.T @ r_est)
        fitted = xk @ beta
        e_alt = r_est - fitted
        scores = np.einsum("ctp,ct->tp", xk.reshape(n_ch, n_t, len(keep)),
                           e_alt.reshape(n_ch, n_t))
        corr_len = stats.correlation_length(e_alt.reshape(n_ch, n_t).sum(axis=0), 400)
        lags = stats.nw_lags(n_t, corr_len)
        s = stats.newey_west(scores, lags)
        hinv = np.linalg.pinv(gram)
        cov = hinv @ s @ hinv
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        names = [d.params[j] for j in keep]
        noms = np.array([steps[j] for j in keep])
        t.params = names
        t.beta = {n: float(b) for n, b in zip(names, beta, strict=True)}
        t.se = {n: float(v) for n, v in zip(names, se, strict=True)}
        t.nominal = {n: float(v) for n, v in zip(names, noms, strict=True)}
        detect = float(np.max(np.abs(noms) / np.maximum(se, 1e-300)))
        if detect < MIN_DETECTABLE_Z:
            t.status = "not_excited"
            t.reason = (f"a realistic-size effect would stand only {detect:.1f} standard "
                        f"errors out of the residual")
            results.append(t)
            continue
        t.wald, t.p_value, t.dof = stats.wald(beta, cov)
        rr = float(r_est @ r_est)
        t.share_est = float(1.0 - e_alt @ e_alt / rr) if rr > 0 else 0.0
        fv = xvp[:, keep] @ beta
        rv = float(r_val @ r_val)
        t.share_val = float(1.0 - np.sum((r_val - fv) ** 2) / rv) if rv > 0 else 0.0
        results.append(t)
    _holm(results)
    return results


def _holm(tests: list[CandidateTest]) -> None:
    tested = [t for t in tests if t.status == "tested"]
    if tested:
        for t, p in zip(tested, stats.holm([t.p_value for t in tested]), strict=True):
            t.p_holm = p


def judge_deferred(tests: list[CandidateTest], defs: list[EffectDef],
                   judge_at_fit: Callable[[EffectDef], FitJudgement]) -> bool:
    """Judge the ``deferred`` candidates of ``tests`` at their own fits (in place) and redo
    Holm's correction over the round; False when there were none."""
    by_label = {d.label: d for d in defs}
    deferred = [t for t in tests if t.status == "deferred"]
    for t in deferred:
        t.status, t.reason = "tested", ""
        _judged(t, by_label[t.label], judge_at_fit(by_label[t.label]))
    _holm(tests)
    return bool(deferred)


def _judged(t: CandidateTest, d: EffectDef, j: FitJudgement) -> None:
    """The test row of a candidate judged at its own fit: a Wald test of the estimates'
    excess over what the restricted model reaches (one-sided: only an excess counts), the
    shares the fit removed."""
    if j.refused:
        t.status, t.reason = "not_excited", j.refused
        return
    names = list(j.beta)
    t.params = names
    t.beta = dict(j.beta)
    t.se = dict(j.se)
    t.nominal = {p: nom for p, nom in zip(d.params, d.nominal, strict=True) if p in j.beta}
    excess = np.array([j.excess[p] for p in names])
    se = np.array([j.se[p] for p in names])
    if not np.all(np.isfinite(se)) or np.any(se <= 0.0):
        t.status, t.reason = "not_excited", "its fit gives no standard error"
        return
    t.wald, t.p_value, t.dof = stats.wald(excess, np.diag(se * se))
    if np.any(excess <= 0.0):
        t.p_value = 1.0
    t.share_est, t.share_val = j.share_est, j.share_val
    t.reason = "judged at its own fit: " + ", ".join(
        f"{p} {j.beta[p]:.4g} ({j.excess[p] / j.se[p]:+.1f} standard errors beyond the "
        "restricted model's reach)" for p in names)


def retested(tests: list[CandidateTest], defs: list[EffectDef]) -> list[CandidateTest]:
    """The round ``tests`` again for the candidates ``defs`` (a subset of them), on the same
    fit: a round whose best candidate was refused at its refit leaves the fit as it was, and
    the score tests of the next round would simulate the same signatures to the same bits.
    Copies, unselected, Holm's correction redone over the subset; a candidate judged at its
    own fit is deferred again (its fit is redone only in a round that needs it, as in a
    fresh round)."""
    by_label = {t.label: t for t in tests}
    out = []
    for d in defs:
        t = dataclasses.replace(by_label[d.label], selected=False)
        if d.judged_at_fit and t.status != "not_applicable":
            t = CandidateTest(d.label, d.name, list(d.params), "deferred", DEFERRED)
        out.append(t)
    _holm(out)
    return out


def rank(tests: list[CandidateTest]) -> list[CandidateTest]:
    """Significant candidates, best first (validation share, then Wald statistic)."""
    sig = [t for t in tests if t.significant and t.share_val >= MIN_SHARE
           and max(abs(t.beta[p]) / abs(t.nominal[p]) for p in t.beta) >= MIN_MAGNITUDE]
    return sorted(sig, key=lambda t: (t.share_val, t.wald), reverse=True)


__all__ = ["ALPHA", "CandidateTest", "EffectDef", "FitJudgement", "judge_deferred", "rank",
           "retested", "test_candidates"]
