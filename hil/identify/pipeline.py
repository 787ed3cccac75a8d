"""The identification loop: baseline fit, residual tests, attribution, refit, report.

1. Fit the linear model of thesis ch. 2 (d_s, d_p, d_c, k_s, the current-to-force gain K; the
   rod stiffness with the conrod) by output-error simulation on the estimation part.
2. Analyse the residual on the held-out validation part (:mod:`hil.identify.residuals`).
3. Test every library candidate against the residual (:mod:`hil.identify.candidates`).
4. Add the best-supported one, refit everything by simulation, and keep it only if the
   validation cost drops by at least 0.5 %; repeat until no candidate is significant (several
   pulsation orders come in one per round).
5. Refit the final model's parameters on frequency bands, time segments and channel groups
   (:mod:`hil.identify.consistency`): parameters that disagree between them are structure
   the model lacks, even under a white residual.
6. Report NRMSE per channel before and after (validation part), the effects added with
   parameters and 95 % confidence intervals, the residual tests before and after, the
   parameters that differ from the configuration (a different rig: no verdict), and the
   verdict ``unexplained`` when the residual still has structure no candidate explains or
   the parameters disagree between parts of the record.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar
from threadpoolctl import threadpool_limits

from hil.identify.candidates import (
    MIN_MAGNITUDE,
    MIN_SHARE,
    CandidateTest,
    EffectDef,
    FitJudgement,
    judge_deferred,
    rank,
    retested,
    test_candidates,
)
from hil.identify.checks import check_fit, check_record
from hil.identify.consistency import JUDGED as CONSISTENCY_JUDGED
from hil.identify.consistency import Consistency, consistency
from hil.identify.csvdata import MeasuredData
from hil.identify.effects import EFFECTS, ParamEstimate, library
from hil.identify.experiment import Experiment, prepare, quantum
from hil.identify.fit import (
    ABSORBED,
    CREDIBLE,
    NUISANCE_SCALES,
    Z95,
    FitResult,
    OutputErrorFit,
    baseline_free,
    fit_baseline,
    guarded_fit,
    keep_freed_memory,
    lr_threshold,
    small_pages,
)
from hil.identify.model import IDX, FastModel
from hil.identify.noise import (
    CUTOFF_FACTOR,
    InputNoise,
    current_cutoff,
    estimate_input_noise,
    experiment_with_current,
    held_noise_draws,
    lowpass_current,
    noisy_experiment,
    predicted_draws,
    predicted_residual,
)
from hil.identify.residuals import ResidualAnalysis, analyse
from hil.identify.resonance import line_left, stiffness_at_line
from hil.identify.slowfirst import LowPassedPressures, pressures_finite
from plant.config import Config

#: Baseline parameters shown in the report, with units and thesis symbols.
BASELINE_LABELS = {
    "gain_n_per_a": ("K", "N/A", "current-to-force gain, piston-equivalent"),
    "ds": ("d_s", "N/(m/s)", "internal-leakage series damper"),
    "dp": ("d_p", "N/(m/s)", "pump viscous friction"),
    "dc": ("d_c", "N/(m/s)", "piston-side viscous friction"),
    "ks": ("k_s", "N/m", "series elasticity"),
    "jp": ("J_p", "kg", "rotor + pump inertia seen from the piston"),
    "jc": ("J_c", "kg", "piston + load mass"),
    "k_rod": ("k_rod", "N/m", "connecting-rod stiffness"),
    "c_rod": ("c_rod", "N/(m/s)", "connecting-rod damping"),
    "strain_offset_n": ("f_0", "N", "strain-gauge offset"),
    "skew_s": ("skew", "s", "timing skew of the logged input against the outputs (nuisance; "
               "applied current i(t - skew))"),
    "lag_pressure_s": ("tau_p_sensor", "s", "first-order lag of the pressure sensors (nuisance)"),
    "lag_strain_s": ("tau_strain", "s", "first-order lag of the strain measurement (nuisance)"),
}


@dataclass
class EffectAdded:
    """An effect the loop added, with its parameters (derived, physical form)."""

    name: str
    label: str
    params: dict[str, ParamEstimate]
    round: int
    p_holm: float
    share_val: float

    def as_dict(self) -> dict:
        return {"name": self.name, "label": self.label, "round": self.round,
                "p_holm": self.p_holm, "share_of_residual_variance": self.share_val,
                "params": {k: v.as_dict() for k, v in self.params.items()}}


@dataclass
class ChannelError:
    """Validation error of one channel before and after the effects were added."""

    channel: str
    nrmse_before: float
    nrmse_after: float

    @property
    def fit_before(self) -> float:
        return 100.0 * (1.0 - self.nrmse_before)

    @property
    def fit_after(self) -> float:
        return 100.0 * (1.0 - self.nrmse_after)


@dataclass
class IdentifyReport:
    """Everything the identification found (see the module docstring)."""

    path: str
    load: str
    n_samples: int
    sample_rate_hz: float
    baseline: dict[str, ParamEstimate]
    final: dict[str, ParamEstimate]
    held: dict[str, str]
    effects_added: list[EffectAdded]
    rounds: list[list[CandidateTest]]
    channels: list[ChannelError]
    residual_before: ResidualAnalysis
    residual_after: ResidualAnalysis
    unexplained: bool
    unexplained_detail: str
    notes: list[str] = field(default_factory=list)
    rejected: list[str] = field(default_factory=list)
    #: candidates refitted together (no single one passing, structure left): the effects,
    #: the relative change of the validation cost, the outcome ("added", "passes" or why not)
    joint: list[dict] = field(default_factory=list)
    #: why the joint search ran (the structure the fit left then) or did not ("" where its
    #: preconditions, a round and room for two more effects, were not met)
    joint_why: str = ""
    #: the effects found refitted from the configured values of the parameters their fit
    #: moved far (structure left): those parameters, the relative change of the validation
    #: cost, the outcome ("kept" or why not)
    restarts: list[dict] = field(default_factory=list)
    wall_s: float = 0.0
    # arrays for plots
    experiment: Experiment | None = None
    outputs_before: dict[str, np.ndarray] = field(default_factory=dict)
    outputs_after: dict[str, np.ndarray] = field(default_factory=dict)
    intersample: str = "zoh"
    intersample_reason: str = ""
    input_noise: InputNoise | None = None
    #: the final fit's parameters refitted on parts of the record, and whether they agree
    consistency: Consistency | None = None
    #: fitted parameters far from the configured values (symbol -> value, ci95, configured,
    #: ratio): the rig differs from the configuration, which is no verdict on the model
    differs: dict[str, dict] = field(default_factory=dict)

    def candidate_table(self) -> list[dict]:
        """One row per candidate: the round it was selected in, else the last round."""
        selected = {e.label for e in self.effects_added}
        rows: dict[str, dict] = {}
        for i, tests in enumerate(self.rounds):
            for t in tests:
                if t.label in rows and rows[t.label]["selected"]:
                    continue
                rows[t.label] = {
                    "name": t.name, "label": t.label, "round": i, "status": t.status,
                    "reason": t.reason, "statistic": t.wald, "dof": t.dof,
                    "p_value": t.p_value, "p_holm": t.p_holm,
                    "share_est": t.share_est, "share_val": t.share_val,
                    "significant": t.significant,
                    "selected": t.label in selected and t.selected,
                }
        return list(rows.values())


def nrmse(y: np.ndarray, yhat: np.ndarray) -> float:
    """||y - yhat|| / ||y - mean(y)|| over the finite samples (0 = perfect)."""
    ok = np.isfinite(y) & np.isfinite(yhat)
    y, yhat = y[ok], yhat[ok]
    den = float(np.linalg.norm(y - y.mean()))
    return float(np.linalg.norm(y - yhat) / den) if den > 0 else float("nan")


def _val_cost(exp: Experiment, out: dict[str, np.ndarray], sigma: dict[str, float]) -> float:
    cost = 0.0
    for c in exp.channels:
        e = (exp.measured[c] - out[c])[exp.val]
        cost += float(np.nansum(e * e)) / sigma[c] ** 2
    return cost


def _estimates(fit: FitResult, names: list[str]) -> dict[str, ParamEstimate]:
    out = {}
    for n in names:
        sym, unit, _ = BASELINE_LABELS[n]
        v = fit.value(n)
        if n in fit.se:
            lo, hi = fit.ci95(n)
        else:
            lo = hi = v
        out[sym] = ParamEstimate(sym, v, lo, hi, unit)
    return out


#: Relative cost difference under which two intersample modes fit equally well.
INTERSAMPLE_TIE = 2e-3


def choose_intersample(data: MeasuredData, cfg: Config, given: str | None,
                       say: Callable[[str], None]) -> tuple[Experiment, np.ndarray | None]:
    """The experiment with the input's intersample behaviour: as given, else estimated.

    Estimated: the baseline is fitted with the current band-limited between samples
    (``bl``) and the timing skew free over a whole sample (the provisional fit). Then
    ``bl``, ``foh`` and ``zoh`` are compared at that fit, each with the skew that suits it
    best, searched over 1.5 samples around the provisional skew (for ``zoh`` half a sample
    earlier: a held sample is, on average, a band-limited one half a sample late). The
    lower cost wins; costs within :data:`INTERSAMPLE_TIE` tie, and so does a mode whose best
    skew lies on its search's edge; a tie goes to ``bl``, then ``foh``.
    Returns the experiment and the parameter vector to start the baseline from.
    """
    if given is not None:
        exp = prepare(data, cfg, given)
        src = data.header.get("intersample")
        exp.intersample_reason = ("from the '# intersample:' header line" if src == given
                                  else "as given (--intersample)")
        return exp, None
    exp = prepare(data, cfg, "bl")
    model = FastModel(exp)
    fitter = OutputErrorFit(model, NUISANCE_SCALES(exp.dt))
    fitter.skew_limit = 1.0
    say("intersample: provisional fit, skew free over one sample")
    prov = fitter.fit(model.start_vector(), baseline_free(exp), passes=1, max_nfev=20)
    results: dict[str, tuple[float, float]] = {}
    bounded: set[str] = set()
    for mode in ("bl", "foh", "zoh"):
        f_mode = OutputErrorFit(FastModel(dataclasses.replace(exp, intersample=mode)))

        def cost(sk: float, f_mode: OutputErrorFit = f_mode) -> float:
            th = prov.theta.copy()
            th[IDX["skew_s"]] = sk
            return f_mode.cost(th, prov.sigma)

        centre = prov.value("skew_s") - (0.5 * exp.dt if mode == "zoh" else 0.0)
        lo, hi = centre - 0.75 * exp.dt, centre + 0.75 * exp.dt
        sol = minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                              options={"xatol": exp.dt / 200, "maxiter": 20})
        results[mode] = (float(sol.fun), float(sol.x))
        if min(sol.x - lo, hi - sol.x) <= exp.dt / 50:  # within four of the search's steps
            bounded.add(mode)
    ref = min(c for c, _ in results.values())
    # Below a few hundred hertz a staircase is a band-limited signal half a sample late, and
    # the costs tie: then the data cannot tell, and a logged current is taken for what a log
    # of a measured current is, a sampled continuous signal (bl before foh before zoh). A
    # mode whose best skew is on its search's edge has a lower cost beyond it: it ties with
    # any that beat it there (the skew on the edge is a model that lacks something taking
    # the timing for it, where the provisional fit stopped; by the last bits of the
    # arithmetic, a zoh would otherwise "fit best" a continuous current by half a per cent).
    tie = [m for m in results
           if results[m][0] <= (1.0 + INTERSAMPLE_TIE) * ref or m in bounded]
    best = next(m for m in ("bl", "foh", "zoh") if m in tie)
    detail = ", ".join(f"{m} {results[m][0] / ref:.5f} (skew {results[m][1] * 1e6:+.0f} us"
                       f"{', on its search edge' if m in bounded else ''})" for m in results)
    if len(tie) > 1:
        why = (f"{' and '.join(tie)} fit equally well (a staircase and a continuous current "
               f"half a sample apart look alike below a few hundred hertz); taken as "
               f"{best}, a sampled continuous current")
    else:
        why = f"{best} fits best"
    exp = prepare(data, cfg, best)
    exp.intersample_reason = f"estimated: {why} (relative cost with its best skew: {detail})"
    theta = prov.theta.copy()
    # The provisional fit is short and unguarded: a parameter the data barely pin (k_s with
    # its resonance above Nyquist) may still be running away when it stops, at a place set
    # by the last bits of the arithmetic. The baseline would start there, and on another
    # CPU's kernels it settled in another local minimum; a value the data did not pin is no
    # start, the configured one is.
    start = model.start_vector()
    for name, _, _ in fitter.offenders(prov):
        theta[IDX[name]] = start[IDX[name]]
    theta[IDX["skew_s"]] = float(np.clip(results[best][1], -0.5 * exp.dt, 0.5 * exp.dt))
    return exp, theta


def identify(
    data: MeasuredData,
    cfg: Config,
    max_effects: int = 6,
    progress: Callable[[str], None] | None = None,
    intersample: str | None = None,
) -> IdentifyReport:
    """Run the whole loop on one record (see the module docstring).

    ``intersample`` (``zoh``, ``foh``, ``bl``) says how the logged current behaved between
    samples; None takes the ``# intersample:`` header line, else estimates it. Raises
    :class:`~hil.identify.checks.RefusedData` for a record that cannot be identified.

    The linear algebra runs on one BLAS thread: its products are tall and thin, OpenBLAS's
    extra threads spin between them (half again the CPU time for no shorter wall time), and
    the simulations already take a thread per core (:func:`~hil.identify.model.map_threads`).
    glibc's malloc keeps freed memory from here on (:func:`~hil.identify.fit.keep_freed_memory`),
    and numpy no longer asks for huge pages (:func:`~hil.identify.fit.small_pages`).
    """
    keep_freed_memory()
    small_pages()
    with threadpool_limits(limits=1, user_api="blas"):
        return _identify(data, cfg, max_effects, progress, intersample)


def _identify(data: MeasuredData, cfg: Config, max_effects: int,
              progress: Callable[[str], None] | None, intersample: str | None
              ) -> IdentifyReport:
    t_start = time.perf_counter()
    loop = _Loop(data, cfg, progress or (lambda msg: None), intersample)
    loop.forward(max_effects)
    loop.drop_shrunk()
    loop.joint(max_effects)
    loop.restart_slow_first()
    loop.free_held_again()
    return loop.report(t_start)


def model_input(exp: Experiment, say: Callable[[str], None]) -> tuple[Experiment, InputNoise]:
    """The noise on the logged current and the experiment whose current every model of the run
    is simulated from: a sampled continuous current low-passed above its band (its noise
    there never reached the plant; :mod:`hil.identify.noise`), a held command as logged."""
    fs = exp.data.sample_rate_hz
    noise = estimate_input_noise(exp.iq, fs, quantum(exp.iq))
    if exp.intersample == "zoh":
        return exp, noise
    cut = current_cutoff(exp.iq, fs)
    if cut <= 0:
        return exp, noise
    noise.cutoff_hz = cut
    say(f"current low-passed at {cut:.0f} Hz (its band ends at {cut / CUTOFF_FACTOR:.0f} Hz; "
        f"above, {noise.rms_a:.3g} A rms of converter noise the plant never felt)")
    return experiment_with_current(exp, lowpass_current(exp.iq, fs, cut)), noise


class HeldFirst(NamedTuple):
    """A held-first refit of an effect (:meth:`_Loop.held_first`) and the refits it can
    stand aside for, each made only when called."""

    fit: FitResult
    held: dict[str, str]
    #: what it did, for the progress line
    what: str
    #: the polish without the baseline's holds freed (None: none were freed)
    without_base: Callable[[], HeldFirst] | None = None
    #: from the record's piston line: the polish from the search's end, as before
    as_before: Callable[[], HeldFirst] | None = None
    #: from the record's piston line: the polish with J_c held, then freed (it returns None
    #: where J_c was free already)
    jc_held: Callable[[], HeldFirst | None] | None = None


class _Loop:
    """The state of one identification run, step by step: the baseline fit
    (:meth:`__init__`), effects added one at a time (:meth:`forward`), effects dropped that
    shrank once others were in (:meth:`drop_shrunk`), effects that come only together
    (:meth:`joint`), held baseline parameters freed again (:meth:`free_held_again`), the
    report (:meth:`report`). ``current`` is the fit so far."""

    def __init__(self, data: MeasuredData, cfg: Config, say: Callable[[str], None],
                 intersample: str | None) -> None:
        self.data = data
        self.say = say
        check_record(data)
        if intersample is None:
            intersample = data.header.get("intersample")
        exp, theta_prov = choose_intersample(data, cfg, intersample, say)
        say(f"intersample {exp.intersample}: {exp.intersample_reason}")
        exp, noise = model_input(exp, say)
        self.exp = exp
        self.model = model = FastModel(exp)
        # the candidates' signatures are derivatives for a score test, not a fit: half the
        # sub-steps (100 us at 5 kHz) move them by far less than their standard errors, at
        # half the cost of the several dozen simulations each round takes
        self.test_model = FastModel(exp, n_sub=max(1, model.n_sub // 2))
        self.noise = noise
        #: the model's current was low-passed above its band (:func:`model_input`): the
        #: estimation cost is then free of the input noise's bias, and can choose between
        #: the minima two starts reach (:meth:`start_chosen`)
        self.unbiased = noise.cutoff_hz > 0
        self.noisy_model = (FastModel(noisy_experiment(exp, noise.rms_a, None, noise.cutoff_hz))
                            if noise.rms_a > 0 else None)
        self._held_noise: tuple[FastModel, list[FastModel]] | None = None

        self.est_mask = OutputErrorFit(model).fit_mask()
        say(f"baseline fit ({exp.load}, {exp.n} samples, channels {', '.join(exp.channels)})")
        self.base = base = fit_baseline(model, theta0=theta_prov, judge=self.agreement_of)
        check_fit(exp, base)
        self.skew_fitter = OutputErrorFit(model, NUISANCE_SCALES(exp.dt))
        if "skew_s" in base.free and self.skew_fitter.at_bound(base, "skew_s"):
            exp.skew_at_bound = base.value("skew_s") > 0
            exp.notes.append(f"the baseline's timing skew sits at its bound "
                             f"({base.value('skew_s') * 1e6:+.0f} us, half a sample): the "
                             "outputs and the logged input are further apart in time than a "
                             "sampling alignment")
        self.names = [n for n in BASELINE_LABELS if n in base.free or n in base.held]
        self.baseline_est = _estimates(base, self.names)
        self.analysis0 = self.analysis_of(base)
        self.sigma_ref = dict(base.sigma)
        self.current = base
        self.held = dict(base.held)
        self.defs_all = {d.label: d for d in library(exp)}
        self.added: list[EffectAdded] = []
        self.added_labels: set[str] = set()
        self.rejected: list[str] = []
        self.excluded: set[str] = set()
        self.rounds: list[list[CandidateTest]] = []
        self.joint_rows: list[dict] = []
        self.joint_why = ""
        self.restarts: list[dict] = []
        self.configured = model.start_vector()
        self.prefit: dict[str, tuple[FitResult, dict[str, str]]] = {}
        #: the fit :meth:`free_held_again` was last tried at
        self.freed_at: FitResult | None = None

    def noise_part(self, theta: np.ndarray) -> dict[str, np.ndarray] | None:
        if self.noisy_model is None:
            return None
        if theta[IDX["sf_coulomb_n"]] == 0.0:
            return predicted_residual(self.model.outputs(theta), self.noisy_model.outputs(theta))
        # a seal that can hold the piston makes the noise's path depend on where it starts:
        # the increment is taken from a cleaned current, as the rig felt it, and over several
        # draws of the noise, whose parts differ widely in power there (noise.py)
        if self._held_noise is None:
            self._held_noise = held_noise_draws(self.exp, self.noise)
        clean, noisy = self._held_noise
        return predicted_draws(clean.outputs(theta), [m.outputs(theta) for m in noisy])

    def refitter(self, model: FastModel | LowPassedPressures | None = None) -> OutputErrorFit:
        """A fitter of ``model`` (default the loop's) with the nuisance parameters' and every
        library effect's scales: the one the refits, the polish and the freeing use."""
        return OutputErrorFit(model or self.model, {**NUISANCE_SCALES(self.exp.dt),
                                                    **_all_scales(self.defs_all)})

    def robust_start(self, fit: FitResult) -> list[str]:
        """The parameters a refit with an effect in starts from their configured values: none
        where ``fit`` (the fit without it) is near the configuration; else those far from it
        (:func:`far_from_configuration`) and, with them, the other parameters that take an
        unmodelled dissipation or phase: the connecting rod's damper and the sensors' lags
        (:data:`ABSORBING`). The rule reads the fit's values against a factor of 1.5, once
        per refit: the start does not hang on which of two refits comes out a hair lower.
        Conrod, seal friction, rig seed 1: the baseline put the seal's dissipation into
        ``c_rod`` (49x), ``d_c`` (2.7x) and the strain lag (at its 1 ms bound); the refit
        from there, or from ``d_c`` alone put back, ends in a minimum with the pressure
        differences 62 % predictable, from all of them put back in the rig's basin.

        Where the model's current carries the input noise (not :attr:`unbiased`), the far
        parameters alone: the estimation cost there prefers damped minima (the
        errors-in-variables bias), and the wider start led the free piston's pump and seal
        friction under ``slide`` (16 s, rig seed 3) to an ``unexplained`` end, 41 s of CPU
        for 24."""
        far = far_from_configuration(fit, self.exp)
        if not far or not self.unbiased:
            return far
        return far + [p for p in ABSORBING if p in fit.free
                      and fit.theta[IDX[p]] != self.configured[IDX[p]]]

    def refit_with(self, d: EffectDef | list[EffectDef], start: dict[str, float],
                   robust: bool = False, nfev: int | None = None, judged_alone: bool = False,
                   model: FastModel | None = None, run_on: bool = False
                   ) -> tuple[FitResult, dict[str, str]]:
        """``current`` refitted with the effect ``d`` (or several at once) in, their
        parameters from ``start``. ``robust``: from the robust start (:meth:`robust_start`)
        where the fit without them is far from the configured values (the effects may have
        been what moved it there). ``nfev``: the Jacobians a pass, in place of the
        default (:data:`ROBUST_NFEV` from a robust start that moved something, else
        :data:`PLAIN_NFEV`). ``judged_alone``: the refit is judged by :meth:`verdict_on`
        alone (no cost of it compared), which refuses it once a parameter of the effects is
        held: the guard stops at that hold (:func:`~hil.identify.fit.guarded_fit`'s
        ``refuse``; free piston, both frictions under ``slide``: the seal's static level
        held at 0, then two more holds and refits, 1.2 s of CPU, for a refused refit).
        ``model``: the model the refit simulates, in place of the loop's (a search whose end
        is refitted on the loop's model, :meth:`others_held_chosen`). ``run_on``: the guard's
        refit after a hold in a fit stopped at its budget has that budget
        (:func:`~hil.identify.fit.guarded_fit`)."""
        exp, current, configured = self.exp, self.current, self.configured
        ds_ = d if isinstance(d, list) else [d]
        theta0 = current.theta.copy()
        put_back = self.robust_start(current) if robust else []
        for p in put_back:
            theta0[IDX[p]] = configured[IDX[p]]
        credible = theta0.copy()
        new_free = list(current.free)
        for e in ds_:
            for p in e.params:
                if p in start:
                    theta0[IDX[p]] += start[p]
                    new_free.append(p)
            for p, begin in e.refit_extra:
                theta0[IDX[p]] = credible[IDX[p]] = begin(exp)
                new_free.append(p)
        for e in ds_:
            EFFECTS[e.name].prepare_refit(theta0, credible, new_free, exp, current.free,
                                          self.est_mask)
        scales = {p: nom for e in ds_ for p, nom in zip(e.params, e.nominal, strict=True)}
        refitter = OutputErrorFit(model or self.model, {**NUISANCE_SCALES(exp.dt),
                                                        **_all_scales(self.defs_all), **scales})
        moved = self.unbiased and bool(put_back)
        # from the robust start the absorbed parameters have the whole way back to walk: the
        # fit is given the Jacobians to arrive (conrod, seal friction, rig seed 1: stopped
        # after 16 with the pressure differences 1.3 % predictable, at 0.3 % one fit on)
        if nfev is None:
            nfev = ROBUST_NFEV if moved else PLAIN_NFEV
        own = frozenset(p for e in ds_ for p in e.params) if judged_alone else frozenset()
        new, held_now = guarded_fit(refitter, theta0, new_free, credible, sigma=current.sigma,
                                    configured=configured, max_nfev=nfev, refuse=own,
                                    run_on=run_on)
        if own.intersection(held_now):
            return new, held_now
        # a shape parameter that took the effect's law to a degenerate one: held at its
        # start (the guard's interval test cannot see it: no sample informs the
        # degenerate part, so its interval is as narrow as the arithmetic makes it)
        odd = {p: why for e in ds_ for p, why in EFFECTS[e.name].implausible(new, exp).items()}
        if odd:
            new, again = guarded_fit(refitter, theta0, [p for p in new_free if p not in odd],
                                     credible, sigma=current.sigma, configured=configured,
                                     max_nfev=nfev)
            held_now = {**again, **odd}
        return new, held_now

    def verdict_on(self, ds_: list[EffectDef], new: FitResult, held_now: dict[str, str]
                   ) -> str:
        """Why the refit ``new`` with the effects ``ds_`` in is not kept ("" if it is): a
        parameter of theirs held (not credible), a validation cost lowered by less than
        :data:`MIN_SHARE`, or one of them shrunk below :data:`MIN_MAGNITUDE` of a realistic
        size (a score test is local: the refit can shrink an effect to nothing while other
        terms take its place)."""
        own = [p for p in held_now if any(p in e.params for e in ds_)]
        if own:
            return f"not credible after the refit ({own[0]}: {held_now[own[0]]})"
        before = _val_cost(self.exp, self.current.outputs, self.sigma_ref)
        after = _val_cost(self.exp, new.outputs, self.sigma_ref)
        if not after < (1.0 - MIN_SHARE) * before:
            return (f"refit lowered the validation cost by less than {MIN_SHARE:.1%} "
                    f"({after:.6g} vs {before:.6g})")
        for e in _shrunk(ds_, new):
            sizes = _sizes(e, new)
            p = max(sizes, key=sizes.get)
            return (f"the refit shrank {e.label} to {new.value(p):.4g} "
                    f"({sizes[p]:.1%} of a realistic size)")
        return ""

    def weighted_ss(self, out: dict[str, np.ndarray], mask: np.ndarray) -> float:
        w = self.current.weights
        return sum(float(np.nansum(((self.exp.measured[c] - out[c])[mask] / w[c]) ** 2))
                   for c in self.exp.channels)

    def judge_at_fit(self, d: EffectDef) -> FitJudgement:
        """A candidate that takes over a nuisance pinned at its bound, judged at its own fit
        (the refit it would get if selected, kept for that)."""
        self.say(f"fitting {d.label} to judge it (the fit's skew sits at its bound)")
        # judged by its own parameters' credibility first: the guard stops at their hold
        new, held_now = self.prefit[d.label] = self.refit_with(d, {p: 0.0 for p in d.params},
                                                               judged_alone=True)
        own = [p for p in held_now if p in d.params]
        if own:
            return FitJudgement(refused=f"not credible at its own fit ({own[0]}: "
                                        f"{held_now[own[0]]})")
        # the restricted model reaches a delay of the skew's bound (half a sample)
        reach = {"delay_s": self.skew_fitter.skew_limit * self.exp.dt}
        beta = {p: new.value(p) for p in d.params}
        shares = []
        for mask in (self.est_mask, self.exp.val):
            before = self.weighted_ss(self.current.outputs, mask)
            shares.append(1.0 - self.weighted_ss(new.outputs, mask) / before if before > 0
                          else 0.0)
        return FitJudgement(beta=beta, excess={p: v - reach.get(p, 0.0) for p, v in beta.items()},
                            se={p: new.se.get(p, float("nan")) for p in d.params},
                            share_est=shares[0], share_val=shares[1])

    def forward(self, max_effects: int) -> None:
        """Rounds of score tests, each adding the best candidate that its refit confirms."""
        exp, defs_all, say, held = self.exp, self.defs_all, self.say, self.held
        tested_at: FitResult | None = None
        for rnd in range(max_effects + 1):
            defs = [d for lbl, d in defs_all.items()
                    if lbl not in self.added_labels and lbl not in self.excluded]
            residual = {c: exp.measured[c] - self.current.outputs[c] for c in exp.channels}
            say(f"round {rnd}: testing {len(defs)} candidates")
            self.prefit.clear()
            if self.rounds and tested_at is self.current:
                # the last round's refit was refused: the same fit, the same signatures
                tests = retested(self.rounds[-1], defs)
            else:
                tests = test_candidates(defs, self.test_model.outputs, self.current.theta, IDX,
                                        exp, self.current.weights, residual, self.est_mask,
                                        exp.val, self.current.free,
                                        states=self.test_model.states)
            tested_at = self.current
            self.rounds.append(tests)
            ranked = rank(tests)
            if not ranked and len(self.added) < max_effects and judge_deferred(
                    tests, defs, self.judge_at_fit):
                ranked = rank(tests)
            if not ranked or len(self.added) >= max_effects:
                break
            best = ranked[0]
            d = defs_all[best.label]
            far = self.robust_start(self.current)
            if best.label in self.prefit:
                say(f"round {rnd}: adding {best.label} (its fit from the test)")
                new, held_now = self.prefit[best.label]
                other: tuple[FitResult, dict[str, str]] | None = None
            else:
                say(f"round {rnd}: adding {best.label}; refit")
                new, held_now, other = self.refit_added(d, best.beta, far, rnd)
            why = self.verdict_on([d], new, held_now)
            if why and far:
                # forward from a robust baseline: the fit without the effect may have
                # absorbed it into parameters far from their configured values (two
                # frictions on a free piston: J_c 40x, d_c 4.5x), a start the refit does not
                # come back from; or the robust start was the one refused
                say(f"round {rnd}: {best.label} {why}; the refit from the other start")
                new2, held2 = other or self.refit_with(d, best.beta, robust=True,
                                                       judged_alone=True)
                why2 = self.verdict_on([d], new2, held2)
                if not why2:
                    new, held_now, why = new2, held2, ""
                else:
                    why += f"; from the other start too ({why2})"
            if why:
                self.excluded.add(best.label)
                self.rejected.append(f"{best.label}: {why}")
                continue
            for p, _ in d.refit_extra:
                if p in held_now:  # a shape the data cannot pin: the preset's, and say so
                    held[p] = f"after adding {best.label}: {held_now.pop(p)}"
            for p, why in held_now.items():
                held[p] = f"after adding {best.label}: {why}"
            for p in [p for p in held if p in new.free]:
                del held[p]  # freed again in the refit kept (others_held_chosen)
            self.current = new
            self.skew_again()
            best.selected = True
            self.added_labels.add(best.label)
            self.added.append(EffectAdded(best.name, best.label, {}, rnd, best.p_holm,
                                          best.share_val))

    def refit_added(self, d: EffectDef, beta: dict[str, float], far: list[str], rnd: int
                    ) -> tuple[FitResult, dict[str, str], tuple[FitResult, dict[str, str]] | None]:
        """The refit of the round's best candidate ``d`` from its test's sizes ``beta``;
        ``far``: the robust start (:meth:`robust_start`) of the fit without it. Returns the
        refit, its held parameters and the refit from the robust start where one was made
        in full (:meth:`start_chosen`; None otherwise).

        With no effect in yet and the fit far, the plain and the robust start are compared
        (:meth:`start_chosen`). With effects in and the fit far, the plain refit, and where
        it leaves material structure the held-first one beside it
        (:meth:`others_held_chosen`). A friction that can hold the piston
        (:data:`STICK_SLIP`) takes the held-first refit first: where that leaves the
        residual white and passes :meth:`verdict_on` it is kept and no plain refit is made
        (conrod, pump and seal friction, the 16 s bench record: the plain refit, 4.2 s of
        CPU, and its residual analysis, 1.4 s, were made only to be compared with the
        held-first one, which explains the record); elsewhere the rule is as before, the
        held-first refit made once."""
        # the two starts compared for the seal alone: its far minimum is the one they tell
        # apart (conrod, seal friction, rig seeds 1 and 2); the first effect of any other kind
        # ended in the plain refit's minimum from both (the conrod's pulsation 1e-4 apart,
        # the pump friction 1e-5), the robust trial made for nothing (1.4 s of the conrod
        # triple's 16 s record)
        chosen = bool(far and not self.added and self.unbiased
                      and STICK_SLIP.intersection(d.params))
        other = None
        # a friction that can hold the piston, after other effects: the held-first
        # refit first, and none plain where it leaves the residual white
        made = (self.held_first(d, beta, base_too=True) if far and self.unbiased
                and not chosen and STICK_SLIP.intersection(d.params) else None)
        if made is not None and made.as_before is not None and not self.white_and_passes(d, made):
            # the polish from the record's piston line left structure: the same polish
            # with J_c held first, kept only where white and passing; else the polish from
            # the search's end, as before, and the rule goes on with it (compared as itself
            # with the plain refit, the line's polish turned the conrod triple's 6 s row at
            # rig seed 2 unexplained)
            alt = made.jc_held() if made.jc_held is not None else None
            made = alt if alt is not None and self.white_and_passes(d, alt) else made.as_before()
        if made is not None and self.white_and_passes(d, made):
            self.say(f"round {rnd}: {made.what} leaves the residual white (no plain refit)")
            return made.fit, made.held, other
        if made is not None and made.without_base is not None:
            # not kept at once: the held-first refit the plain one is compared with is the
            # one without the baseline's holds freed (freed, it can come out a hair lower
            # and be kept where the old rule's was not: conrod triple, rig seed 2)
            made = made.without_base()
            if self.white_and_passes(d, made):
                # white itself: kept as the first polish would have been, no plain refit
                # (conrod, pump and seal friction, 16 s, rig seed 1: J_c freed took the
                # polish to the far basin, the polish without it explains the record, and
                # the plain refit, 3.5 s and its analysis, was made only to lose to it)
                self.say(f"round {rnd}: {made.what} leaves the residual white (no plain refit)")
                return made.fit, made.held, other
        if chosen:
            # from the baseline only, and only where the estimation cost is free of
            # the input noise's bias (it ranks the two minima; without the low-pass
            # it ranked them wrong: docs/identify.md): its far parameters took what
            # the model lacks, all of it. Once an effect is in they were refitted
            # with it, and the
            # second start found no other basin (conrod, pump and seal friction, the
            # seal's refit in round 1: from the robust start at an estimation cost
            # 8-41 % above the plain one's, both seeds) for 8-17 s of CPU a record
            new, held_now, other = self.start_chosen(
                d, beta, self.refit_with(d, beta), rnd)
        else:
            new, held_now = self.refit_with(d, beta, judged_alone=True)
            if (far and self.unbiased and STICK_SLIP.intersection(d.params)
                    and structure_excess(self.analysis_of(new)) > 0.0):
                # effects in already, the fit still far, and its residual still holds
                # material structure: what it absorbed may be shared out between the
                # new effect and those in (others_held_chosen). A refit that leaves
                # the residual white needs no other start (conrod, pump friction
                # after the pulsation: the second refit was never kept, +2-3 s a
                # record). The residual alone decides: the parameters' consistency
                # across parts of the record (0.4 s on a 16 s record) is judged of
                # the refit kept
                new, held_now = self.others_held_chosen(d, beta, (new, held_now),
                                                        rnd, made)
        return new, held_now, other

    def start_chosen(self, d: EffectDef, beta: dict[str, float],
                     plain: tuple[FitResult, dict[str, str]], rnd: int
                     ) -> tuple[FitResult, dict[str, str],
                                tuple[FitResult, dict[str, str]] | None]:
        """The refit of ``d`` where the fit without it is the baseline (no effect in yet)
        and far from the configuration (:meth:`forward`): from the fit as it stands
        (``plain``, made) and from the robust start (:meth:`robust_start`); the robust one is
        kept where its estimation cost is lower by more than :data:`START_MARGIN`, else the
        plain one. The two end in different minima tens of per cent apart (conrod, seal
        friction: rig seed 1 from the fit as it stands in one with the pressure differences
        62 % predictable, from the robust start in the rig's, 0.3 %; seed 2 the other way
        round, 68 % and 0.1 %), or in the same one a few ulps apart: the margin keeps the
        last bits of the arithmetic from choosing.

        The robust refit is first run with the plain one's budget (:data:`PLAIN_NFEV`): a
        least-squares descent only lowers its cost, so one that is not lower by the margin
        there rarely is after :data:`ROBUST_NFEV`, and the long run is made only for a start
        that already leads (conrod, pump and seal friction, the pump friction's refit from
        the baseline: both starts end in the same minimum, 1e-5 apart), or that is still
        descending at the budget's end above the plain one by more than the margin and
        less than :data:`RUN_ON_BAND` (two costs at unequal progress decide nothing; within
        the margin the two are one minimum, the conrod's pulsation 1e-4 apart). Returns the kept
        refit and the other where it was run in full (None: :meth:`forward` refits from the
        robust start if the plain one is refused)."""
        mask = self.est_mask
        plain_cost = self.weighted_ss(plain[0].outputs, mask)
        lead = (1.0 - START_MARGIN) * plain_cost
        trial = self.refit_with(d, beta, robust=True, nfev=PLAIN_NFEV)
        trial_cost = self.weighted_ss(trial[0].outputs, mask)
        # a trial still descending at its budget's end above the plain refit's minimum (by
        # more than the margin: within it, the same minimum) and not far above it says
        # nothing yet: where its budget ran out decided (conrod, seal friction, rig seed 1:
        # 4 % above the plain refit with the fits stopped at 50 variances, 37 % below at 1,
        # the same basin at the end of both): it is run on, the full refit
        behind = (1.0 + START_MARGIN) * plain_cost <= trial_cost < (1.0 + RUN_ON_BAND) * plain_cost
        if not trial_cost < lead and (trial[0].converged or not behind):
            return *plain, None
        robust = self.refit_with(d, beta, robust=True)
        if self.weighted_ss(robust[0].outputs, mask) < lead:
            self.say(f"round {rnd}: the refit from the configured values of "
                     f"{', '.join(self.robust_start(self.current))} ends lower")
            return *robust, plain
        return *plain, robust

    def others_held_chosen(self, d: EffectDef, beta: dict[str, float],
                           plain: tuple[FitResult, dict[str, str]], rnd: int,
                           made: HeldFirst | None = None
                           ) -> tuple[FitResult, dict[str, str]]:
        """The refit of ``d`` where effects are in already and the fit without ``d`` is
        still far from the configuration (:meth:`forward`): besides the plain refit (made),
        one from the robust start with the effects already in held at their values, then
        everything freed for a polish of :data:`PLAIN_NFEV` Jacobians; kept where its
        estimation cost is lower than the plain one's by :data:`START_MARGIN`. With those
        effects free from the start, the new one's refit shares what the far parameters
        took out between them, and lands in a minimum behind a ridge from the rig's
        (conrod, pump and seal friction, rig seed 1: the seal's refit after the pump
        friction, from every start with the pump friction free, ends with the pressure
        differences 63 % predictable; with it held, then freed, at 1.5 %, an estimation cost
        1.6x lower; docs/identify.md, "The conrod's two frictions").

        The held-first refit also frees the baseline parameters the guard held in an earlier
        effect's refit (:meth:`held_since_baseline`), from their held values: held while
        the effects now in were still missing, they may be pinned now, and held they keep
        the rig's basin out of reach (conrod, pump friction, seal friction and pulsation,
        rig seed 1: ``k_s`` held at the preset, 1.08x the rig's, in the pulsation's round;
        the seal's refit, held-first or not, then ends with the pressure differences 68 %
        predictable; with ``k_s`` free in it, explained). The guard holds them again where
        they are still not credible."""
        alt = made or self.held_first(d, beta)
        if alt is None:
            return plain
        mask = self.est_mask
        if (self.weighted_ss(alt.fit.outputs, mask)
                < (1.0 - START_MARGIN) * self.weighted_ss(plain[0].outputs, mask)):
            self.say(f"round {rnd}: {alt.what} ends lower")
            return alt.fit, alt.held
        return plain

    def white_and_passes(self, d: EffectDef, made: HeldFirst) -> bool:
        """The held-first refit of ``d`` (:meth:`held_first`) leaves the residual white
        (:func:`structure_excess` 0) and passes :meth:`verdict_on`: it is kept without the
        plain refit (:meth:`forward`)."""
        return (not made.fit.left and structure_excess(self.analysis_of(made.fit)) == 0.0
                and not self.verdict_on([d], made.fit, made.held))

    def others_held(self) -> list[str]:
        """The free parameters of the effects in (:meth:`held_first` holds them first)."""
        return [p for e in self.added
                for p in (*self.defs_all[e.label].params,
                          *(q for q, _ in self.defs_all[e.label].refit_extra))
                if p in self.current.free]

    def held_first(self, d: EffectDef, beta: dict[str, float], base_too: bool = False
                   ) -> HeldFirst | None:
        """:meth:`others_held_chosen`'s refit of ``d`` with the effects in held first, then
        polished with everything free; None where no effect's parameter is free.

        ``base_too``: the polish also frees the parameters the baseline held whose interval
        at the search's end is narrower than their value (:meth:`baseline_pinned`);
        :attr:`HeldFirst.without_base` then makes the polish without them (the refit of
        ``base_too`` False, from the same search). Where the search's end rings off the
        record's piston line, the polish starts from the stiffness at that line, and
        :attr:`HeldFirst.as_before` and :attr:`HeldFirst.jc_held` make the others."""
        current = self.current
        others = self.others_held()
        if not others:
            return None
        again = self.held_since_baseline()
        self.current = dataclasses.replace(current, free=[p for p in current.free
                                                          if p not in others] + again)
        try:
            # the held refit is a search for the basin, and the polish below refits its end
            # on the loop's model: half the sub-steps (the score tests' model) find the same
            # basin at half the cost a simulation, and in fewer Jacobians (conrod, pump and
            # seal friction, 16 s, rig seed 3: 24 where 40 did not end the descent; the
            # polished fit's estimation cost 19155 against 19157, docs/identify.md)
            # where it stops at its budget and its guard then holds a parameter (conrod, pump
            # and seal friction, 16 s, rig seed 1: c_rod walked to its bound in the last 14 of
            # 40 Jacobians, held back at 50), the refit after the hold runs on with the
            # search's budget: three Jacobians left the end off the valley floor, and the
            # polish with J_c freed from there went to the far basin
            first, held_first = self.refit_with(d, beta, robust=True, model=self.test_model,
                                                run_on=True)
        finally:
            self.current = current
        refitter = self.refitter()
        free = list(first.free) + [p for p in others if p not in first.free]

        def polish(extra: list[str], at_line: float | None = None) -> HeldFirst:
            start, more, fitter = first.theta, [], refitter
            if at_line is not None:
                start = first.theta.copy()
                start[IDX["ks"]] = at_line
                more = [p for p in ("ks", "jc") if p not in free and p not in extra]
                # a descent from the line that leaves it is on its way to another basin
                # (J_c taking up the seal's friction): stopped there, not run to its end
                fitter = self.refitter()
                fitter.leave = line_left(self.exp, start)
            alt, held_alt = guarded_fit(fitter, start, free + extra + more, start,
                                        sigma=current.sigma, configured=self.configured,
                                        max_nfev=PLAIN_NFEV)
            freed = [p for p in again + extra + more if p in alt.free]
            what = (f"the refit with {', '.join(others)} held first"
                    + (f" and {', '.join(freed)} free again" if freed else "")
                    + (f", polished from k_s {at_line:.4g} N/m (the record's piston line)"
                       if at_line is not None else ""))
            return HeldFirst(alt, {**held_first, **held_alt}, what)

        # not where the search freed a later round's hold: the conrod triple's 16 s record
        # (k_s, held in the pulsation's round) freed J_c too in the polish, left structure
        # and cost a second polish, +4 s
        extra = self.baseline_pinned(refitter, first, free) if base_too and not again else []

        def as_before() -> HeldFirst:
            if not extra:
                return polish([])
            return polish(extra)._replace(without_base=lambda: polish([]))

        line = stiffness_at_line(self.exp, first.theta, first.outputs) if base_too else None
        if line is None:
            return as_before()

        def jc_held_first() -> HeldFirst | None:
            # the line's polish with J_c freed at once can carry it off to the far basin
            # (conrod triple, 16 s, rig seed 1: J_c 0.295 -> 0.625, the seal's shape 0.15,
            # static 25.7 N, the pressure differences 68 % predictable); from the line with
            # J_c held the polish walks into the rig's basin (shape 0.91, 40 Jacobians), and
            # freed from there J_c settles at the rig's (0.310, white): what the plain refit
            # and the resonance restart reached before, for 10 s more. The J_c-held polish
            # is a search for that basin, its end refitted with J_c freed: on the test
            # model, as the search (seed 1: converged in 3 + 7 Jacobians where the loop's
            # model stopped at its budget, 3 + 12; the freed polish ends at the same fit to
            # four digits, white)
            if "jc" in free or "jc" in extra:
                return None
            start = first.theta.copy()
            start[IDX["ks"]] = line[0]
            held_jc, held_a = guarded_fit(self.refitter(self.test_model), start,
                                          free + extra + ["ks"], start,
                                          sigma=current.sigma, configured=self.configured,
                                          max_nfev=PLAIN_NFEV)
            alt, held_alt = guarded_fit(refitter, held_jc.theta, free + extra + ["ks", "jc"],
                                        held_jc.theta, sigma=current.sigma,
                                        configured=self.configured, max_nfev=PLAIN_NFEV)
            return HeldFirst(
                alt, {**held_first, **held_a, **held_alt},
                f"the refit with {', '.join(others)} held first, polished from k_s "
                f"{line[0]:.4g} N/m (the record's piston line) with J_c held, then free")

        return polish(extra, line[0])._replace(as_before=as_before, jc_held=jc_held_first)

    def baseline_pinned(self, fitter: OutputErrorFit, fit: FitResult, free: list[str]
                        ) -> list[str]:
        """Parameters the baseline held (still held) whose interval at ``fit``, with them
        and ``free`` free, is narrower than their value: one Jacobian."""
        held = [p for p in self.base.held if p in BASELINE_LABELS and p in self.held
                and p not in free]
        if not held:
            return []
        return pinned(fitter, fit, free, held)

    def held_since_baseline(self) -> list[str]:
        """Baseline parameters held by the guard in an effect's refit (not by the baseline
        fit): held in a model that lacked the effects added after it."""
        return [p for p in self.held if p in BASELINE_LABELS and p not in self.base.held
                and p not in self.current.free]

    def skew_again(self) -> None:
        """The skew pinned at +T/2 may have been an effect's doing: once one is in, the delay
        is offered against the current fit's skew."""
        if "skew_s" in self.current.free:
            self.exp.skew_at_bound = (self.skew_fitter.at_bound(self.current, "skew_s")
                                      and self.current.value("skew_s") > 0)

    def drop_shrunk(self) -> None:
        """An effect added early, by a local test, may have shrunk to nothing once a later
        one was in (a pump friction standing in for a pulsation): drop it and refit without
        it."""
        held = self.held
        for e in list(self.added):
            d = self.defs_all[e.label]
            current = self.current
            sizes = {p: abs(current.value(p)) / abs(nom)
                     for p, nom in zip(d.params, d.nominal, strict=True) if nom}
            if len(self.added) < 2 or not sizes or max(sizes.values()) >= MIN_MAGNITUDE:
                continue
            p_max = max(sizes, key=sizes.get)
            shrunk = current.value(p_max)
            self.say(f"dropping {e.label}: shrank to {shrunk:.4g} once the others were in")
            theta = current.theta.copy()
            drop = list(d.params) + [p for p, _ in d.refit_extra]
            for p in drop:
                theta[IDX[p]] = 0.0
                held.pop(p, None)
            refitter = self.refitter()
            self.current, held_now = guarded_fit(
                refitter, theta, [p for p in current.free if p not in drop], theta,
                sigma=current.sigma, passes=1, max_nfev=9)
            for p, why in held_now.items():
                held[p] = f"after dropping {e.label}: {why}"
            self.added.remove(e)
            self.added_labels.discard(e.label)
            self.rejected.append(f"{e.label}: shrank to {shrunk:.4g} "
                                 f"({sizes[p_max]:.1%} of a realistic size) once the others "
                                 "were in; dropped")

    #: the last few fits' residual analyses and consistencies, each latest last
    _analyses: tuple[tuple[FitResult, ResidualAnalysis], ...] = ()
    _agreements: tuple[tuple[FitResult, Consistency], ...] = ()
    JUDGED_KEPT = 3

    def judged(self, fit: FitResult) -> tuple[ResidualAnalysis, Consistency]:
        """The residual analysis (validation part) of ``fit`` and its parameters'
        consistency across parts of the record. Kept for the last few fits judged: the same
        fit is judged by several steps (the joint step's gate, the freed refit's run-on and
        its keeping, the report, which judges the fit before the freeing again where that
        was not kept), each a few simulations and spectra for the same answer."""
        return self.analysis_of(fit), self.agreement_of(fit)

    def analysis_of(self, fit: FitResult) -> ResidualAnalysis:
        """:meth:`judged`'s residual analysis, kept (the baseline's is the report's first
        one, and judged again while the baseline is the loop's fit)."""
        for f, analysis in self._analyses:
            if f is fit:
                return analysis
        exp = self.exp
        residual = {c: exp.measured[c] - fit.outputs[c] for c in exp.channels}
        analysis = analyse(exp, residual, exp.val, self.noise_part(fit.theta))
        self._analyses = (*self._analyses, (fit, analysis))[-self.JUDGED_KEPT:]
        return analysis

    def agreement_of(self, fit: FitResult, exp: Experiment | None = None,
                     mask: np.ndarray | None = None) -> Consistency:
        """:meth:`judged`'s consistency, kept; with ``exp`` and ``mask`` as
        :func:`~hil.identify.consistency.consistency` takes them (the baseline's holds
        judge the fit they end in, which the loop judges again: free piston, both
        frictions, 0.4 s a record), kept only for the loop's record and estimation
        samples."""
        ours = ((exp is None or exp is self.exp)
                and (mask is None or np.array_equal(mask, self.est_mask)))
        if ours:
            for f, agree in self._agreements:
                if f is fit:
                    return agree
        agree = consistency(fit, self.exp if exp is None else exp,
                            self.est_mask if mask is None else mask)
        if ours:
            self._agreements = (*self._agreements, (fit, agree))[-self.JUDGED_KEPT:]
        return agree

    def structure(self) -> tuple[str, str]:
        """What the current fit leaves unexplained, by the judge of the report's verdict, in
        its two kinds: material residual structure (:func:`_verdict`'s detail) and the
        parameters that disagree between parts of the record ("" each where there is
        none)."""
        analysis, agree = self.judged(self.current)
        left, detail = _verdict(analysis)
        bad = agree.inconsistent
        disagree = ("parameters disagree between parts of the record: " + "; ".join(
            s.describe(BASELINE_LABELS[s.name][0]) for s in bad)) if bad else ""
        return (detail if left else ""), disagree

    def structure_left(self) -> str:
        """:meth:`structure` in one line; "" when the fit explains the record. The steps
        that search further (the joint sets, the freed refit run on) run only where this is
        not empty."""
        return "; ".join(filter(None, self.structure()))

    def restart_far(self) -> bool:
        """The effects found, added one at a time, each refitted from where the fit before
        it stood: with several in, that path can end in a local minimum whose linear
        parameters sit far from their configured values (free piston, pump friction,
        pulsation and viscosity: ``k_s`` 0.64x, ``d_s`` 1.9x, the strain lag at its bound,
        the pump friction 11 % low). With structure left, refit the same model once from
        the configured values of those parameters; keep it when its validation cost is
        lower and it holds none of the effects' parameters. True when kept.

        So are the parameters whose configured value, the rest of the fit as it stands,
        fits the estimation part better than the fit's own value (:meth:`better_configured`):
        the fit sits in a local minimum along that parameter, behind a hump the optimiser
        does not cross."""
        if not self.added:
            return False
        far = far_from_configuration(self.current, self.exp)
        far += [p for p in self.better_configured() if p not in far]
        if not far:
            return False
        ds_ = [self.defs_all[e.label] for e in self.added]
        self.say("refit of the effects found from the configured values of "
                 + ", ".join(far))
        theta0 = self.current.theta.copy()
        for p in far:
            theta0[IDX[p]] = self.configured[IDX[p]]
        refitter = self.refitter()
        new, held_now = guarded_fit(refitter, theta0, list(self.current.free), theta0,
                                    sigma=self.current.sigma, configured=self.configured)
        own = [p for p in held_now if any(p in e.params for e in ds_)]
        before = _val_cost(self.exp, self.current.outputs, self.sigma_ref)
        after = _val_cost(self.exp, new.outputs, self.sigma_ref)
        kept = not own and after < before
        self.restarts.append({"from_configured": far, "validation_cost_change":
                              after / before - 1.0 if before > 0 else float("nan"),
                              "outcome": "kept" if kept else (
                                  f"not kept ({own[0]} held)" if own else
                                  "not kept (no lower validation cost)")})
        if not kept:
            return False
        for p, why in held_now.items():
            self.held[p] = f"after the refit from the configured values: {why}"
        self.current = new
        return True

    def restart_resonance(self) -> bool:
        """The effects found may have settled where the model's piston rings at another
        frequency than the record's, the friction laws and the pressure lag taking up the
        difference (conrod, both frictions and the pulsation, rig seed 2: ``k_s`` held at the
        preset, 1.16x the rig's, the pressure differences 59 % predictable). Where the
        record shows the piston's line and the model's is off it
        (:func:`~hil.identify.resonance.stiffness_at_line`), refit the same model from the
        ``k_s`` that moves the line there, ``k_s`` and ``J_c`` free, and run the refit on
        once more where it does not explain the record yet (the seed-2 record: ``k_s``
        0.986x the rig's after the first, 0.997x and explained after the second, 25 s of
        CPU), and again (up to :data:`RESONANCE_REFITS` in all) while the last refit took
        :data:`RUN_ON_PROGRESS` of the residual structure (:func:`structure_excess`) off.
        Kept only where it explains the record, holds none of the effects' parameters and
        lowers the validation cost: a restart that leaves structure has not found what
        the fit lacks. True when kept."""
        current = self.current
        if not self.added:
            return False
        line = stiffness_at_line(self.exp, current.theta, current.outputs)
        if line is None:
            return False
        ks, f_rec, f_mod = line
        self.say(f"refit of the effects found from k_s {ks:.4g} N/m, where the model's piston "
                 f"rings at the record's {f_rec:.0f} Hz (it rang at {f_mod:.0f} Hz)")
        theta0 = current.theta.copy()
        theta0[IDX["ks"]] = ks
        free = list(current.free) + [p for p in ("ks", "jc") if p not in current.free]
        refitter = self.refitter()
        # its end is read by the verdict as it stands (explained or not): stopped short, a
        # fit on its way leaves structure the full descent takes off
        refitter.converged_gain = JUDGED_GAIN
        own = {p for e in self.added for p in self.defs_all[e.label].params}
        new = current
        held_now: dict[str, str] = {}
        was = np.inf
        for k in range(RESONANCE_REFITS):
            new, held_pass = guarded_fit(refitter, theta0, free, theta0, sigma=current.sigma,
                                         configured=self.configured)
            held_now.update(held_pass)  # the run-on starts with the first pass's holds
            if own.intersection(held_now):
                break
            self.current = new
            if not self.structure_left():
                break
            # beyond the second, run on while the last refit took a share of the structure
            # off: a fixed count of them made the verdict hang on where each one's stop fell
            # (the seed-2 record: with the fits stopped at 50 residual variances, 1.1 % of
            # the pressures predictable after the second refit, against 1 % allowed)
            now = structure_excess(self.judged(new)[0])
            if k >= 1 and not now <= (1.0 - RUN_ON_PROGRESS) * was:
                break
            was = now
            theta0 = new.theta.copy()
            free = list(new.free)
        return self.restart_kept(current, new, held_now, ["ks", "jc"],
                                 f"k_s at the record's piston resonance ({f_rec:.0f} Hz)",
                                 "after the refit from the piston resonance")

    def restart_kept(self, current: FitResult, new: FitResult, held_now: dict[str, str],
                     freed: list[str], origin: str, why: str) -> bool:
        """A restart's refit ``new`` of ``current`` (the fit so far) judged: kept where it
        holds none of the effects' parameters, leaves no structure and lowers the
        validation cost; its outcome recorded in :attr:`restarts` (``origin``: where it
        started from), the parameters ``freed`` no longer held where ``new`` has them free,
        ``new``'s own holds recorded with ``why``. True when kept (``current`` is then
        ``new``)."""
        own = {p for e in self.added for p in self.defs_all[e.label].params}
        held_own = sorted(own.intersection(held_now))
        before = _val_cost(self.exp, current.outputs, self.sigma_ref)
        after = _val_cost(self.exp, new.outputs, self.sigma_ref)
        self.current = new
        left = self.structure_left()
        kept = not held_own and not left and after < before
        self.restarts.append({
            "from_configured": ["ks"],
            "from": origin,
            "validation_cost_change": after / before - 1.0 if before > 0 else float("nan"),
            "outcome": "kept" if kept else (
                f"not kept ({held_own[0]} held)" if held_own else
                "not kept (structure left)" if left else "not kept (no lower validation cost)")})
        if not kept:
            self.current = current
            return False
        for p in freed:
            if p in new.free:
                self.held.pop(p, None)
        for p, held_why in held_now.items():
            self.held[p] = f"{why}: {held_why}"
        return True

    def restart_slow_first(self) -> bool:
        """The effects found may have settled where the model's piston line is off the
        record's and the sensors' lag filters the model's ring away, the slow parameters
        taking up the rest: a refit from the line alone (:meth:`restart_resonance`) keeps
        them there (free piston, pump and seal friction, the bench's 16 s multisine at rig
        seed 3: both frictions in only as the joint search's pair, `K` held at the preset
        since the baseline, 1.17x the rig's, the seal's `eps` at the preset, `k_s` and
        `J_c` at the preset, the pressures' residual 76 % predictable, three quarters of
        it at the line). Where the record shows the line and the model's is off it (or
        rings above the record's band: the line is then looked for around the configured
        resonance, :func:`~hil.identify.resonance.stiffness_at_line`), put the line there
        with `J_c` at its configured value and refit in two stages: the pressures
        low-passed below the line (:class:`~hil.identify.slowfirst.LowPassedPressures`,
        :data:`SLOW_CUTOFF` of the record's line), `k_s` and `J_c` held, the loop's other
        holds (the baseline's, the effects' law parameters held when they came in) freed
        but a baseline's hold for absorbed structure (:data:`~hil.identify.fit.ABSORBED`)
        and, with the seal in, its regularisation velocity; then the full band from there
        with `k_s`, `J_c` free (a freed hold that then disagrees between parts of the record,
        where nothing else is left, held again: :meth:`freed_disagreeing`). Kept only where
        it explains the record, holds none of the effects' parameters and lowers the
        validation cost. True when kept (docs/identify.md, "The free piston's two frictions
        under the multisine at rig seeds 1 and 2")."""
        current, exp = self.current, self.exp
        if not self.added or not self.structure_left() or not pressures_finite(exp):
            return False
        line = stiffness_at_line(exp, current.theta, current.outputs, self.configured)
        if line is None:
            return False
        ks, f_rec, f_mod = line
        theta0 = current.theta.copy()
        # the line gives (k_s + k_rod) / J_c, not J_c: J_c from its configured value, k_s
        # where the line stays (a fit that ran J_c away with the line's ratio kept, the
        # free piston's pair at rig seed 1, J_c 1.8x, would start the slow part from there)
        k_rod = theta0[IDX["k_rod"]] if exp.load == "conrod" else 0.0
        jc = self.configured[IDX["jc"]]
        ks = (ks + k_rod) * jc / theta0[IDX["jc"]] - k_rod
        theta0[IDX["ks"]], theta0[IDX["jc"]] = ks, jc
        # the loop's holds but the line's two: the baseline's, and the effects' law
        # parameters held at their start when they came in (the seal's Stribeck velocity at
        # rig seed 1: held at the preset's 5 mm/s by the pair's refit, the rig's 4)
        shapes = {p for e in self.added for p, _ in self.defs_all[e.label].refit_extra}
        # but not a baseline's hold for structure it had absorbed (far from its configured
        # value, it disagreed between parts of the record): freed here, it disagrees again
        # once the line is back (d_s at rig seed 1, held again after the full band's refit,
        # a second refit and its judgement, 2 s of the record's CPU), so it stays held
        extra = [p for p in self.held if (p in BASELINE_LABELS or p in shapes)
                 and p not in ("ks", "jc") and p not in current.free
                 and ABSORBED not in self.held[p]]
        if (any(e.name == "seal_friction" for e in self.added)
                and "sf_eps_m_per_s" not in current.free):
            extra.append("sf_eps_m_per_s")
            theta0[IDX["sf_eps_m_per_s"]] = exp.const.eps_seal
        self.say(f"refit of the effects found below the piston's line ({f_rec:.0f} Hz in the "
                 f"record, {f_mod:.0f} Hz in the model) first, k_s {ks:.4g} N/m and J_c "
                 f"{jc:.4g} kg put on it")
        # the line's skirt reaches below the cut-off (at 0.4 of the line, the response 1.2x
        # the static one): the slow part is fitted with the line where the record has it.
        # A search, whose end the full band refits on the loop's model: half the sub-steps
        # (the score tests' model) are as good below the line, at half the cost, and it is
        # given the Jacobians to arrive (stopped at 40 on the bench's record, K 0.89x the
        # rig's, the full band's refit from there left structure)
        slow = self.refitter(LowPassedPressures(self.test_model, SLOW_CUTOFF * f_rec))
        # below the line the pressures say nothing about k_s or J_c: held there
        free = [p for p in current.free if p not in ("ks", "jc")] + extra
        first = slow.fit(theta0, free, sigma=current.sigma, passes=2, max_nfev=ROBUST_NFEV)
        theta1 = first.theta.copy()
        free += ["ks", "jc"]
        refitter = self.refitter()
        refitter.converged_gain = JUDGED_GAIN
        new, held_now = guarded_fit(refitter, theta1, free, theta1, sigma=current.sigma,
                                    configured=self.configured)
        back = self.freed_disagreeing(new, extra)
        if back:
            # a hold freed here that the record then says moves between its parts (as d_s
            # at rig seed 1 did when its hold for absorbed structure was freed: 1.07x over
            # the record at p = 7e-6, the residual white, the rig's basin; at its hold,
            # explained): held again
            self.say(f"{', '.join(back)} held again: freed, it disagrees between parts of "
                     "the record")
            theta2 = new.theta.copy()
            for p in back:
                theta2[IDX[p]] = current.theta[IDX[p]]
            free = [p for p in free if p not in back]
            # one pass: it starts at the end of the one before, a per cent away
            new, held_again = guarded_fit(refitter, theta2, free, theta2, sigma=current.sigma,
                                          passes=1, configured=self.configured)
            held_now = {**held_now, **{p: "disagrees between parts of the record once freed; "
                                          f"held at {current.theta[IDX[p]]:.4g}" for p in back},
                        **held_again}
            extra = [p for p in extra if p not in back]
        kept = self.restart_kept(
            current, new, held_now, extra + ["ks", "jc"],
            f"the pressures below the piston's line, then k_s at it ({f_rec:.0f} Hz)",
            "after the refit below the piston's line")
        if kept:
            # every hold was freed here, and those held again judged at this fit: the
            # freeing at the end would ask the same question of the same fit (a hold for
            # absorbed structure, not freed here, is not asked there either: the record's
            # parts disagreeing is what held it, and its interval is not that question)
            self.freed_at = self.current
        return kept

    def freed_disagreeing(self, fit: FitResult, freed: list[str]) -> list[str]:
        """Of the ``freed`` parameters, those that disagree between parts of the record at
        ``fit`` where that is all ``fit`` leaves (the residual without material structure,
        no other parameter disagreeing); [] otherwise."""
        analysis, agree = self.judged(fit)
        if _verdict(analysis)[0]:
            return []
        bad = [s.name for s in agree.inconsistent]
        if not bad or any(p not in freed for p in bad):
            return []
        return list(dict.fromkeys(bad))

    def better_configured(self) -> list[str]:
        """Free linear-model parameters (:data:`CONSISTENCY_JUDGED`) at whose configured
        value, every other parameter as the current fit has it, the estimation cost is lower
        than at the fit's value by more than the likelihood-ratio threshold of one parameter
        (:func:`~hil.identify.fit.lr_threshold`, the one that decides whether the data ask
        for a value far from the configuration): one simulation each. Free piston, pump and
        seal friction under ``slide``, rig seed 1: the pump friction's refit from its law's
        middle shape either took the ``atan`` law near the rig's 0.47 mm/s, or (4 ulps of
        the data apart) the ``tanh`` law with ``eps`` 3.9 mm/s and ``k_s`` 1.5x the truth,
        1.4x the configured value, the pressures' residual 2 % predictable; there ``k_s`` at
        its configured value alone lowers the cost by 3 %, and the fit from there is
        explained."""
        fitter = OutputErrorFit(self.model)
        current = self.current
        cost = fitter.cost(current.theta, current.sigma)
        out = []
        for name in CONSISTENCY_JUDGED:
            if name not in current.free or not self.exp.start.get(name):
                continue
            theta = current.theta.copy()
            theta[IDX[name]] = self.configured[IDX[name]]
            if theta[IDX[name]] != current.theta[IDX[name]] and (
                    fitter.cost(theta, current.sigma) < cost - lr_threshold(current, name)):
                out.append(name)
        return out

    def joint(self, max_effects: int) -> None:
        """Effects that come together: a residual with structure left and no candidate that
        passes alone, so the library's candidates are refitted in pairs (then as one
        triple), from the robust start, each judged on the validation part as a single one
        is. Before the sets: the refit from the configured values (:meth:`restart_far`), then
        the held parameters freed (:meth:`free_held_again`); where either explains the
        record, no set is tried."""
        exp, defs_all = self.exp, self.defs_all
        if not (len(self.added) + 2 <= max_effects and self.rounds):
            return
        residual, disagree = self.structure()
        if not (residual or disagree):
            self.joint_why = ("not run: the fit explains the record (no material residual "
                              "structure, its parameters agree between parts of the record)")
            return
        if self.restart_far():
            residual, disagree = self.structure()
            if not (residual or disagree):
                self.joint_why = ("not run: the refit from the configured values explains "
                                  "the record")
                return
        if self.restart_resonance():
            self.joint_why = ("not run: the refit from the record's piston resonance explains "
                              "the record")
            return
        if self.free_held_again():
            # parameters held at a value an earlier round's model needed (a baseline one
            # held at the preset, an effect's shape held when it came in before the others)
            # are the model's own, and freeing them is the loop's last step anyway: one
            # short refit, where a set is several full ones, each with them still held. Where
            # that explains the record no effect is looked for beyond it (free piston, seal
            # friction and pulsation under slide, rig seed 3: J_c apart between bands, 45 s
            # of refused sets, then d_p and k_s freed explained the record; pump friction
            # and pulsation: the motor encoder 1.6 floors, a refused pair, then d_s and the
            # friction's regularisation velocity freed explained it)
            self.joint_why = ("not run: the refit with the held parameters freed again "
                              "explains the record")
            return
        why = "; ".join(filter(None, (residual, disagree)))
        self.joint_why = f"run: {why}"
        self.say(f"joint search, the fit leaves {why}")
        pool = _joint_pool(self.tests_for_sets(), defs_all, self.added_labels)
        sets = [[a, b] for i, a in enumerate(pool) for b in pool[i + 1:]]
        if len(pool) >= 3:
            sets.append(pool[:3])
        # then, where no pair or triple passes, single candidates again (_single_pool)
        sets += [[lbl] for lbl in _single_pool(self.rounds, defs_all, self.added_labels,
                                               self.excluded)]
        best_set: tuple[float, list[str], FitResult, dict[str, str]] | None = None
        before = _val_cost(exp, self.current.outputs, self.sigma_ref)
        for labels in sets:
            if best_set is not None:
                # the sets are in the pool's order, best-supported first: the first that
                # passes is taken. Picking the lowest validation cost among all that pass
                # made the outcome hang on which of two near-equal refits came out a hair
                # lower, and cost a refit per set tried after it (free piston, both
                # frictions: two more pairs, 12 s, both refused)
                break
            ds_ = [defs_all[lbl] for lbl in labels]
            new, held_now, after, change, why = self.refit_set(labels, before)
            if change is None:
                continue
            shrunk = {e.label for e in _shrunk(ds_, new)}
            rest = [lbl for lbl in labels if lbl not in shrunk]
            if why.startswith("the refit shrank") and rest and rest not in sets:
                # the set was credible and lowered the cost, but some of it shrank to
                # nothing: the rest of it is what the data ask for, tried alone (free
                # piston, both frictions under slide, the pump friction not selected once
                # the seal was in: with a third-order pulsation it removed 52 % of the
                # validation cost, the pulsation shrunk to 0.8 % of a realistic size)
                sets.append(rest)
            if not why:
                best_set = (after, labels, new, held_now)
        if best_set is None:
            return
        _, labels, new, held_now = best_set
        self.add_set(labels, new, held_now)

    def tests_for_sets(self) -> list[list[CandidateTest]]:
        """The score tests :meth:`joint` ranks its sets by: the rounds', and, where the
        sets' refits start from a robust start that moves parameters (:meth:`robust_start`),
        the candidates the last round found not excited tested again there, as a latest
        round (a candidate's latest test ranks it). A test is linearised where it is made,
        and a fit that absorbed the effects into far parameters can hide one in a residual
        it leaves tens of times the noise (free piston, pump and seal friction under the
        multisine, rig seed 1: the baseline's ``J_p`` 232x and ``J_c`` 7200x, the pump
        friction "not excited", a realistic size 1.5 standard errors out of the residual, in
        every round, so never in a set; tested at the robust start it ranks second to the
        seal, and the pair explains the record). The candidates the rounds tested keep their
        tests (at rig seed 3 the pump friction, significant in the rounds, is not tested at
        the robust start, ``d_p`` put back, when every candidate is tested again there)."""
        exp, current = self.exp, self.current
        far = self.robust_start(current)
        if not far or not self.rounds:
            return self.rounds
        last = {t.label: t.status for t in self.rounds[-1]}
        defs = [d for lbl, d in self.defs_all.items()
                if last.get(lbl) == "not_excited" and not d.judged_at_fit]
        if not defs:
            return self.rounds
        theta = current.theta.copy()
        for p in far:
            theta[IDX[p]] = self.configured[IDX[p]]
        self.say(f"{', '.join(d.label for d in defs)} tested again from the configured values "
                 f"of {', '.join(far)}")
        out = self.test_model.outputs(theta)
        residual = {c: exp.measured[c] - out[c] for c in exp.channels}
        return [*self.rounds, test_candidates(defs, self.test_model.outputs, theta, IDX, exp,
                                              current.weights, residual, self.est_mask,
                                              exp.val, current.free,
                                              states=self.test_model.states)]

    def refit_set(self, labels: list[str], before: float
                  ) -> tuple[FitResult, dict[str, str], float, float | None, str]:
        """The candidates ``labels`` refitted together from the robust start, their
        parameters from a quarter of their realistic sizes, judged as a single one is
        (:meth:`verdict_on`) against the validation cost ``before``; reported in the joint
        rows. Returns the fit, its held parameters, its validation cost, the cost's relative
        change (None: diverged) and why it is not kept ("" if it is)."""
        ds_ = [self.defs_all[lbl] for lbl in labels]
        self.say(f"jointly: {' + '.join(labels)}")
        start = {p: 0.25 * nom for e in ds_ for p, nom in zip(e.params, e.nominal, strict=True)}
        new, held_now = self.refit_with(ds_, start, robust=True)
        after = _val_cost(self.exp, new.outputs, self.sigma_ref)
        change, why = joint_change(before, after)
        if not why:
            why = self.verdict_on(ds_, new, held_now)
        self.joint_rows.append({"effects": labels, "validation_cost_change": change,
                                "outcome": why or "passes"})
        return new, held_now, after, change, why

    def add_set(self, labels: list[str], new: FitResult, held_now: dict[str, str]) -> None:
        """The candidates ``labels``, refitted together to ``new``, added."""
        defs_all, held = self.defs_all, self.held
        for row in self.joint_rows:
            if row["effects"] == labels:
                row["outcome"] = "added"
        for lbl in labels:
            for p, _ in defs_all[lbl].refit_extra:
                if p in held_now:
                    held[p] = f"after adding {lbl}: {held_now.pop(p)}"
        for p, why in held_now.items():
            held[p] = f"after adding {' + '.join(labels)}: {why}"
        self.current = new
        last = {t.label: t for tests in self.rounds for t in tests}
        for lbl in labels:
            self.added_labels.add(lbl)
            last[lbl].selected = True
            self.added.append(EffectAdded(defs_all[lbl].name, lbl, {}, len(self.rounds) - 1,
                                          last[lbl].p_holm, last[lbl].share_val))

    def free_held_again(self) -> bool:
        """A baseline parameter held because an unmodelled effect blurred it may be credible
        now that the effect is in: free the held ones once more (the guard holds them again
        if not). So may an added effect's shape parameter held when it came in before the
        others (free piston, pump friction, pulsation and viscosity: the pump friction's
        regularisation velocity held at the preset's 0.1 mm/s in the round that added it, the
        pulsation and the viscosity still missing, and its force 11 % low for it).

        Tried once per fit: :meth:`joint` may try it first, and a fit it was tried at is
        not tried again (the same fit and held parameters give the same answer). True when
        the freed fit is kept."""
        if self.current is self.freed_at:
            return False
        kept = self._free_held_again()
        self.freed_at = self.current
        return kept

    def _free_held_again(self) -> bool:
        current, held = self.current, self.held
        shapes = {p for e in self.added for p, _ in self.defs_all[e.label].refit_extra}
        retry = [p for p in held if (p in BASELINE_LABELS or p in shapes)
                 and p not in current.free]
        if not (self.added and retry):
            return False
        fitter = self.refitter()
        # One Jacobian tells which of them the data pin now: one whose interval at the
        # current fit is still wider than its value would be held again by the guard, after
        # a refit with all of them free and another without it (a third of a 16 s record's
        # time, for the same fit)
        # (a shape held at its start, where the rest of the model then sat, is tried at its
        # refit whatever its interval at that start)
        narrow = pinned(fitter, current, current.free, retry)
        retry = [p for p in retry if p in shapes or p in narrow]
        if not retry:
            return False
        self.say(f"refit with {', '.join(retry)} free again")
        first = fitter.fit(current.theta, current.free + retry, sigma=current.sigma, passes=1,
                           max_nfev=9)
        bad = fitter.offenders(first)
        if set(retry) <= {n for n, _, _ in bad}:
            # not one of them credible at the refit: the guard would hold them again one at
            # a time, a refit each, and come back to the fit there is
            return False
        if bad and bad[0][0] in current.free:
            # the guard's first hold would be of a parameter the fit there is has free, and
            # a refit that holds one of those is not kept, whatever the guard's further
            # holds (a refit each) do
            return False
        again, held_again = guarded_fit(fitter, current.theta, current.free + retry,
                                        current.theta, sigma=current.sigma, passes=1,
                                        max_nfev=9, configured=self.model.start_vector(),
                                        first=first)
        if any(p in held_again for p in current.free):
            return False
        held_before = dict(held)
        for p in retry:
            if p not in held_again:
                held.pop(p)
        self.current = again
        # a short refit that raises the validation cost is not run on: it is refused as
        # :meth:`worse_than` would refuse it, without judging its residual first (the conrod's
        # two frictions, rig seed 2: `c_rod` freed at the end, 668.612 vs 668.054, its
        # residual analysis and consistency 1.3 s of CPU for a fit not kept)
        why = self.cost_rises(current)
        if not why:
            self.finish_freed(fitter, current)
            why = self.worse_than(current)
        if why:
            self.current = current
            held.clear()
            held.update(held_before)
            self.rejected.append(f"{', '.join(retry)} freed again: not kept ({why})")
            return False
        return True

    def finish_freed(self, fitter: OutputErrorFit, before: FitResult) -> None:
        """The refit that freed held parameters is short (one pass of three Jacobians: it
        asks whether the data pin them now). Where the fit it gives still leaves structure,
        it may simply not have arrived: parameters held at a value an earlier round's model
        needed start far from where the full model wants them (free piston, pump friction,
        pulsation and viscosity, seed 1: `k_s` and `d_s` held at the preset since the
        baseline, freed at the end, stopped with `d_s` 1.3x the truth and the viscosity 11 %
        low, the piston encoder 15.6 floors high; seal friction and pulsation, seed 2:
        `J_c` held at 6.8x the truth, freed at 2x). The fit is run on to its end; it is kept
        when it holds none of the parameters that are free and does not raise the
        validation cost.

        It is run on only where the short refit took a material share of the residual
        structure that ``before`` (the fit without them freed) left (:data:`RUN_ON_PROGRESS`
        of :func:`structure_excess`): a descent that is on its way to explaining the record
        (the first case above: the piston encoder 18.5 floors high before, 15.6 after the
        short refit, 1.3 after the run-on) against one that moved the freed parameters
        without touching the structure (free piston, pump and seal friction, the bench's
        16 s multisine record: the pressures' residual 78 % predictable before, 76 % after
        the short refit, 75 % after a run-on of 7.5 s of CPU, which :meth:`worse_than` then
        refuses for that structure). Where the structure left is only a disagreement between
        parts of the record (no residual measure to compare) it is run on as before."""
        if not self.structure_left():
            return
        current = self.current
        was = structure_excess(self.judged(before)[0])
        now = structure_excess(self.judged(current)[0])
        if was > 0.0 and not now <= (1.0 - RUN_ON_PROGRESS) * was:
            self.say(f"the refit that freed held parameters not run on: it left "
                     f"{now / was:.0%} of the residual structure there was")
            return
        self.say("the refit that freed held parameters, run on to its end")
        done, held_now = guarded_fit(fitter, current.theta, list(current.free),
                                     current.theta, sigma=current.sigma,
                                     configured=self.configured)
        before = _val_cost(self.exp, current.outputs, self.sigma_ref)
        after = _val_cost(self.exp, done.outputs, self.sigma_ref)
        if not held_now and after <= before:
            self.current = done

    def cost_rises(self, before: FitResult) -> str:
        """Why the current fit's validation cost is above ``before``'s ("" if it is not)."""
        exp = self.exp
        cost_before = _val_cost(exp, before.outputs, self.sigma_ref)
        cost_now = _val_cost(exp, self.current.outputs, self.sigma_ref)
        if cost_now > cost_before:
            return f"the validation cost rises, {cost_now:.6g} vs {cost_before:.6g}"
        return ""

    def worse_than(self, before: FitResult) -> str:
        """Why the current fit, reached from ``before`` by freeing held parameters, is not
        kept ("" if it is): a higher validation cost, or structure left, in the residual or
        as parameters that disagree between parts of the record. Freeing them is kept where
        it explains the record (the motivating cases of :meth:`finish_freed` end
        ``explained``); a fit that still leaves structure has not found what the model
        lacks, and a lower cost bought there by parameters the record barely pins is that
        structure taken into them: the fit before is the one to report (free piston, both
        frictions added near their sizes, the pressures' residual 75 % predictable either
        way: `d_s`, `J_p`, `J_c` freed took `k_s` to 3.4x and the pump friction 22 % high for
        1.7 % of the validation cost, and whether `k_s` then came out inconsistent between
        bands hung on the CSV's last digits)."""
        why = self.cost_rises(before)
        if why:
            return why
        left = self.structure_left()
        return f"it still leaves {left}" if left else ""

    def report(self, t_start: float) -> IdentifyReport:
        """The added effects described with the final fit's covariance, the residual judged
        again, the parameters' consistency across parts of the record; the wall time from
        ``t_start`` (:func:`time.perf_counter`)."""
        exp, current, base, data = self.exp, self.current, self.base, self.data
        for e in self.added:
            d = self.defs_all[e.label]
            e.params = EFFECTS[d.name].describe(d, current, exp)
        self.say("consistency of the parameters across frequency bands, time segments and "
                 "channels")
        analysis1, agree = self.judged(current)
        channels = [ChannelError(c, nrmse(exp.measured[c][exp.val], base.outputs[c][exp.val]),
                                 nrmse(exp.measured[c][exp.val], current.outputs[c][exp.val]))
                    for c in exp.channels]
        unexplained, detail = _verdict(analysis1)
        if agree.inconsistent:
            # a white residual bought with parameters that differ with the part of the
            # record that pins them: the model absorbs a structure it does not have
            unexplained = True
            detail = "; ".join(filter(None, [detail, "parameters disagree between parts of "
                                             "the record, the model lacks structure: "
                                             + "; ".join(
                                                 s.describe(BASELINE_LABELS[s.name][0])
                                                 for s in agree.inconsistent)]))
        final_est = _estimates(current, self.names)
        differs = differs_from_configuration(current, exp, final_est)
        return IdentifyReport(
            data.path, data.load, exp.n, data.sample_rate_hz, self.baseline_est, final_est,
            self.held, self.added, self.rounds, channels, self.analysis0, analysis1,
            unexplained, detail,
            notes=list(data.notes) + list(exp.notes)
            + [f"ignored column {c}" for c in data.ignored],
            rejected=self.rejected, joint=self.joint_rows, joint_why=self.joint_why,
            restarts=self.restarts,
            wall_s=time.perf_counter() - t_start, experiment=exp,
            outputs_before=base.outputs, outputs_after=current.outputs,
            intersample=exp.intersample, intersample_reason=exp.intersample_reason,
            input_noise=self.noise, consistency=agree, differs=differs,
        )


#: Candidates refitted together when none passes alone: the best few of the last round.
JOINT_POOL = 3
#: Validation cost of a joint refit, as a multiple of the fit's without the effects, above
#: which the refit has diverged on the held-out part (a model that went unstable there): it
#: is reported as that, with no percentage of a runaway cost.
DIVERGED_RATIO = 10.0


def _joint_pool(rounds: list[list[CandidateTest]], defs: dict[str, EffectDef],
                added: set[str]) -> list[str]:
    """The candidates tried together: of every round's score-tested ones not added (those
    rejected alone included: they are the likeliest halves of a pair), not judged at their
    own fit, the :data:`JOINT_POOL` best, significant ones first, then by the share of the
    validation residual they would remove; one per library effect (pulsation orders compete
    among themselves)."""
    best: dict[str, CandidateTest] = {}
    for tests in rounds:
        for t in tests:
            if t.status == "tested" and t.label not in added and not defs[t.label].judged_at_fit:
                best[t.label] = t  # the latest round's test of it
    ranked = sorted(best.values(), key=lambda t: (not t.significant, -t.share_val))
    pool: list[str] = []
    names: set[str] = set()
    for t in ranked:
        if t.name not in names:
            pool.append(t.label)
            names.add(t.name)
    return pool[:JOINT_POOL]


def _single_pool(rounds: list[list[CandidateTest]], defs: dict[str, EffectDef],
                 added: set[str], excluded: set[str]) -> list[str]:
    """Candidates refitted alone again, from the robust start, where no pair passes: those
    rejected at their refit in an earlier round (the model has changed since: the seal
    friction on the free piston, refused while a pulsation was still missing) and those the
    last round's score test called collinear with a declared parameter (the fit had taken
    the effect into that parameter: a pump friction into ``K`` and ``J_p``, a test
    linearised there cannot see it). One per library effect, not judged at their own
    fit."""
    out: list[str] = []
    names = {defs[lbl].name for lbl in added}
    last = rounds[-1] if rounds else []
    for lbl in [*sorted(excluded), *(t.label for t in last if t.status == "collinear")]:
        d = defs[lbl]
        if lbl in added or d.judged_at_fit or d.name in names or lbl in out:
            continue
        out.append(lbl)
        names.add(d.name)
    return out


def _sizes(d: EffectDef, fit: FitResult) -> dict[str, float]:
    """The effect's parameters in ``fit`` relative to their realistic sizes."""
    return {p: abs(fit.value(p)) / abs(nom)
            for p, nom in zip(d.params, d.nominal, strict=True) if nom}


def _shrunk(ds_: list[EffectDef], fit: FitResult) -> list[EffectDef]:
    """The effects of ``ds_`` that ``fit`` shrank below :data:`MIN_MAGNITUDE` of a
    realistic size (every parameter)."""
    return [d for d in ds_ if (sizes := _sizes(d, fit)) and max(sizes.values()) < MIN_MAGNITUDE]


def joint_change(before: float, after: float) -> tuple[float | None, str]:
    """The relative change of the validation cost by a joint refit, and why the refit is
    out at once ("" if not): several effects' parameters fitted together from small starts
    can find a model that fits the estimation part and runs away on the held-out one (a
    cost beyond :data:`DIVERGED_RATIO` times the one before, or not finite); its change is
    None then, not a percentage of a runaway."""
    ratio = after / before if before > 0 else float("inf")
    if np.isfinite(ratio) and ratio <= DIVERGED_RATIO:
        return ratio - 1.0, ""
    return None, f"diverged on the validation part (cost {ratio:.3g} x the fit without them)"


def _all_scales(defs: dict[str, EffectDef]) -> dict[str, float]:
    out = {}
    for d in defs.values():
        for p, nom in zip(d.params, d.nominal, strict=True):
            out[p] = nom
    return out


#: Share of a judged channel's residual variance predictable from its own past above which
#: non-white structure counts as material (see :mod:`hil.identify.residuals`).
MATERIAL_SHARE = 0.01
#: Factor from the configured (datasheet) value beyond which a fitted parameter is reported
#: as "differs from the configuration": a finding about the rig (another rod, hose,
#: fixture), not about the model, unless the parameter also disagrees between parts of the
#: record (:mod:`hil.identify.consistency`).
DIFFERS_FACTOR = 1.5


#: Parameters outside :data:`CONSISTENCY_JUDGED` that the robust start
#: (:meth:`_Loop.robust_start`) also puts back: the connecting rod's damper and the sensors'
#: lags take a dissipation or a phase the model lacks as readily as the judged dampers do.
ABSORBING = ("c_rod", "lag_pressure_s", "lag_strain_s")
#: Jacobians per pass of a refit from the robust start (40 from a start near the end).
ROBUST_NFEV = 120
#: Jacobians per pass of a refit from the fit as it stands.
PLAIN_NFEV = 40

#: Parameters of a friction that can hold the piston (the seal's static level): its refit
#: after other effects makes the held-first refit (:meth:`_Loop.held_first`) before the plain
#: one, and no plain one where the held-first one leaves the residual white. Of the 6 s
#: ``identify-check`` rows that made both (the conrod's pump friction + seal and the triple
#: with pulsation, both seeds), the seal's held-first refit was kept in 3 of 4, the pump
#: friction's (after the pulsation) in none of 3: it stays second, made only where the plain
#: refit leaves structure.
STICK_SLIP = frozenset({"sf_coulomb_n"})
#: Share of the estimation cost by which the refit from the robust start must end lower than
#: the one from the fit as it stands to be kept (:meth:`_Loop.start_chosen`): two minima lie
#: tens of per cent apart, two ends of one minimum well within a per cent.
START_MARGIN = 0.02
#: Share above the plain refit's estimation cost within which the robust start's trial, still
#: descending at its budget's end, is run on in full (:meth:`_Loop.start_chosen`).
RUN_ON_BAND = 0.25


def far_from_configuration(fit: FitResult, exp: Experiment) -> list[str]:
    """Free linear-model parameters beyond :data:`DIFFERS_FACTOR` of their configured
    values."""
    out = []
    for name in CONSISTENCY_JUDGED:
        start = exp.start.get(name)
        if name in fit.free and start:
            ratio = fit.value(name) / start
            if not 1.0 / DIFFERS_FACTOR <= ratio <= DIFFERS_FACTOR:
                out.append(name)
    return out


def differs_from_configuration(fit: FitResult, exp: Experiment,
                               estimates: dict[str, ParamEstimate]) -> dict[str, dict]:
    """:func:`far_from_configuration` for the report: ``{symbol: {"value", "ci95", "unit",
    "configured", "ratio"}}``."""
    out = {}
    for name in far_from_configuration(fit, exp):
        sym, unit, _ = BASELINE_LABELS[name]
        e = estimates[sym]
        out[sym] = {"value": e.value, "ci95": [e.ci_low, e.ci_high], "unit": unit,
                    "configured": exp.start[name], "ratio": fit.value(name) / exp.start[name]}
    return out


#: Share of the residual structure (:func:`structure_excess`) the short refit that frees held
#: parameters must take off for its run-on to be made (:meth:`_Loop.finish_freed`).
RUN_ON_PROGRESS = 0.1
#: Residual variances a step must gain for a pass to go on, in a fit whose end a verdict
#: reads as it stands (:meth:`_Loop.restart_resonance`: kept only where it explains the
#: record); the other fits stop at :data:`~hil.identify.fit.CONVERGED_GAIN`.
JUDGED_GAIN = 1.0
#: Refits at most from the record's piston resonance (:meth:`_Loop.restart_resonance`): each
#: after the first is made only while the last took :data:`RUN_ON_PROGRESS` of the residual
#: structure off.
RESONANCE_REFITS = 4
#: The low-pass of :meth:`_Loop.restart_slow_first`'s first stage, as a share of the record's
#: piston line: 0.4 of the free piston's 1.24 kHz is 500 Hz; the fourth-order filter takes
#: the line about 30 dB down.
SLOW_CUTOFF = 0.4


def pinned(fitter: OutputErrorFit, fit: FitResult, free: list[str], held: list[str]
           ) -> list[str]:
    """Of the ``held`` parameters, those the record pins at ``fit``: with them and ``free``
    free, their 95 % interval narrower than their value (one Jacobian), or not held for
    credibility at all (not in :data:`CREDIBLE`)."""
    se = fitter.standard_errors(fit.theta, free + held, fit.sigma)
    return [p for p in held if p not in CREDIBLE
            or 2.0 * Z95 * se.get(p, np.inf) <= abs(fit.value(p))]


def _material(a: ResidualAnalysis) -> list:
    """The judged channels whose residual holds material structure (:func:`_verdict`)."""
    return [r for r in a.channels.values() if r.judged and not r.white
            and (r.floor_ratio > 0 or r.predictable_share > MATERIAL_SHARE)]


def structure_excess(a: ResidualAnalysis) -> float:
    """How far the worst judged channel's residual is beyond the verdict's limits
    (:func:`_verdict`), in units of them: an encoder speed's multiple of its quantisation
    floor, else the share of the residual predictable from its past over
    :data:`MATERIAL_SHARE`; 0 where no channel holds material structure."""
    return max((r.floor_ratio if r.floor_ratio > 0 else r.predictable_share / MATERIAL_SHARE
                for r in _material(a)), default=0.0)


def _verdict(a: ResidualAnalysis) -> tuple[bool, str]:
    """``unexplained`` when a judged channel's residual still holds material structure:
    not white and more than 1 % of its variance predictable from its past (pressures and
    strain), or more than 1.5 x the quantisation floor by at least 1 % of the speed (encoder
    speeds)."""
    bad = _material(a)
    if not bad:
        return False, ""
    parts = []
    for r in bad:
        if r.floor_ratio > 0:
            parts.append(f"{r.channel}: residual {r.floor_ratio:.1f} x the encoder's "
                         f"quantisation floor ({r.excess_share:.1%} of the speed beyond it)")
            continue
        what = (f"{r.channel}: Ljung-Box p={r.ljung_box_p:.2g}, "
                f"{r.predictable_share:.1%} of the residual predictable")
        if r.peak_hz_ratio > 20:
            what += f", narrow-band peak at {r.peak_hz:.1f} Hz"
            if r.peak_order_ratio > 8:
                what += f" (rotor-angle order {r.peak_order:g} also stands out)"
            else:
                what += " not locked to the rotor angle"
        parts.append(what)
    return True, "residual structure no candidate explains: " + "; ".join(parts)


__all__ = ["ChannelError", "EffectAdded", "IdentifyReport", "ParamEstimate", "identify",
           "nrmse"]
