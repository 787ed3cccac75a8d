"""Command-line verbs of the identification tool (wired into ``hil.cli`` by the project).

* ``eha-hil identify DATA.csv [-c PRESET|FILE] [--set K=V] [--report DIR] [--json]
  [--max-effects N] [--load CASE] [--sample-rate HZ]``
* ``eha-hil bench identify [--seconds 16] [--effect NAME] [--realism rig|plant]`` — wall and
  CPU time of a whole run on a synthetic 5 kHz record against the 20 s CPU budget;
* ``eha-hil identify-synth OUT.csv --load fixed_piston --effect pump_coulomb_friction`` — an
  example dataset from the project's plant, to try the tool on; ``--realism rig`` takes it
  from the independent rig simulator (:mod:`hil.identify.rig`) instead.

A user mistake (malformed CSV, unknown preset, unusable report directory) is one line
``eha-hil identify: ...`` (or ``identify-synth``) on stderr, exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from hil.cli.args import (
    add_config_options,
    float_range,
    input_file,
    int_range,
    output_dir,
    output_file,
)
from hil.cli.contract import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    Context,
    Outcome,
    UsageError,
    standalone,
)

#: Rows identified by default: ~40 s at 5 kHz, about 1.5 GB at the peak (docs/identify.md).
DEFAULT_MAX_ROWS = 200_000
#: Peak memory of an identification: a base plus this per row used (measured with
#: /usr/bin/time -v, docs/identify.md), for the size check before any reading.
BASE_BYTES = 400e6
BYTES_PER_ROW = 7_000
#: CPU seconds (all threads) a 16 s, 5 kHz record may take to identify on the 2-core machine.
CPU_BUDGET_S = 20.0


def configure_identify(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil identify``."""
    parser.add_argument("data", metavar="DATA.csv", type=input_file("measured-data CSV"),
                        help="measured-data CSV (docs/identify.md)")
    # -c/--set: the constants and start values, as on every other verb
    add_config_options(parser, mcu=False)
    parser.add_argument("--preset", dest="config", help=argparse.SUPPRESS)  # old name of -c
    parser.add_argument("--report", metavar="DIR", type=output_dir,
                        help="write tables and plots into DIR")
    parser.add_argument("--json", action="store_true", help="print the JSON summary")
    parser.add_argument("--max-effects", type=int_range(0, 20), default=6,
                        help="stop after adding this many effects, 0..20")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.add_argument("--max-rows", type=int_range(1000, 5_000_000), default=DEFAULT_MAX_ROWS,
                        metavar="N", help="use at most the first N data rows (a longer file "
                        "is not read past them; the size check says how many it holds and "
                        "the memory it would need), 1000..5000000")
    parser.add_argument("--load", choices=("fixed_piston", "free_piston", "conrod_fixed"),
                        default=None, help="load case, for a file without a '# load:' line "
                        "(a header line that says otherwise is an error)")
    parser.add_argument("--sample-rate", type=float_range(0.0, 1e9, open_lo=True, unit="Hz"),
                        default=None, metavar="HZ",
                        help="sample rate, Hz, for a file without a '# sample_rate_hz:' line "
                        "(a header line that says otherwise is an error); without either it "
                        "is inferred from the median time step")
    parser.add_argument("--intersample", choices=("zoh", "foh", "bl"), default=None,
                        help="how the logged current behaved between samples: zoh (held), "
                        "foh (linear), bl (band-limited); default: the '# intersample:' "
                        "header line, else estimated from the data (the report says why)")


