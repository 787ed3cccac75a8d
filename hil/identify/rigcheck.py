"""The identification checked against the independent rig: a matrix of cases, each judged.

Each case is a record from :mod:`hil.identify.rig` (parameters drawn off the preset, a
continuous current logged with converter noise, sensor chains, other friction laws) with a
known truth; :func:`hil.identify.pipeline.identify` sees only the record. A case is *right*
when

* every true library effect is named, and nothing else is added;
* each judged magnitude (:data:`MAGNITUDE_KEYS`) is within :data:`TOL_MAGNITUDE` of the truth
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

#: (truth key in the rig's ``truth["effects"][name]``, key in the report's effect params,
#: tolerance kind) per library effect: the magnitudes a case is judged on.
MAGNITUDE_KEYS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "pump_pulsation": (("amplitude", "amplitude", "amplitude"),
                       ("torque_n", "torque_n", "amplitude")),
    "pump_coulomb_friction": (("force_n", "force_n", "magnitude"),),
    "seal_friction": (("coulomb_n", "coulomb_n", "magnitude"),),
    "stiffness_vs_position": (("ks_relative_span", "ks_relative_span", "magnitude"),),
    "viscosity_temperature": (("coeff_per_c", "coeff_per_c", "magnitude"),),
    "strain_thermal_drift": (("n_per_c", "n_per_c", "magnitude"),),
    "input_delay": (("delay_s", "delay_s", "magnitude"),),
    "sensor_saturation": (("level_pa", "level", "magnitude"),),
}
TOL_MAGNITUDE = 0.10
TOL_AMPLITUDE = 0.20

LOADS: tuple[str, ...] = ("fixed_piston", "free_piston", "conrod_fixed")


@dataclass(frozen=True)
class Case:
    """One record of the matrix: load, effects (rig names), experiment profile."""

    load: str
    effects: tuple[str, ...] = ()
    profile: str = "multisine"
    seconds: float = 6.0

    @property
    def label(self) -> str:
        eff = " + ".join(self.effects) if self.effects else "null"
        prof = "" if self.profile == "multisine" else f" ({self.profile})"
        return f"{self.load}: {eff}{prof}"


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
    return cases


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

    def as_dict(self) -> dict[str, Any]:
        return {"case": self.case.label, "load": self.case.load,
                "effects": list(self.case.effects), "profile": self.case.profile,
                "seed": self.seed, "right": self.right, "why": self.why,
                "found": self.found, "unexplained": self.unexplained,
                "refused": self.refused,
                "magnitudes": [{"what": w, "truth": t, "found": f}
                               for w, t, f in self.magnitudes],
                "param_error": self.param_error,
                "wall_s": self.wall_s, "cpu_s": self.cpu_s}


def judge(case: Case, truth: dict[str, dict[str, float]], found: dict[str, dict[str, float]],
          unexplained: bool) -> tuple[bool, str, list[tuple[str, float, float | None]]]:
    """Right or wrong, why, and the magnitudes compared (module docstring)."""
    from hil.identify.rig import LIBRARY_EFFECTS

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
        for tkey, fkey, kind in MAGNITUDE_KEYS.get(eff, ()):
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
    if outside and not unexplained:
        problems.append("verdict explained with " + ", ".join(outside) + " in the record")
    if not outside and unexplained:
        problems.append("verdict unexplained")
    return not problems, "; ".join(problems) or "ok", mags


def run_case(case: Case, seed: int) -> CaseResult:
    """Generate the record, identify it, judge it (runs in a worker process)."""
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    t0, c0 = time.perf_counter(), time.process_time()
    rig = generate_rig(case.load, list(case.effects), seconds=case.seconds, seed=seed,
                       profile=case.profile)
    return identify_and_judge(case, seed, rig, load_config("hydra_default"), t0, c0)


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
    right, why, mags = judge(case, truth, found, rep.unexplained)
    true_p = rig.truth["parameters"]
    param_error = {sym: rep.final[sym].value / true_p[name] - 1.0
                   for name, (sym, _, _) in BASELINE_LABELS.items()
                   if sym in rep.final and name in true_p and name not in rep.held}
    return CaseResult(case, seed, right, why, list(case.effects), labels, rep.unexplained,
                      magnitudes=mags, wall_s=time.perf_counter() - t0,
                      cpu_s=time.process_time() - c0, param_error=param_error)


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
    """The matrix as a markdown table, then a one-line tally."""
    lines = ["| case | seed | truth / found (magnitudes) | effects found | verdict | right |",
             "|---|---|---|---|---|---|"]
    for r in results:
        mags = "; ".join(_fmt_mag(*m) for m in r.magnitudes) or "-"
        found = ", ".join(r.found) or "none"
        verdict = ("refused" if r.refused else
                   "unexplained" if r.unexplained else "explained")
        ok = "yes" if r.right else f"**no**: {r.why}"
        lines.append(f"| {r.case.label} | {r.seed} | {mags} | {found} | {verdict} | {ok} |")
    n_right = sum(r.right for r in results)
    cpu = sum(r.cpu_s for r in results)
    lines.append("")
    lines.append(f"{n_right} of {len(results)} right; {cpu:.0f} s CPU in all.")
    return "\n".join(lines)
