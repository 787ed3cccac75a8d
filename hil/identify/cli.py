"""Command-line verbs of the identification tool (wired into ``hil.cli`` by the project).

* ``eha-hil identify DATA.csv [--preset NAME] [--report DIR] [--json] [--max-effects N]``
* ``eha-hil bench identify [--seconds 16] [--effect NAME]`` — wall time of a whole run on a
  synthetic 5 kHz record against the 60 s budget;
* ``eha-hil identify-synth OUT.csv --load fixed_piston --effect pump_coulomb_friction`` — an
  example dataset from the project's plant, to try the tool on.

A user mistake (malformed CSV, unknown preset, unusable report directory) prints one line
starting ``eha-hil identify: `` (or ``identify-synth``) on stderr and returns 2.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

EXIT_OK = 0
EXIT_USAGE = 2
BUDGET_S = 60.0


def _err(verb: str, msg: str) -> int:
    print(f"eha-hil {verb}: {msg}", file=sys.stderr)
    return EXIT_USAGE


def configure_identify(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil identify``."""
    parser.add_argument("data", metavar="DATA.csv", help="measured-data CSV (docs/identify.md)")
    parser.add_argument("--preset", default="hydra_default",
                        help="actuator preset or TOML file for the constants and start values")
    parser.add_argument("--report", metavar="DIR", help="write tables and plots into DIR")
    parser.add_argument("--json", action="store_true", help="print the JSON summary")
    parser.add_argument("--max-effects", type=int, default=6,
                        help="stop after adding this many effects (default 6)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run_identify(args: argparse.Namespace) -> int:
    """Run ``eha-hil identify``; 0 on success, 2 on a user error (one line on stderr)."""
    from hil.identify.csvdata import CsvError, read_measured
    from plant.config import ConfigError, load_config

    if args.max_effects < 0:
        return _err("identify", f"--max-effects {args.max_effects}: must be >= 0")
    if args.report:
        rdir = Path(args.report)
        if rdir.exists() and not rdir.is_dir():
            return _err("identify", f"--report {args.report}: exists and is not a directory")
        if not rdir.parent.exists() and str(rdir.parent):
            return _err("identify", f"--report {args.report}: parent directory does not exist")
    try:
        cfg = load_config(args.preset)
    except ConfigError as exc:
        return _err("identify", f"--preset {args.preset}: {exc}")
    try:
        data = read_measured(args.data)
    except CsvError as exc:
        return _err("identify", str(exc))
    from hil.identify import report
    from hil.identify.pipeline import identify

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"identify: {msg}", file=sys.stderr, flush=True)

    try:
        rep = identify(data, cfg, max_effects=args.max_effects, progress=progress)
    except ValueError as exc:
        return _err("identify", f"{args.data}: {exc}")
    if args.report:
        try:
            report.write_report(rep, args.report)
        except OSError as exc:
            return _err("identify", f"--report {args.report}: {exc}")
    print(report.to_json(rep) if args.json else report.text(rep))
    return EXIT_OK