@standalone("eha-hil identify")
def run_identify(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Run ``eha-hil identify``: exit 0 on success, 2 on a user error (one line on stderr)."""
    from hil.identify.checks import RefusedData
    from hil.identify.csvdata import CsvError, read_measured
    from plant.config import load_config

    cfg = load_config(args.config, args.set or ())  # a ConfigError names the preset and key

    def progress(msg: str) -> None:
        if not args.quiet:
            # One write per line: print() writes the text and its newline separately, and an
            # interrupt between the two glued its own line onto this one.
            sys.stderr.write(f"identify: {msg}\n")
            sys.stderr.flush()

    too_big = _size_check(args.data, args.max_rows, progress)
    if too_big:
        raise UsageError(too_big)
    try:
        data = read_measured(args.data, load=args.load, sample_rate_hz=args.sample_rate,
                             max_rows=args.max_rows, progress=progress)
    except CsvError as exc:
        raise UsageError(str(exc)) from None
    from hil.identify import report
    from hil.identify.pipeline import identify

    for note in data.notes:  # what reading did to the file (also in the report's notes)
        progress(f"{args.data}: {note}")

    try:
        rep = identify(data, cfg, max_effects=args.max_effects, progress=progress,
                       intersample=args.intersample)
    except RefusedData as exc:
        # a record that cannot be identified: say why, never a verdict
        return Outcome(None, {"file": str(args.data), "refused": str(exc)}, EXIT_USAGE,
                       error=f"{args.data}: refused: {exc}")
    except ValueError as exc:
        raise UsageError(f"{args.data}: {exc}") from None
    rep.notes[:0] = [n for n in data.notes if n not in rep.notes]
    files = ()
    if args.report:
        # the report goes to a temporary directory whose files are moved in when all are
        # written, after the result is printed: a failed report leaves nothing
        # half-written, an interruption while it is written keeps the result
        from hil.cli.outputs import Later

        files = (Later("report", args.report, lambda tmp: report.write_report(rep, tmp),
                       directory=True),)
    code, error = EXIT_OK, None
    if data.cut:  # a cut file: identified up to its last whole line, and said so (exit 1)
        from hil.cli import cutfiles

        code, error = EXIT_FAILED, cutfiles.message(args.data, data.cut,
                                                    float(data.t[-1] - data.t[0]))
    return Outcome(report.text(rep), json.loads(report.to_json(rep)), code, error=error,
                   files=files)


def _size_check(path: str, max_rows: int, progress) -> str:  # noqa: ANN001
    """Before reading: how many rows the file holds (by its size), how many will be used,
    the memory that takes; the refusal (one line) if it cannot fit in this machine."""
    import os

    from hil.identify.csvdata import estimate_rows

    rows = estimate_rows(path)
    used = min(rows, max_rows)
    need = BASE_BYTES + BYTES_PER_ROW * used
    try:
        avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Linux
        avail = None
    size = os.path.getsize(path)
    if avail is not None and need > avail:
        return (f"{path}: identifying {used:,} rows needs about {need / 1e9:.1f} GB, "
                f"{avail / 1e9:.1f} GB is free: give a smaller --max-rows")
    if rows > max_rows or size > 50e6:
        progress(f"{path}: {size / 1e6:,.0f} MB, about {rows:,} rows by its size; using "
                 f"{'the first ' if rows > max_rows else ''}{used:,} (--max-rows {max_rows:,})"
                 f", about {need / 1e9:.1f} GB")
    return ""


def configure_synth(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil identify-synth``."""
    # the names only, from light modules: the generators themselves load the simulation
    from hil.identify.record_options import INTERSAMPLE, SYNTH_PROFILES, TEMPERATURE_SHAPES
    from hil.identify.rig_effects import RIG_EFFECTS
    from hil.identify.synth_effects import ALL_SYNTH_EFFECTS

    parser.add_argument("out", metavar="OUT.csv", type=output_file((".csv",), text=True),
                        help="CSV file to write (an existing file only if it is text)")
    parser.add_argument("--load", default="fixed_piston",
                        choices=("fixed_piston", "free_piston", "conrod_fixed"),
                        help="load case of the record")
    parser.add_argument("--realism", default="plant", choices=("plant", "rig"),
                        help="plant: the project's plant (default); rig: the independent "
                        "rig simulator (drawn parameters, continuous current, sensor chains)")
    # validated in run_synth: the two generators know different effects
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="effect to switch on (repeatable); none gives the null dataset. "
                        f"plant: {', '.join(ALL_SYNTH_EFFECTS)}; rig: {', '.join(RIG_EFFECTS)}")
    parser.add_argument("--magnitude", action="append", default=[], metavar="EFFECT.KEY=V",
                        help="override a magnitude, e.g. pump_coulomb_friction.force_n=60")
    parser.add_argument("--seconds", type=float_range(1.0, 600.0, open_lo=True, unit="s"),
                        default=8.0, help="record length, s, in (1, 600]")
    parser.add_argument("--seed", type=int_range(0, 2**32 - 1), default=1,
                        help="noise seed: the same seed gives the same record")
    parser.add_argument("--preset", dest="config", help=argparse.SUPPRESS)  # old name of -c
    parser.add_argument("-c", "--config", dest="config", default=None,
                        metavar="PRESET|FILE",
                        help="actuator preset or TOML file the record is made from (default: "
                        "hydra_linear for the plant, hydra_default for the rig's nominal "
                        "parameters)")
    parser.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                        help="override one configuration value (repeatable)")
    parser.add_argument("--profile", default="multisine", choices=SYNTH_PROFILES,
                        help="excitation: multisine (default); resonance (piston free: "
                        "strong 0.7-2 kHz band over a 0.5 Hz position sweep, makes k_s(x) "
                        "identifiable); slide (piston free: triangle sweep at constant "
                        "speed, quick reversals, avoids the seal's stick-slip)")
    parser.add_argument("--temperature", default=None, choices=tuple(TEMPERATURE_SHAPES),
                        help="rig: oil temperature shape (default constant, or ramp_level "
                        "when an effect needs a moving temperature)")
    parser.add_argument("--current-noise-lsb", type=float_range(0.0, 100.0, unit="LSB"),
                        default=None, metavar="X",
                        help="rig: noise of the logged current, LSB of the 12-bit +-40 A "
                        "converter (default 1)")
    parser.add_argument("--intersample", default=None, choices=INTERSAMPLE,
                        help="rig: continuous current (default) or the logged value held")
    parser.add_argument("--header-intersample", action="store_true",
                        help="rig: write '# intersample: ...' into the CSV header")
    parser.add_argument("--spread", type=float_range(0.0, 0.5), default=None,
                        help="rig: relative spread of the drawn parameters, 0..0.5 "
                        "(default 0.15)")


