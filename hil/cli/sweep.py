"""``eha-hil sweep SCENARIO``: grids and Monte Carlo over any scenario of ``eha-hil run``.

Exit codes: 0 every point ran (requirements missed at some points are the study's result,
not a failure; ``--min-yield`` makes them one); 1 a point failed with an error (recorded in
the table) or a yield is below ``--min-yield``; 2 a mistake in the command line or the
configuration; 130 interrupted (the journal keeps every finished point: ``--resume``).
"""

from __future__ import annotations

import argparse
import errno
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hil.cli import progress as cli_progress
from hil.cli.args import common, float_range, int_range, output_dir, output_file
from hil.cli.contract import EXIT_FAILED, EXIT_OK, Context, Outcome, UsageError, command
from hil.sweep import requirements, space

OUT_FILE = output_file((".parquet", ".csv"))


def _duration(seconds: float | None) -> str:
    if seconds is None:
        return "?"
    s = int(round(seconds))
    return f"{s // 3600}h{s // 60 % 60:02d}m" if s >= 3600 else (
        f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s")


#: errno values of a write that the disk refused (full, quota, read-only, I/O error).
_DISK_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO, errno.EFBIG)


def _usage(message: str) -> Exception:
    return UsageError(message)


def _resolve_scenario(args: argparse.Namespace) -> str:
    from hil import scenarios
    from hil.cli.run import THESIS_PRESET

    if args.scenario == "thesis":
        raise _usage("one scenario at a time (f3 .. f8, not 'thesis')")
    try:
        scenarios.check_name(args.scenario)
    except KeyError as exc:
        raise _usage(str(exc.args[0])) from None
    if args.config is None and args.scenario in scenarios.ON_THESIS_PRESET:
        args.config = THESIS_PRESET  # as `eha-hil run` does
    return args.scenario


def _reporter(scenario: str, enabled: bool) -> Callable[[dict | None, Any], None]:
    def report(record: dict | None, prog: Any) -> None:
        cli_progress.at(f"at {prog.done}/{prog.total} points (finished points are in the "
                        "journal; rerun with --resume)")
        failed = f", {prog.failed} failed" if prog.failed else ""
        resumed = f", {prog.resumed} from the journal" if prog.resumed else ""
        unit = (f"points{resumed}{failed}, {_duration(prog.elapsed_s)} elapsed, "
                f"ETA {_duration(prog.eta_s)}").ljust(70)
        cli_progress.reporter(f"sweep {scenario}", enabled, unit, note=False)(
            prog.done, prog.total)

    return report


