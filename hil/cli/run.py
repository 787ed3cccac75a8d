"""``eha-hil run SCENARIO`` (one scenario, or ``thesis``: every thesis experiment)."""

from __future__ import annotations

import argparse
import sys

from hil.cli import outputs
from hil.cli import progress as cli_progress
from hil.cli.args import common, output_dir, output_file, plot_dir
from hil.cli.contract import EXIT_FAILED, EXIT_OK, Context, Outcome, UsageError, command
from hil.cli.outputs import Later
from hil.cli.verify import add_rtl_option, rtl_sets, rtl_verdict
from hil.output.tables import table

#: Preset the thesis scenarios run on unless -c is given (calibrated effect magnitudes).
THESIS_PRESET = "hydra_thesis"


# --- run -------------------------------------------------------------------------------------
def cmd_run_thesis(args: argparse.Namespace, ctx: Context) -> Outcome:
    import time

    from hil import scenarios

    names = [n for n in scenarios.THESIS if n in scenarios.names()]
    if args.plot:
        raise UsageError("--plot: 'thesis' writes one plot per scenario; use --plot-dir DIR")
    out_dir = plot_dir(args.plot_dir or "thesis-plots")
    cfg = ctx.config()
    rows = []
    results = []
    notes = []
    profiles: list[dict] = []
    plotted: list[str] = []
    _image_profile(cfg, "")  # this command's steps only
    for name in names:
        t0 = time.perf_counter()
        ctx.say(f"{name} ...")
        done = ", ".join(r.name for r, _ in results)
        cli_progress.at(f"in {name}" + (f" ({done} done)" if done else ""))
        res = scenarios.get(name).run(cfg, None)
        wall = time.perf_counter() - t0
        results.append((res, wall))
        prof = _image_profile(cfg, name.upper())
        if prof:
            profiles.append(prof)
        if res.plot and outputs.write("plot", out_dir / f"{name}.png",
                                      lambda tmp, res=res: res.plot(res, tmp)):
            plotted.append(f"{name}.png")
        for m in res.metrics:
            diff = "" if m.thesis is None else f"{(m.value - m.thesis) / m.thesis * 100:+.0f} %"
            mark = "" if m.ok is None else ("ok" if m.ok else "MISSED")
            rows.append((f"{name.upper()} {m.name}", "" if m.thesis is None else m.thesis,
                         m.value, m.unit, diff, m.requirement, mark))
        notes += [f"{name.upper()}: {n}" for n in res.notes]
    text = table(["figure", "thesis", "ours", "unit", "diff", "required", ""], rows,
                 fmt=".3g", title=f"thesis experiments on the full stack ({cfg.sources[-1]})")
    if notes:
        text += "\n" + "\n".join(f"note: {n}" for n in notes)
    if plotted:
        text += f"\nplots written to {out_dir}/ ({', '.join(plotted)})"
    text += _profile_text(profiles)
    ok = all(r.ok for r, _ in results)
    data = {"config": cfg.sources, "ok": ok, "scenarios": [
        {"scenario": r.name, "title": r.title, "wall_s": w, "ok": r.ok, "notes": r.notes,
         "metrics": [{"name": m.name, "value": m.value, "unit": m.unit, "thesis": m.thesis,
                      "requirement": m.requirement, "ok": m.ok} for m in r.metrics]}
        for r, w in results]}
    if profiles:
        data["mcu_image_profile"] = profiles
    return rtl_verdict(Outcome(text, data, EXIT_OK if ok else EXIT_FAILED), ctx)


def _image_profile(cfg, label: str) -> dict | None:  # noqa: ANN001 - Config
    """The execution-time summary of the image steps since the last call (None: the MCU
    is not an image)."""
    if cfg.get("mcu.impl") != "image":
        return None
    from hil.sim.image import profile

    return profile.take(label)


def _profile_text(profiles: list[dict]) -> str:
    if not profiles:
        return ""
    from hil.sim.image import profile

    return "\nMCU image execution time (estimated, docs/mcu.md):\n" + "\n".join(
        "  " + profile.line(p) for p in profiles)


def _run_live(res, address: str) -> str:  # noqa: ANN001 - ScenarioResult
    """``run --foxglove``: serve the scenario's series until a client takes them (after the
    result is printed: giving up with Ctrl-C keeps the table of the finished run)."""
    from hil.framelog.live import FoxgloveLive, LiveError, parse_address
    from hil.framelog.series_export import publish_live

    try:
        live = FoxgloveLive(*parse_address(address))
    except (ValueError, LiveError) as exc:
        raise UsageError(str(exc)) from None
    with live:
        print(f"foxglove: {res.name}'s series on {live.url}: open it in Foxglove Studio "
              "(Open connection > Foxglove WebSocket) and subscribe (e.g. a Plot panel); "
              "Ctrl-C to give up", file=sys.stderr, flush=True)
        publish_live(res, live)
    return f"series sent to Foxglove at {live.url}"


