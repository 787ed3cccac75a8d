"""The identification checked against the independent rig: a matrix of cases, each judged.

Each case is a record from :mod:`hil.identify.rig` (parameters drawn off the preset, a
continuous current logged with converter noise, sensor chains, other friction laws) with a
known truth; :func:`hil.identify.pipeline.identify` sees only the record. A case is *right*
when

* every true library effect is named, and nothing else is added;
* each judged magnitude (:func:`magnitude_keys`) is within :data:`TOL_MAGNITUDE` of the truth
  (amplitudes within :data:`TOL_AMPLITUDE`);
* the verdict is honest: ``unexplained`` exactly when an effect outside the library is in
  the record.

``eha-hil identify-check`` runs the matrix (two seeds by default, a process per core) and
prints or writes it as a markdown table (docs/identify.md, "Checked against the rig").
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any


def magnitude_keys() -> dict[str, tuple[tuple[str, str, str], ...]]:
    """(truth key in the rig's ``truth["effects"][name]``, key in the report's effect params,
    tolerance kind) per library effect: the magnitudes a case is judged on (each effect's
    :attr:`~hil.identify.effects.Effect.judged`)."""
    from hil.identify.effects import EFFECTS

    return {name: e.judged for name, e in EFFECTS.items()}


TOL_MAGNITUDE = 0.10
TOL_AMPLITUDE = 0.20

LOADS: tuple[str, ...] = ("fixed_piston", "free_piston", "conrod_fixed")


#: The preset's keys a case may scale (a different rig: another hose, rod, piston), with the
#: short names the table shows.
RIG_SCALES: dict[str, str] = {"hydraulics.ks_n_per_m": "k_s",
                              "load.conrod_stiffness_n_per_m": "k_rod",
                              "hydraulics.jc_kg": "J_c"}


@dataclass(frozen=True)
class Case:
    """One record of the matrix: load, effects (rig names), experiment profile; ``scale``:
    preset values the rig is built from, scaled (key of :data:`RIG_SCALES`, factor), while
    the identification starts from the unscaled preset; ``magnitudes``: (effect, key,
    value) overrides of the rig's default magnitudes."""

    load: str
    effects: tuple[str, ...] = ()
    profile: str = "multisine"
    seconds: float = 6.0
    scale: tuple[tuple[str, float], ...] = ()
    magnitudes: tuple[tuple[str, str, float], ...] = ()
    #: the outside effect is, over the excitation band, the linear model with other
    #: parameters (:func:`equivalent_parameters`): right is ``explained`` with those
    absorbed: bool = False

    @property
    def label(self) -> str:
        eff = " + ".join(self.effects) if self.effects else "null"
        for name, key, value in self.magnitudes:
            eff = eff.replace(name, f"{name} ({key} {value:g})", 1)
        prof = "" if self.profile == "multisine" else f" ({self.profile})"
        rig = "".join(f", {RIG_SCALES[k]} {f:g}x" for k, f in self.scale)
        return f"{self.load}{rig}: {eff}{prof}"

    def rig_effects(self) -> dict[str, dict[str, float]]:
        """The effects with their magnitude overrides, as :func:`generate_rig` takes them."""
        out: dict[str, dict[str, float]] = {e: {} for e in self.effects}
        for name, key, value in self.magnitudes:
            out[name][key] = value
        return out

    def rig_preset(self, cfg: Any) -> Any:
        """The preset the rig is built from: ``cfg`` with :attr:`scale` applied."""
        if not self.scale:
            return cfg
        return cfg.with_overrides({k: f * cfg.get(k) for k, f in self.scale},
                                  source="identify-check: a different rig")