def cmd_sweep(args: argparse.Namespace, ctx: Context) -> Outcome:
    scenario = _resolve_scenario(args)
    if args.resume and not args.out:
        raise _usage("--resume: needs --out FILE (the journal lives beside it)")
    if args.dask and args.dask != "local" and args.workers:
        raise _usage(f"--workers: the cluster at {args.dask} has its own workers")
    if not (args.param or args.tolerance or args.seeds):
        raise _usage("nothing to vary; give --param, --tolerance or --seeds")
    # after the checks above: the sweep's modules load pandas (~1 s of CPU)
    from hil import scenarios
    from hil.scenarios.knobs import split_sets
    from hil.sweep import plots, requirements, summary, table
    from hil.sweep.backends import BackendError, make_backend
    from hil.sweep.engine import run_sweep
    from hil.sweep.journal import Journal, JournalError, journal_path, readable
    from plant.config import load_config

    scen = scenarios.get(scenario)
    config_sets, fixed_knobs = split_sets(args.set or ())
    base = load_config(args.config, config_sets)
    from plant.model import check_config

    check_config(base)  # a base the points cannot simulate (work unbounded): one line now
    scen.settings(fixed_knobs, "--set")  # one line naming the setting, before anything runs
    plan = space.build_plan(base, args.param or [], args.tolerance or [], args.samples or 0,
                            args.seeds or (), args.distribution, args.draw_seed,
                            knobs=scen.knobs, scenario=scenario,
                            settings=scen.settings if scen.knobs else None,
                            fixed=fixed_knobs)
    show = not ctx.json
    journal = None
    if args.out:
        jpath = journal_path(args.out)
        journal = Journal(jpath)
        cli_progress.output("journal", jpath, check=readable)
        if jpath.exists() and not args.resume and show:
            print(f"eha-hil sweep: starting over: {jpath} is replaced (--resume continues "
                  "the sweep it holds)", file=sys.stderr)
    try:
        backend = make_backend(args.workers, args.dask,
                               warn=lambda m: print(f"eha-hil sweep: {m}", file=sys.stderr))
    except BackendError as exc:
        raise _usage(str(exc)) from None
    if show:
        print(f"sweep {scenario}: {len(plan.points)} points ({plan.kind}) on {backend.name}",
              file=sys.stderr, flush=True)
    try:
        outcome = run_sweep(scenario, base, plan, backend, journal, args.resume,
                            on_point=_reporter(scenario, show))
    except JournalError as exc:
        raise _usage(str(exc)) from None
    except OSError as exc:
        if journal is None or exc.errno not in _DISK_ERRORS:
            raise
        # the journal could not be written (a full disk): the sweep stops, the line says
        # which file and where (hil.cli.outputs.finish), exit 1
        from hil.cli import outputs

        outputs.failed("journal", journal.path, f"{exc.strerror} (stopped "
                       f"{cli_progress.position() or 'at the start'})")
        raise outputs.StreamFailed from None
    finally:
        backend.close()
    try:
        records = requirements.apply(outcome.records, args.require or [])
    except ValueError as exc:
        kept = ("; the journal keeps every point: rerun with --resume and the metric's "
                "name" if args.out else "")
        raise _usage(f"{exc}{kept}") from None
    df = table.frame(plan, records)
    title = (f"sweep {scenario}: {len(plan.points)} points ({plan.kind}), "
             f"{base.sources[-1]}")
    summ = summary.summarise(df, records, [g.key for g in plan.grid])
    lines = [summary.text(summ, title)]
    errors = df[df["error"] != ""]
    for _, row in errors.head(5).iterrows():
        lines.append(f"point {row['point']} failed: {row['error']}")
    if len(errors) > 5:
        lines.append(f"... and {len(errors) - 5} more (column 'error' of the table)")
    from hil.cli import outputs

    table_ok = bool(args.out) and outputs.write("table", args.out,
                                                lambda tmp: table.write(df, tmp))
    if table_ok:
        lines.append(f"table written to {args.out} ({len(df)} rows; journal "
                     f"{journal_path(args.out).name})")
    plot_paths: list[Path] = []
    if args.plot_dir:
        out_dir = Path(args.plot_dir)
        made: list[Path] = []
        if outputs.write_dir("plots", out_dir, lambda tmp: made.extend(
                plots.plot_sweep(df, plan, records, tmp, title))):
            plot_paths = [out_dir / p.name for p in made]
            lines.append(f"plots written to {out_dir}/ ("
                         f"{', '.join(p.name for p in plot_paths)})")
    lines.append(f"{outcome.computed} points computed, {outcome.resumed} from the journal, "
                 f"{_duration(outcome.wall_s)} on {outcome.backend}")
    low = []
    if args.min_yield is not None:
        low = [m.name for m in summ.metrics
               if m.yield_ is not None and m.yield_ < args.min_yield]
        if low:
            lines.append(f"yield below {args.min_yield:g}: {', '.join(low)}")
    data = {"scenario": scenario, "config": base.sources, "kind": plan.kind,
            "parameters": plan.parameters, "computed": outcome.computed,
            "resumed": outcome.resumed, "backend": outcome.backend,
            "out": args.out if table_ok else None, "plots": [str(p) for p in plot_paths],
            "summary": summ.as_dict(), "below_min_yield": low,
            "errors": [{"point": int(r["point"]), "error": r["error"]}
                       for _, r in errors.iterrows()]}
    return Outcome("\n".join(lines), data, EXIT_FAILED if (summ.errors or low) else EXIT_OK)