def _synth_effects(args: argparse.Namespace, known: Sequence[str],
                   magnitudes: Mapping[str, Mapping[str, float]], realism: str
                   ) -> dict[str, dict[str, float]] | str:
    """``--effect`` and ``--magnitude`` as {effect: {key: value}}, or the one-line mistake.
    A pulsation's further orders (``amplitude_2``, ...) are keys of the rig only."""
    for e in args.effect:
        if e not in known:
            return (f"--effect {e}: unknown effect for --realism {realism} "
                    f"(known: {', '.join(known)})")
    effects: dict[str, dict[str, float]] = {e: {} for e in args.effect}
    for item in args.magnitude:
        try:
            key, value = item.split("=", 1)
            name, field = key.split(".", 1)
            val = float(value)
        except ValueError:
            return f"--magnitude {item}: expected EFFECT.KEY=NUMBER"
        if name not in effects:
            return f"--magnitude {item}: effect {name} not switched on"
        extra_order = (realism == "rig" and name == "pump_pulsation"
                       and field.rsplit("_", 1)[-1].isdigit())
        if field not in magnitudes[name] and not extra_order:
            return (f"--magnitude {item}: unknown key "
                    f"(known: {', '.join(magnitudes[name]) or 'none'})")
        effects[name][field] = val
    return effects