def cmd_run(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil import scenarios

    if args.config is None and (args.scenario == "thesis"
                                or args.scenario in scenarios.ON_THESIS_PRESET):
        args.config = THESIS_PRESET
    if args.scenario == "thesis":
        for opt in ("series", "foxglove"):
            if vars(args)[opt] is not None:
                raise UsageError(f"--{opt}: 'thesis' runs several scenarios; give one "
                                 "(f1-measured, f3 ... f9-roll)")
        return cmd_run_thesis(args, ctx)
    try:
        scenario = scenarios.get(args.scenario)
    except KeyError as exc:
        raise UsageError(str(exc.args[0])) from None
    if args.plot_dir is not None:
        if args.plot:
            raise UsageError("--plot and --plot-dir: give one of them")
        args.plot = str(plot_dir(args.plot_dir) / f"{scenario.name}.png")
    from hil.scenarios.knobs import split_sets

    if args.foxglove is not None:  # a bad address: before the run
        from hil.framelog.live import parse_address

        try:
            parse_address(args.foxglove)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    from plant.config import load_config  # (numpy with it: not for the parser's sake)

    config_sets, knob_values = split_sets(args.set or ())
    cfg = load_config(args.config, [*config_sets, *rtl_sets(args)])
    _image_profile(cfg, "")  # this command's steps only
    res = scenario.call(cfg, ctx.progress(scenario.name), knob_values)
    prof = _image_profile(cfg, res.name)
    rows = [(m.name, m.value, m.unit, m.requirement,
             "" if m.ok is None else ("ok" if m.ok else "MISSED")) for m in res.metrics]
    text = table(["metric", "value", "unit", "requirement", ""], rows, fmt=".4g",
                 title=f"{res.name}: {res.title} ({cfg.sources[-1]})")
    if res.notes:
        text += "\n" + "\n".join(f"note: {n}" for n in res.notes)
    text += _profile_text([prof] if prof else [])
    # files (and the wait for a Foxglove client) after the result is printed: an
    # interruption or a failed write keeps the table of a finished run (hil.cli.outputs)
    files: list[Later] = []
    if args.plot and res.plot:
        files.append(Later("plot", args.plot, lambda tmp: res.plot(res, tmp)))
    if args.series:
        from hil.framelog.series_export import tables, write_series

        if not tables(res.series, res.name)[0]:
            raise UsageError(f"{res.name}: the scenario has no time series to write")
        n_rows: list[int] = []
        files.append(Later("series", args.series,
                           lambda tmp: n_rows.append(write_series(res, tmp)),
                           lambda: f" ({n_rows[0]} rows)"))
    if args.foxglove is not None:
        said: list[str] = []
        files.append(Later("waiting for a Foxglove client", "",
                           lambda _: said.append(_run_live(res, args.foxglove)),
                           lambda: said[0] if said else "", action=True))
    data = {"scenario": res.name, "title": res.title, "config": cfg.sources, "ok": res.ok,
            "metrics": [{"name": m.name, "value": m.value, "unit": m.unit,
                         "requirement": m.requirement, "ok": m.ok} for m in res.metrics],
            "notes": res.notes}
    if prof:
        data["mcu_image_profile"] = prof
    return rtl_verdict(Outcome(text, data, EXIT_OK if res.ok else EXIT_FAILED,
                               files=tuple(files)), ctx)


def add_parser(sub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``run``."""
    # the catalogue, not the scenarios themselves: they load the simulation
    from hil.scenarios.catalog import CATALOG

    scen = sorted(CATALOG)
    p = sub.add_parser("run", parents=[common()],
                       help="run a scenario on the simulated stack (thesis, "
                       + ", ".join(scen) + "; exit 1 if a requirement is missed)",
                       epilog="Scenarios: thesis: the thesis experiments (F1m, F3-F9); "
                       + "; ".join(f"{n}: {CATALOG[n].summary}" for n in scen)
                       + ". Scenario settings (--set scenario.NAME=VALUE; sweepable): "
                       + "; ".join(f"{n}: " + ", ".join(k.name for k in CATALOG[n].knobs)
                                   for n in scen if CATALOG[n].knobs)
                       + " (docs/scenarios.md).")
    p.add_argument("scenario", metavar="SCENARIO",
                   help="scenario name, or 'thesis' for the thesis experiments (F1m, F3-F9); "
                   "these default to -c hydra_thesis")
    p.add_argument("--plot-dir", default=None, type=output_dir,
                   help="directory for one plot per scenario, NAME.png (with 'thesis' "
                   "default thesis-plots)")
    p.add_argument("--foxglove", nargs="?", const="", metavar="HOST:PORT",
                   help="after the run, serve its series to Foxglove Studio (WebSocket; "
                   "default 127.0.0.1:8765, loopback) until a client has taken them")
    p.add_argument("--series", metavar="FILE", type=output_file((".csv", ".parquet", ".mcap")),
                   help="write the time series behind the metrics to FILE (.csv, .parquet "
                   "or .mcap; README, Scenarios)")
    add_rtl_option(p)
    command(p, cmd_run)
