"""Where the CPU of one identification goes: its stages, with the simulations each ran.

``eha-hil bench identify`` gives the whole CPU of a record's identification; this splits it
by the loop's own progress messages (each stage runs from its message to the next one: the
intersample choice, the baseline fit, each round's score tests, each refit, the joint
search, the held parameters freed again, the final judgement) and counts the model's
simulations in each (:meth:`~hil.identify.model.FastModel._simulate_states`, all threads),
so a stage's CPU reads as simulations times their cost plus the Python around them.

Run: ``python -m hil.bench.identify_stages --load free_piston --profile slide --effect
pump_coulomb_friction --effect seal_friction`` (the record ``bench identify`` times: 16 s at
5 kHz from the rig, seed 3; ``--seed``, ``--seconds``, ``--threads`` as there). The kernels
are compiled and the CSV reader imported outside the timing. The figures grow with the
machine's load: quote them with ``uptime``.

``--fits`` also lists every output-error fit inside the stages (its CPU, simulations, free
parameters, sub-steps, Jacobian limit, whether it converged, and the loop's calls that made
it): where a stage's CPU goes, fit by fit. ``--table`` runs the 16 s table instead: the
twelve multi-effect records (``TABLE``) at ``--seed``, one line each.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
import traceback
from functools import partial
from pathlib import Path

# the 16 s table: every multi-effect record of the rig, (load, profile, effects)
TABLE: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("fixed_piston", "multisine", ("pump_coulomb_friction", "pump_pulsation")),
    ("fixed_piston", "multisine", ("strain_thermal_drift", "viscosity_temperature")),
    ("fixed_piston", "multisine", ("pump_coulomb_friction", "pump_pulsation",
                                   "viscosity_temperature")),
    ("free_piston", "multisine", ("pump_coulomb_friction", "pump_pulsation")),
    ("free_piston", "multisine", ("pump_coulomb_friction", "pump_pulsation",
                                  "viscosity_temperature")),
    ("free_piston", "slide", ("seal_friction", "pump_pulsation")),
    ("free_piston", "slide", ("pump_coulomb_friction", "seal_friction")),
    ("free_piston", "multisine", ("pump_coulomb_friction", "seal_friction")),
    ("conrod_fixed", "multisine", ("pump_coulomb_friction", "pump_pulsation")),
    ("conrod_fixed", "multisine", ("strain_thermal_drift", "viscosity_temperature")),
    ("conrod_fixed", "multisine", ("pump_coulomb_friction", "seal_friction")),
    ("conrod_fixed", "multisine", ("pump_coulomb_friction", "seal_friction", "pump_pulsation")),
)


def _caller_chain(depth: int = 5) -> str:
    """The identification loop's calls that led to a fit, outermost first."""
    names = [f.name for f in traceback.extract_stack()[:-2]
             if "hil/identify" in f.filename.replace("\\", "/")]
    return "/".join(names[-depth:])