def default_cases() -> list[Case]:
    """Null on each load; each library effect alone on each load where it is observable;
    effects outside the library (a viscoelastic hose, mains hum on a pressure sensor, backlash
    at the motor encoder); two effects at once."""
    cases = [Case(load) for load in LOADS]
    each_load = ("pump_pulsation", "pump_coulomb_friction", "viscosity_temperature",
                 "input_delay")
    for eff in each_load:
        cases += [Case(load, (eff,)) for load in LOADS]
    cases += [Case(load, ("seal_friction",), profile="slide" if load == "free_piston"
                      else "multisine") for load in ("free_piston", "conrod_fixed")]
    cases.append(Case("free_piston", ("stiffness_vs_position",), profile="resonance"))
    cases += [Case(load, ("strain_thermal_drift",)) for load in ("fixed_piston", "conrod_fixed")]
    cases += [Case(load, ("sensor_saturation",)) for load in ("fixed_piston", "conrod_fixed")]
    cases += [Case(load, ("hose_viscoelastic",)) for load in ("fixed_piston", "conrod_fixed")]
    cases += [Case("conrod_fixed", ("mains_hum",)), Case("free_piston", ("backlash",))]
    cases += [Case("fixed_piston", ("pump_pulsation", "pump_coulomb_friction")),
              Case("conrod_fixed", ("input_delay", "strain_thermal_drift")),
              Case("free_piston", ("pump_coulomb_friction", "viscosity_temperature"))]
    return cases + different_rig_cases() + viscoelastic_cases() + combined_cases()


def different_rig_cases() -> list[Case]:
    """Rigs 0.25x-4x off the preset the fit starts from (a stiffer or softer hose or rod, a
    heavier piston), with and without a library effect: right is what the rig has, the
    different values reported, not an ``unexplained``."""
    ks, rod, jc = "hydraulics.ks_n_per_m", "load.conrod_stiffness_n_per_m", "hydraulics.jc_kg"
    return [Case("fixed_piston", scale=((ks, 4.0),)),
            Case("fixed_piston", ("pump_coulomb_friction",), scale=((ks, 0.25),)),
            Case("conrod_fixed", scale=((rod, 4.0),)),
            Case("conrod_fixed", scale=((rod, 0.25),)),
            Case("conrod_fixed", ("pump_pulsation",), scale=((rod, 4.0),)),
            Case("free_piston", scale=((jc, 4.0),)),
            Case("free_piston", ("pump_coulomb_friction",), scale=((jc, 4.0),)),
            Case("conrod_fixed", ("viscosity_temperature",), scale=((rod, 4.0), (jc, 4.0)))]


def viscoelastic_cases() -> list[Case]:
    """A series elasticity with a frequency-dependent part (a Maxwell branch of half the
    stiffness) with its corner from 0.5 to 30 Hz (30 Hz is in the matrix above)."""
    return [Case(load, ("hose_viscoelastic",),
                 magnitudes=(("hose_viscoelastic", "corner_hz", corner),),
                 absorbed=corner < ABSORBED_CORNER_HZ)
            for load in ("fixed_piston", "conrod_fixed") for corner in (0.5, 3.0, 10.0)]


#: Maxwell-branch corner below which the branch is, wherever the data pin the series
#: stiffness, a spring ``k_m`` in parallel (docs/identify.md, "Checked against the rig"):
#: its stiffness ``k_m jw/(jw + w_c)`` differs from ``k_m`` by ``k_m/sqrt(1 + (f/f_c)^2)``,
#: and the outputs feel a change of ``k_s`` only as ``(f/f_0)/sqrt(1 + (f/f_0)^2)`` below
#: the series corner ``f_0 = k_s/(2 pi d_s)`` (about 70 Hz with the branch); the product
#: peaks, at ``sqrt(f_c f_0)``, at ``(k_m/(k_s + k_m)) f_c/(f_c + f_0)`` of the force: 0.24 %
#: at 0.5 Hz, 0.47 % at 1 Hz, against 1.4 % at 3 Hz and 4.2 % at 10 Hz; the independent
#: rig's consistent records differ from the model by up to about 1 %
#: (:data:`hil.identify.consistency.MATERIAL_RATIO`).
ABSORBED_CORNER_HZ = 1.0