def cmd_bench_sweep(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.sweep import bench_sweep
    from hil.output.tables import table
    from plant.config import load_config

    args.scenario = args.scenario_name
    scenario = _resolve_scenario(args)
    base = load_config(args.config, args.set or ())
    from plant.model import check_config

    check_config(base)
    r = bench_sweep(scenario, base, args.points, args.workers, ctx.say)
    rows = [(x.backend, x.wall_s, x.cpu_s, x.cpu_points_s) for x in r.runs]
    text = table(["backend", "wall [s]", "CPU [s]", "CPU in points [s]"], rows, fmt=".3g",
                 title=f"sweep {scenario}, {args.points} points (sim.seed 0..{args.points - 1}"
                 f"), {base.sources[-1]}")
    text += (f"\nspeed-up of the pool (wall, serial / pool): {r.speedup_wall:.2f}x; CPU, "
             f"pool / serial: {r.cpu_ratio:.2f}x; tables identical: "
             f"{'yes' if r.identical else 'NO'}\nload average (1, 5, 15 min) before "
             f"{', '.join(f'{x:.2f}' for x in r.load_before)}, after "
             f"{', '.join(f'{x:.2f}' for x in r.load_after)}; {r.cores} cores")
    data = {"scenario": scenario, "points": args.points, "config": base.sources,
            "runs": [vars(x) for x in r.runs], "speedup_wall": r.speedup_wall,
            "cpu_ratio": r.cpu_ratio, "identical": r.identical,
            "load_before": r.load_before, "load_after": r.load_after, "cores": r.cores}
    return Outcome(text, data, EXIT_OK if r.identical else EXIT_FAILED)


def add_parsers(sub: Any, bsub: Any) -> None:
    """Register ``sweep`` and ``bench sweep``."""
    # the catalogue, not the scenarios themselves: they load the simulation
    from hil.scenarios.catalog import CATALOG

    p = sub.add_parser(
        "sweep", parents=[common(plot=False)],
        help="parameter grid or Monte Carlo over a scenario: table, summary with yield, "
        "plots; local process pool or a Dask cluster",
        epilog="Example: eha-hil sweep f7 --tolerance effects.seal_friction.coulomb_n,"
        "effects.seal_friction.static_n=30% --tolerance hydraulics.jp_kg=10% --samples 50 "
        "--out f7.parquet --plot-dir f7-plots. Scenarios: " + ", ".join(sorted(CATALOG))
        + ". Exit codes: 0 every point ran; 1 a point failed with an error or a yield is "
        "below --min-yield; 2 a mistake; 130 interrupted (resume with --resume).")
    p.add_argument("scenario", metavar="SCENARIO", help="a scenario of eha-hil run; the "
                   "thesis experiments f3..f8 default to -c hydra_thesis")
    p.add_argument("--param", action="append", type=space.parse_param,
                   metavar="KEY=START:STOP:COUNT|KEY=V1,V2,...",
                   help="a grid parameter (repeatable: the full factorial, first outermost)")
    p.add_argument("--tolerance", action="append", type=space.parse_tolerance,
                   metavar="KEY[,KEY...]=P%|KEY=WIDTH",
                   help="a Monte Carlo tolerance, relative (P%% of the key's value) or "
                   "absolute in the key's unit; keys given together move by one draw "
                   "(repeatable)")
    p.add_argument("--distribution", choices=space.DISTRIBUTIONS, default="uniform",
                   help="tolerance draws: uniform over the band, or normal with sigma = a "
                   "third of it, cut at its edges")
    p.add_argument("--samples", type=int_range(1, 100_000), default=None,
                   help="Monte Carlo samples (actuators built to tolerance), 1..100000")
    p.add_argument("--draw-seed", type=int_range(0, 2**32 - 1), default=0,
                   help="base seed of the Monte Carlo draws: sample j's values depend on it "
                   "and j only")
    p.add_argument("--seeds", type=space.parse_seeds, metavar="A..B|A,B,...",
                   help="noise seeds (sim.seed) to run every point with")
    p.add_argument("--out", type=OUT_FILE, metavar="FILE.parquet|FILE.csv",
                   help="the results table, one row per point; its journal "
                   "FILE.points.jsonl beside it")
    p.add_argument("--resume", action="store_true",
                   help="continue the sweep whose journal is beside --out: only the points "
                   "it lacks are computed")
    p.add_argument("--plot-dir", type=output_dir, metavar="DIR",
                   help="one figure per metric, METRIC.png")
    p.add_argument("--workers", type=int_range(1, 1024), default=None,
                   help="worker processes (default: one per core; 1 runs in this process); "
                   "with --dask local, the LocalCluster's workers")
    p.add_argument("--dask", metavar="tcp://HOST:PORT|local",
                   help="run the points on a Dask cluster (its scheduler's address), or on "
                   "a LocalCluster")
    p.add_argument("--require", action="append", type=requirements.parse_requirement,
                   metavar="'METRIC>=BOUND'",
                   help="judge METRIC (its name in the table, without the unit) by this bound "
                   "instead of the scenario's requirement; also <=, >, < (repeatable: all "
                   "must hold); with --resume, a finished sweep is judged again at no cost")
    p.add_argument("--min-yield", type=float_range(0.0, 1.0), default=None,
                   help="exit 1 when a judged metric's yield is below this fraction")
    command(p, cmd_sweep)

    b = bsub.add_parser("sweep", parents=[common(plot=False)],
                        help="speed-up of the local process pool over a serial sweep, wall "
                        "and CPU time")
    b.add_argument("--scenario", dest="scenario_name", default="f5",
                   help="the scenario swept over sim.seed")
    b.add_argument("--points", type=int_range(2, 1000), default=8, help="points, 2..1000")
    b.add_argument("--workers", type=int_range(2, 1024), default=None,
                   help="pool workers (default: one per core)")
    command(b, cmd_bench_sweep)