def configure_synth(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil identify-synth``."""
    from hil.identify.synth import ALL_SYNTH_EFFECTS, PROFILES

    parser.add_argument("out", metavar="OUT.csv", help="CSV file to write")
    parser.add_argument("--load", default="fixed_piston",
                        choices=("fixed_piston", "free_piston", "conrod_fixed"))
    parser.add_argument("--effect", action="append", default=[], choices=ALL_SYNTH_EFFECTS,
                        help="effect to switch on (repeatable); none gives the null dataset")
    parser.add_argument("--magnitude", action="append", default=[], metavar="EFFECT.KEY=V",
                        help="override a magnitude, e.g. pump_coulomb_friction.force_n=60")
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--preset", default="hydra_linear", help="plant preset (base)")
    parser.add_argument("--profile", default="multisine", choices=PROFILES,
                        help="excitation: multisine (default); resonance (piston free: "
                        "strong 0.7-2 kHz band over a 0.5 Hz position sweep, makes k_s(x) "
                        "identifiable); slide (piston free: triangle sweep at constant "
                        "speed, quick reversals, avoids the seal's stick-slip)")


def run_synth(args: argparse.Namespace) -> int:
    """Write an example dataset; prints what was put into it."""
    from hil.identify.csvdata import write_measured
    from hil.identify.synth import DEFAULT_MAGNITUDES, generate
    from plant.config import ConfigError

    effects: dict[str, dict[str, float]] = {e: {} for e in args.effect}
    for item in args.magnitude:
        try:
            key, value = item.split("=", 1)
            name, field = key.split(".", 1)
            val = float(value)
        except ValueError:
            return _err("identify-synth", f"--magnitude {item}: expected EFFECT.KEY=NUMBER")
        if name not in effects:
            return _err("identify-synth", f"--magnitude {item}: effect {name} not switched on")
        if field not in DEFAULT_MAGNITUDES[name]:
            known = ", ".join(DEFAULT_MAGNITUDES[name]) or "none"
            return _err("identify-synth", f"--magnitude {item}: unknown key (known: {known})")
        effects[name][field] = val
    if args.seconds <= 1.0:
        return _err("identify-synth", f"--seconds {args.seconds}: need more than 1 s")
    out = Path(args.out)
    if not out.parent.exists() and str(out.parent):
        return _err("identify-synth", f"{args.out}: directory {out.parent} does not exist")
    try:
        res = generate(args.load, effects, seconds=args.seconds, seed=args.seed,
                       preset=args.preset, profile=args.profile)
    except (ConfigError, ValueError) as exc:
        return _err("identify-synth", str(exc))
    truth = "; ".join(f"{k} {v}" for k, v in res.truth.items()) or "none"
    write_measured(out, res.data, {"effects": truth})
    print(f"wrote {out}: {args.load}, {res.data.n} samples at {res.data.sample_rate_hz:g} Hz, "
          f"effects: {truth}")
    return EXIT_OK


def configure_bench(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil bench identify``."""
    parser.add_argument("--seconds", type=float, default=16.0, help="record length (s)")
    parser.add_argument("--load", default="fixed_piston",
                        choices=("fixed_piston", "free_piston", "conrod_fixed"))
    parser.add_argument("--effect", action="append", default=None,
                        help="effects in the record (default: pump_pulsation and "
                             "pump_coulomb_friction)")
    parser.add_argument("--json", action="store_true")


def run_bench(args: argparse.Namespace) -> int:
    """Time a whole identification (CSV read to report) of a synthetic 5 kHz record."""
    import json

    from hil.identify.csvdata import read_measured, write_measured
    from hil.identify.pipeline import identify
    from hil.identify.synth import generate
    from plant.config import load_config

    effects = args.effect or ["pump_pulsation", "pump_coulomb_friction"]
    cfg = load_config("hydra_default")
    warm = generate(args.load, effects, seconds=2.0, seed=7)
    identify(warm.data, cfg, max_effects=1)  # compile the kernels outside the timing
    res = generate(args.load, effects, seconds=args.seconds, seed=3)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.csv"
        write_measured(path, res.data)
        t0 = time.perf_counter()
        data = read_measured(path)
        rep = identify(data, cfg)
        wall = time.perf_counter() - t0
    out = {"seconds": args.seconds, "samples": data.n, "sample_rate_hz": data.sample_rate_hz,
           "load": args.load, "effects_in_data": effects,
           "effects_added": [e.label for e in rep.effects_added],
           "wall_s": wall, "budget_s": BUDGET_S, "ratio_to_budget": wall / BUDGET_S}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"bench identify: {args.seconds:g} s at {data.sample_rate_hz:g} Hz "
              f"({data.n} samples, {args.load}, effects {', '.join(effects)})")
        print(f"  wall time {wall:.1f} s = {wall / BUDGET_S:.2f} x the {BUDGET_S:.0f} s budget; "
              f"added: {', '.join(out['effects_added']) or 'none'}")
    return EXIT_OK


__all__ = ["configure_bench", "configure_identify", "configure_synth", "run_bench",
           "run_identify", "run_synth"]