def equivalent_parameters(case: Case, effects: dict[str, dict[str, float]],
                          parameters: dict[str, float]) -> dict[str, float]:
    """For an :attr:`Case.absorbed` case, the linear model's parameters that the record
    holds (internal names): a Maxwell branch below the band is a stiffer series spring,
    ``k_s + k_m``. ``effects`` and ``parameters``: the rig's truth."""
    out: dict[str, float] = {}
    if case.absorbed and "hose_viscoelastic" in effects:
        out["ks"] = parameters["ks"] + effects["hose_viscoelastic"]["k_m_n_per_m"]
    return out


def combined_cases() -> list[Case]:
    """Two and three effects at once, on each load: frictions together, friction with
    pulsation, drift with viscosity."""
    return [Case("free_piston", ("pump_coulomb_friction", "seal_friction"), profile="slide"),
            Case("conrod_fixed", ("pump_coulomb_friction", "seal_friction")),
            Case("conrod_fixed", ("pump_coulomb_friction", "pump_pulsation")),
            Case("free_piston", ("seal_friction", "pump_pulsation"), profile="slide"),
            Case("conrod_fixed", ("strain_thermal_drift", "viscosity_temperature")),
            Case("fixed_piston", ("strain_thermal_drift", "viscosity_temperature")),
            Case("fixed_piston", ("pump_coulomb_friction", "pump_pulsation",
                                  "viscosity_temperature")),
            Case("free_piston", ("pump_coulomb_friction", "pump_pulsation",
                                 "viscosity_temperature")),
            Case("conrod_fixed", ("pump_coulomb_friction", "seal_friction",
                                  "pump_pulsation"))]


@dataclass
class CaseResult:
    """The judged outcome of one case at one seed."""

    case: Case
    seed: int
    right: bool
    why: str
    truth: list[str]
    found: list[str]
    unexplained: bool
    refused: str | None = None
    magnitudes: list[tuple[str, float, float | None]] = field(default_factory=list)
    wall_s: float = 0.0
    cpu_s: float = 0.0
    #: fitted baseline parameter / its true value - 1, for those the fit did not hold
    param_error: dict[str, float] = field(default_factory=dict)
    #: :func:`report_digest` of the identification's report ("" when refused): two runs of
    #: a case with the same code and seed give the same, wherever the case ran
    digest: str = ""
    #: the report's reason for an ``unexplained`` verdict (the channel, the structure left);
    #: "" when the verdict is ``explained`` or the record was refused
    unexplained_detail: str = ""

    @property
    def verdict(self) -> str:
        """``refused``, ``unexplained`` or ``explained``: the table's verdict column."""
        return ("refused" if self.refused else
                "unexplained" if self.unexplained else "explained")

    def as_dict(self) -> dict[str, Any]:
        """The ``--json`` / ``--rows`` row: every column of the table, and what the table
        leaves out (the report's reason for ``unexplained``, parameter errors, digest)."""
        return {"case": self.case.label, "load": self.case.load,
                "effects": list(self.case.effects), "profile": self.case.profile,
                "seed": self.seed, "right": self.right, "why": self.why,
                "found": self.found, "verdict": self.verdict,
                "unexplained": self.unexplained,
                "unexplained_detail": self.unexplained_detail,
                "refused": self.refused,
                "magnitudes": [{"what": w, "truth": t, "found": f}
                               for w, t, f in self.magnitudes],
                "param_error": self.param_error, "digest": self.digest,
                "wall_s": self.wall_s, "cpu_s": self.cpu_s}