@standalone("eha-hil identify-synth")
def run_synth(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Write an example dataset; prints what was put into it."""
    from hil.identify.csvdata import write_measured
    from hil.identify.synth import ALL_SYNTH_EFFECTS, DEFAULT_MAGNITUDES, generate
    from plant.config import ConfigError, load_config

    if args.realism == "rig":
        return _run_rig_synth(args)
    rig_only = [f"--{k.replace('_', '-')}" for k in ("temperature", "current_noise_lsb",
                                                      "intersample", "spread")
                if vars(args)[k] is not None]
    if args.header_intersample:
        rig_only.append("--header-intersample")
    if rig_only:
        raise UsageError(f"{rig_only[0]}: only with --realism rig")
    effects = _synth_effects(args, ALL_SYNTH_EFFECTS, DEFAULT_MAGNITUDES, "plant")
    if isinstance(effects, str):
        raise UsageError(effects)
    out = Path(args.out)
    try:
        cfg = load_config(args.config or "hydra_linear", args.set or ())
        res = generate(args.load, effects, seconds=args.seconds, seed=args.seed,
                       preset=cfg, profile=args.profile)
    except (ConfigError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    truth = "; ".join(f"{k} {v}" for k, v in res.truth.items()) or "none"
    from hil.cli import outputs

    wrote = outputs.write("record", out, lambda tmp: write_measured(tmp, res.data,
                                                                     {"effects": truth}))
    return Outcome(f"{'wrote' if wrote else 'made (NOT written)'} {out}: {args.load}, "
                   f"{res.data.n} samples at {res.data.sample_rate_hz:g} Hz, effects: {truth}")


def _run_rig_synth(args: argparse.Namespace) -> Outcome:
    """``identify-synth --realism rig``: a record from the independent rig simulator."""
    from hil.identify.csvdata import write_measured
    from hil.identify.rig import RIG_DEFAULT_MAGNITUDES, RIG_EFFECTS, generate_rig
    from plant.config import ConfigError, load_config

    effects = _synth_effects(args, RIG_EFFECTS, RIG_DEFAULT_MAGNITUDES, "rig")
    if isinstance(effects, str):
        raise UsageError(effects)
    if args.seconds <= 1.0:
        raise UsageError(f"--seconds {args.seconds}: need more than 1 s")
    out = Path(args.out)
    if not out.parent.exists() and str(out.parent):
        raise UsageError(f"{args.out}: directory {out.parent} does not exist")
    try:
        res = generate_rig(
            args.load, effects, seconds=args.seconds, seed=args.seed, profile=args.profile,
            temperature=args.temperature,
            current_noise_lsb=1.0 if args.current_noise_lsb is None else args.current_noise_lsb,
            intersample=args.intersample or "continuous",
            spread=0.15 if args.spread is None else args.spread,
            preset=load_config(args.config or "hydra_default", args.set or ()),
            header_intersample=args.header_intersample)
    except (ConfigError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    # the truth is printed, not written: the file holds only what a rig's log would
    from hil.cli import outputs

    wrote = outputs.write("record", out, lambda tmp: write_measured(tmp, res.data,
                                                                     dict(res.data.header)))
    par = res.truth["parameters"]
    lines = [f"{'wrote' if wrote else 'made (NOT written)'} {out}: rig, {args.load}, "
             f"{res.data.n} samples at {res.data.sample_rate_hz:g} Hz, intersample "
             f"{res.config['intersample']}, temperature {res.config['temperature']}",
             "  true parameters: " + ", ".join(f"{k} {v:.6g}" for k, v in par.items())]
    for name, vals in res.truth["effects"].items():
        lines.append(f"  {name}: " + ", ".join(f"{k} {v:.6g}" for k, v in vals.items()))
    return Outcome("\n".join(lines))


#: The records ``eha-hil bench identify`` times by default: 16 s at 5 kHz from the rig, two
#: effects each, one per load (load, effects, profile).
BENCH_RECORDS = (
    ("fixed_piston", ("pump_pulsation", "pump_coulomb_friction"), "multisine"),
    ("conrod_fixed", ("pump_coulomb_friction", "pump_pulsation"), "multisine"),
    ("free_piston", ("pump_coulomb_friction", "seal_friction"), "multisine"),
)


def configure_bench(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil bench identify``."""
    parser.add_argument("--seconds", type=float_range(1.0, 600.0, open_lo=True, unit="s"),
                        default=16.0, help="record length, s, in (1, 600]")
    parser.add_argument("--load", default=None,
                        choices=("fixed_piston", "free_piston", "conrod_fixed"),
                        help="time one record of this load case (default: the three "
                        "two-effect records, one per load)")
    add_config_options(parser, mcu=False)  # the fitted model's configuration, as for identify
    parser.add_argument("--effect", action="append", default=None,
                        help="effects in the one record timed (default with --load: "
                             "pump_pulsation and pump_coulomb_friction)")
    parser.add_argument("--profile", default="multisine",
                        choices=("multisine", "slide", "resonance"),
                        help="excitation of the one record timed (slide, resonance: "
                        "free_piston and the rig only)")
    parser.add_argument("--realism", default="rig", choices=("rig", "plant"),
                        help="where the record comes from: rig (the independent rig "
                        "simulator, default) or plant (the project's plant)")
    parser.add_argument("--threads", type=int_range(1, 8), default=None,
                        help="simulation threads of the fits (default: one per core; the "
                        "results do not depend on it, the CPU time may)")
    parser.add_argument("--json", action="store_true", help="print JSON")


@standalone("eha-hil bench identify")
def run_bench(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Time whole identifications (CSV read to report) of synthetic 5 kHz records: wall and
    CPU seconds (all threads of this process) of each, against the CPU budget. Without
    ``--load`` or ``--effect``: the :data:`BENCH_RECORDS`."""
    from plant.config import load_config

    if args.load is None and args.effect is None and args.profile == "multisine":
        records = list(BENCH_RECORDS)
    else:
        records = [(args.load or "fixed_piston",
                    tuple(args.effect or ("pump_pulsation", "pump_coulomb_friction")),
                    args.profile)]
    if args.realism == "rig":
        from hil.identify.rig import RIG_EFFECTS as known
    else:
        from hil.identify.synth import ALL_SYNTH_EFFECTS as known
    for load, effects, profile in records:
        for e in effects:
            if e not in known:
                raise UsageError(f"--effect {e}: unknown for --realism "
                                 f"{args.realism} (known: {', '.join(known)})")
        if profile != "multisine" and load != "free_piston":
            raise UsageError(f"--profile {profile}: needs --load free_piston")
    cfg = load_config(args.config, args.set or ())
    if args.threads is not None:
        from hil.identify.model import set_threads
        set_threads(args.threads)
    rows = []
    for load, effects, profile in records:
        ctx.say(f"bench identify: {load}, {' + '.join(effects)} ({profile})")
        rows.append(_bench_record(args, cfg, load, list(effects), profile))
    lines = [f"bench identify: {args.seconds:g} s at {rows[0]['sample_rate_hz']:g} Hz per "
             f"record ({args.realism}); CPU (all threads) beside wall, budget "
             f"{CPU_BUDGET_S:.0f} s CPU"]
    for r in rows:
        lines.append(f"  {r['load']}, {' + '.join(r['effects_in_data'])} ({r['profile']}): "
                     f"CPU {r['cpu_s']:.1f} s = {r['cpu_ratio_to_budget']:.2f} x the budget; "
                     f"wall {r['wall_s']:.1f} s (CPU/wall {r['cpu_per_wall']:.2f}); added: "
                     f"{', '.join(r['effects_added']) or 'none'}; "
                     f"{'unexplained' if r['unexplained'] else 'explained'}")
    out = {"seconds": args.seconds, "realism": args.realism, "cpu_budget_s": CPU_BUDGET_S,
           "threads": args.threads, "records": rows, "cpu_s_max": max(r["cpu_s"] for r in rows)}
    return Outcome("\n".join(lines), out)


def _bench_record(args: argparse.Namespace, cfg, load: str, effects: list[str],  # noqa: ANN001
                  profile: str) -> dict:
    """One timed identification (the kernels compiled and the CSV reader imported outside
    the timing)."""
    from hil.identify.csvdata import read_measured, write_measured
    from hil.identify.pipeline import identify

    if args.realism == "rig":
        from functools import partial

        from hil.identify.rig import generate_rig
        make = partial(generate_rig, profile=profile)
    else:
        from hil.identify.synth import generate as make
    warm = make(load, effects, seconds=2.0, seed=7)
    res = make(load, effects, seconds=args.seconds, seed=3)
    with tempfile.TemporaryDirectory() as tmp:
        # the warm-up takes the timed path (CSV read, identify) on a 2 s record: the
        # kernels compile and the CSV reader's imports load outside the timing (pandas
        # alone is 0.8-1.5 s of CPU, once per process, that fell on the first record)
        warm_path = Path(tmp) / "warm.csv"
        write_measured(warm_path, warm.data)
        identify(read_measured(warm_path), cfg, max_effects=1)
        path = Path(tmp) / "bench.csv"
        write_measured(path, res.data)
        t0, c0 = time.perf_counter(), time.process_time()
        data = read_measured(path)
        rep = identify(data, cfg)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"samples": data.n, "sample_rate_hz": data.sample_rate_hz, "load": load,
            "profile": profile, "effects_in_data": effects,
            "effects_added": [e.label for e in rep.effects_added],
            "unexplained": rep.unexplained,
            "wall_s": wall, "cpu_s": cpu, "cpu_ratio_to_budget": cpu / CPU_BUDGET_S,
            "cpu_per_wall": cpu / wall}


def add_parsers(sub, bsub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``identify``, ``identify-synth``, ``identify-check`` and ``bench identify``."""
    from hil.cli import identify_check as check_cli
    from hil.cli.contract import command

    p = sub.add_parser("identify", help="fit the model to measured data, find the residual's "
                       "missing effect, report the error before and after")
    configure_identify(p)
    command(p, run_identify)
    p = sub.add_parser("identify-synth", help="write a synthetic measured-data CSV from the "
                       "plant, with an effect the fitted model does not declare")
    configure_synth(p)
    command(p, run_synth)
    p = sub.add_parser("identify-check", help="judge the identification on the independent "
                       "rig: every effect, load and seed, as a table")
    check_cli.configure_check(p)
    command(p, check_cli.run_check)
    p = bsub.add_parser("identify", help="wall and CPU time to identify a 16 s, 5 kHz "
                        "dataset (budget 20 s CPU)")
    configure_bench(p)
    command(p, run_bench)


__all__ = ["add_parsers", "configure_bench", "configure_identify", "configure_synth",
           "run_bench", "run_identify", "run_synth"]