def stages(load: str, effects: list[str], profile: str = "multisine", seed: int = 3,
           seconds: float = 16.0, threads: int | None = None, fits: bool = False) -> dict:
    """One timed identification of a rig record, split by its progress messages:
    ``{"stages": [{"stage", "cpu_s", "wall_s", "sims"}], "cpu_s", "wall_s", "sims",
    "effects_added", "unexplained"}``; with ``fits``, also ``"fits"``: one row per
    output-error fit (``cpu_s``, ``sims``, ``n_free``, ``n_sub``, ``max_nfev``,
    ``converged``, ``calls``) in the order they ended."""
    from hil.identify import fit as fitting
    from hil.identify import model
    from hil.identify.csvdata import read_measured, write_measured
    from hil.identify.pipeline import identify
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    cfg = load_config(None, ())
    if threads is not None:
        model.set_threads(threads)
    make = partial(generate_rig, profile=profile)
    res = make(load, effects, seconds=seconds, seed=seed)
    count = [0]
    lock = threading.Lock()
    simulate = model.FastModel._simulate_states

    def counted(self, theta, n_stop):  # noqa: ANN001, ANN202 - the wrapped method's own
        with lock:
            count[0] += 1
        return simulate(self, theta, n_stop)

    fit_rows: list[dict] = []
    fit_method = fitting.OutputErrorFit.fit

    def logged(self, theta0, free, sigma=None, passes=2, max_nfev=40):  # noqa: ANN001, ANN202
        c0, n0 = time.process_time(), count[0]
        r = fit_method(self, theta0, free, sigma=sigma, passes=passes, max_nfev=max_nfev)
        fit_rows.append({"cpu_s": time.process_time() - c0, "sims": count[0] - n0,
                         "n_free": len(free), "n_sub": int(self.model.n_sub),
                         "max_nfev": max_nfev, "converged": bool(r.converged),
                         "calls": _caller_chain()})
        return r

    marks: list[tuple[float, float, int, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        # the timed path on a 2 s record first: the kernels compile and the CSV reader's
        # imports load outside the timing, as in ``eha-hil bench identify``
        warm = Path(tmp) / "warm.csv"
        write_measured(warm, make(load, effects, seconds=2.0, seed=7).data)
        identify(read_measured(warm), cfg, max_effects=1)
        path = Path(tmp) / "record.csv"
        write_measured(path, res.data)
        model.FastModel._simulate_states = counted
        if fits:
            fitting.OutputErrorFit.fit = logged
        try:
            c0, w0 = time.process_time(), time.perf_counter()

            def say(msg: str) -> None:
                marks.append((time.process_time() - c0, time.perf_counter() - w0, count[0],
                              msg))

            say("reading the record")
            rep = identify(read_measured(path), cfg, progress=say)
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        finally:
            model.FastModel._simulate_states = simulate
            fitting.OutputErrorFit.fit = fit_method
    rows = []
    ends = [*marks[1:], (cpu, wall, count[0], "")]
    for (c, w, n, msg), (c1, w1, n1, _) in zip(marks, ends, strict=True):
        rows.append({"stage": msg, "cpu_s": c1 - c, "wall_s": w1 - w, "sims": n1 - n})
    return {"load": load, "profile": profile, "effects_in_data": effects, "seed": seed,
            "seconds": seconds, "stages": rows, "cpu_s": cpu, "wall_s": wall,
            "sims": count[0], "effects_added": [e.label for e in rep.effects_added],
            "unexplained": rep.unexplained, **({"fits": fit_rows} if fits else {})}


def _one_line(out: dict) -> str:
    return (f"{out['load']}, {' + '.join(out['effects_in_data'])} ({out['profile']}), "
            f"seed {out['seed']}, {out['seconds']:g} s: CPU {out['cpu_s']:.2f} s, "
            f"wall {out['wall_s']:.2f} s, {out['sims']} simulations; added: "
            f"{', '.join(out['effects_added']) or 'none'}; "
            f"{'unexplained' if out['unexplained'] else 'explained'}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.bench.identify_stages",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--load", default="free_piston",
                        choices=("fixed_piston", "free_piston", "conrod_fixed"))
    parser.add_argument("--profile", default="multisine",
                        choices=("multisine", "slide", "resonance"))
    from hil.identify.rig import RIG_EFFECTS

    parser.add_argument("--effect", action="append", default=None, choices=RIG_EFFECTS)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=16.0)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.add_argument("--fits", action="store_true",
                        help="also list every output-error fit (CPU, simulations, free "
                             "parameters, sub-steps, Jacobian limit, converged, calls)")
    parser.add_argument("--table", action="store_true",
                        help="run the 16 s table's twelve multi-effect records at --seed, "
                             "one line each (--load, --profile, --effect ignored)")
    args = parser.parse_args(argv)
    if not 0.0 < args.seconds <= 600.0:  # NaN fails too
        parser.error(f"argument --seconds: {args.seconds:g}: need a number in (0, 600] s")
    if args.threads is not None and args.threads < 1:
        parser.error(f"argument --threads: {args.threads}: need an integer of at least 1")
    if args.table:
        for load, profile, effects in TABLE:
            out = stages(load, list(effects), profile, args.seed, args.seconds, args.threads)
            load_avg = Path("/proc/loadavg").read_text().split()[0] \
                if Path("/proc/loadavg").exists() else "?"
            print(json.dumps(out) if args.json else f"{_one_line(out)} (load {load_avg})",
                  flush=True)
        return 0
    effects = args.effect or ["pump_coulomb_friction", "seal_friction"]
    out = stages(args.load, effects, args.profile, args.seed, args.seconds, args.threads,
                 fits=args.fits)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(_one_line(out))
    print("   CPU s  sims  stage (from its progress message to the next)")
    for r in out["stages"]:
        print(f"  {r['cpu_s']:6.2f} {r['sims']:5d}  {r['stage'][:110]}")
    if args.fits:
        print("   CPU s  sims free n_sub nfev conv  fit (the loop's calls that made it)")
        for f in out["fits"]:
            print(f"  {f['cpu_s']:6.2f} {f['sims']:5d} {f['n_free']:4d} {f['n_sub']:5d} "
                  f"{f['max_nfev']:4d} {'yes' if f['converged'] else 'no ':>4}  {f['calls']}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        print("identify_stages: interrupted; nothing was written", file=sys.stderr)
        sys.exit(130)