def judge(case: Case, truth: dict[str, dict[str, float]], found: dict[str, dict[str, float]],
          unexplained: bool, equivalent: dict[str, float] | None = None,
          fitted: dict[str, float] | None = None,
          ) -> tuple[bool, str, list[tuple[str, float, float | None]]]:
    """Right or wrong, why, and the magnitudes compared (module docstring). For an
    :attr:`Case.absorbed` case, ``equivalent`` (:func:`equivalent_parameters`) against
    ``fitted`` (the report's final parameters, internal names, those not held) replaces the
    verdict rule: ``explained``, each within :data:`TOL_MAGNITUDE`."""
    from hil.identify.rig import LIBRARY_EFFECTS

    keys = magnitude_keys()
    lib_truth = [e for e in case.effects if e in LIBRARY_EFFECTS]
    outside = [e for e in case.effects if e not in LIBRARY_EFFECTS]
    problems: list[str] = []
    mags: list[tuple[str, float, float | None]] = []
    missing = [e for e in lib_truth if e not in found]
    spurious = [e for e in found if e not in lib_truth]
    if missing:
        problems.append("missed " + ", ".join(missing))
    if spurious:
        problems.append("added " + ", ".join(spurious))
    for eff in lib_truth:
        for tkey, fkey, kind in keys.get(eff, ()):
            want = truth.get(eff, {}).get(tkey)
            if want is None:
                continue
            got = found.get(eff, {}).get(fkey)
            mags.append((f"{eff}.{tkey}", float(want), None if got is None else float(got)))
            if got is None:
                continue
            tol = TOL_AMPLITUDE if kind == "amplitude" else TOL_MAGNITUDE
            if not math.isfinite(got) or abs(got - want) > tol * abs(want):
                problems.append(f"{eff}.{tkey} {got:.4g} vs {want:.4g} "
                                f"({100 * (got / want - 1):+.0f} %)")
    if case.absorbed:
        fitted = fitted or {}
        for name, want in (equivalent or {}).items():
            got = fitted.get(name)
            mags.append((f"equivalent.{name}", float(want), got))
            if got is None:
                problems.append(f"{name} held: the equivalent {want:.4g} not found")
            elif not math.isfinite(got) or abs(got - want) > TOL_MAGNITUDE * abs(want):
                problems.append(f"{name} {got:.4g} vs the equivalent {want:.4g} "
                                f"({100 * (got / want - 1):+.0f} %)")
        if unexplained:
            problems.append("verdict unexplained where the record is the linear model's")
    elif outside and not unexplained:
        problems.append("verdict explained with " + ", ".join(outside) + " in the record")
    if not outside and unexplained:
        problems.append("verdict unexplained")
    return not problems, "; ".join(problems) or "ok", mags


def run_case(case: Case, seed: int) -> CaseResult:
    """Generate the record, identify it, judge it (runs in a worker process)."""
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    t0, c0 = time.perf_counter(), time.process_time()
    cfg = load_config("hydra_default")
    rig = generate_rig(case.load, case.rig_effects(), seconds=case.seconds, seed=seed,
                       profile=case.profile, preset=case.rig_preset(cfg))
    return identify_and_judge(case, seed, rig, cfg, t0, c0)


def identify_and_judge(case: Case, seed: int, rig: Any, cfg: Any, t0: float,
                       c0: float) -> CaseResult:
    """Identify the rig's record ``rig`` (:class:`hil.identify.rig.RigResult`) starting from
    ``cfg`` and judge it against the rig's truth; ``t0``/``c0``: wall/CPU clock at the
    start (the figures include the rig's own simulation)."""
    from hil.identify.checks import RefusedData
    from hil.identify.pipeline import BASELINE_LABELS, identify

    truth = rig.truth["effects"]
    try:
        rep = identify(rig.data, cfg)
    except RefusedData as err:
        return CaseResult(case, seed, False, f"refused: {err}", list(case.effects), [],
                          False, refused=str(err), wall_s=time.perf_counter() - t0,
                          cpu_s=time.process_time() - c0)
    found: dict[str, dict[str, float]] = {}
    labels: list[str] = []
    for e in rep.effects_added:
        labels.append(e.label)
        params = {k: v.value for k, v in e.params.items()}
        if e.name in found:  # a second order of the same effect: keep the first's figures
            continue
        found[e.name] = params
    true_p = rig.truth["parameters"]
    fitted = {name: rep.final[sym].value for name, (sym, _, _) in BASELINE_LABELS.items()
              if sym in rep.final and name not in rep.held}
    right, why, mags = judge(case, truth, found, rep.unexplained,
                             equivalent_parameters(case, truth, true_p), fitted)
    param_error = {sym: rep.final[sym].value / true_p[name] - 1.0
                   for name, (sym, _, _) in BASELINE_LABELS.items()
                   if sym in rep.final and name in true_p and name not in rep.held}
    return CaseResult(case, seed, right, why, list(case.effects), labels, rep.unexplained,
                      magnitudes=mags, wall_s=time.perf_counter() - t0,
                      cpu_s=time.process_time() - c0, param_error=param_error,
                      digest=report_digest(rep),
                      unexplained_detail=rep.unexplained_detail if rep.unexplained else "")


def report_text(rep: Any) -> str:
    """The report's JSON summary (:func:`hil.identify.report.summary`) with every float at
    full precision and its wall time left out: the same for the same record and code,
    whatever ran before in the process and however many threads it had."""
    import json

    from hil.identify.report import summary

    s = summary(rep)
    s.pop("wall_s", None)
    return json.dumps(s, sort_keys=True, default=repr)


def report_digest(rep: Any) -> str:
    """The first 16 hex digits of the SHA-256 of :func:`report_text`."""
    import hashlib

    return hashlib.sha256(report_text(rep).encode()).hexdigest()[:16]


def _run_packed(args: tuple[Case, int]) -> CaseResult:
    return run_case(*args)


def run_matrix(cases: Sequence[Case], seeds: Sequence[int], jobs: int = 1,
               progress: Callable[[CaseResult, int, int], None] | None = None
               ) -> list[CaseResult]:
    """Every case at every seed; ``jobs`` worker processes; results in matrix order."""
    work = [(c, s) for c in cases for s in seeds]
    results: list[CaseResult | None] = [None] * len(work)
    if jobs <= 1:
        for i, w in enumerate(work):
            results[i] = _run_packed(w)
            if progress:
                progress(results[i], i + 1, len(work))  # type: ignore[arg-type]
        return results  # type: ignore[return-value]
    from concurrent.futures import as_completed

    from hil.workers.pools import process_pool

    _warm()  # compile the kernels into numba's cache once, not in every worker at once
    # workers leave Ctrl-C to this process and end with it (no orphans, no wait)
    with process_pool(jobs) as pool:
        futures = {pool.submit(_run_packed, w): i for i, w in enumerate(work)}
        for done, fut in enumerate(as_completed(futures), start=1):
            res = fut.result()  # a worker that died raises BrokenProcessPool here
            results[futures[fut]] = res
            if progress:
                progress(res, done, len(work))
    return results  # type: ignore[return-value]


def _warm() -> None:
    """Run the rig's and the fit's compiled kernels once (numba caches them on disk)."""
    from hil.identify.experiment import prepare
    from hil.identify.model import FastModel
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    rig = generate_rig("fixed_piston", ["pump_coulomb_friction"], seconds=0.2)
    model = FastModel(prepare(rig.data, load_config("hydra_default")))
    model.outputs(model.start_vector())


def _fmt_mag(what: str, truth: float, found: float | None) -> str:
    short = what.split(".", 1)[1]
    f = "-" if found is None else f"{found:.4g}"
    return f"{short} {truth:.4g} / {f}"


def markdown(results: Sequence[CaseResult]) -> str:
    """The matrix as a markdown table (CPU: the case's process, record and identification),
    then a one-line tally."""
    lines = ["| case | seed | truth / found (magnitudes) | effects found | verdict | right "
             "| CPU s |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        mags = "; ".join(_fmt_mag(*m) for m in r.magnitudes) or "-"
        found = ", ".join(r.found) or "none"
        ok = "yes" if r.right else f"**no**: {r.why}"
        lines.append(f"| {r.case.label} | {r.seed} | {mags} | {found} | {r.verdict} | {ok} "
                     f"| {r.cpu_s:.0f} |")
    n_right = sum(r.right for r in results)
    cpu = sum(r.cpu_s for r in results)
    lines.append("")
    lines.append(f"{n_right} of {len(results)} right; {cpu:.0f} s CPU in all.")
    return "\n".join(lines)
