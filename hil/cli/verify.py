"""The ``eha-hil verify`` verbs: the firmware models against independent builds."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hil.cli.args import common, float_range, int_range
from hil.cli.contract import EXIT_FAILED, EXIT_OK, Context, Outcome, UsageError, command
from hil.output.tables import table

#: A mismatch, or a build that failed: the check did not pass.
EXIT_MISMATCH = EXIT_FAILED


def _rtl_dir(text: str) -> str:
    """A directory holding Verilog (``*.v``)."""
    p = Path(text)
    if not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: not a directory")
    if not any(p.glob("*.v")):
        raise argparse.ArgumentTypeError(f"{text}: no Verilog (*.v) files in it")
    return text


_rtl_dir.kind = "dir"  # type: ignore[attr-defined]


def add_rtl_option(parser: argparse.ArgumentParser) -> None:
    """``--rtl DIR`` on a verb that simulates the board: the current loop's RTL from DIR
    runs in place of the board's own loop (``fpga.impl = "rtl"``, ``fpga.rtl_dir``)."""
    parser.add_argument("--rtl", metavar="DIR", default=None, type=_rtl_dir,
                        help="run the board's current loop as this directory's Verilog "
                        "under Verilator (same as --set fpga.impl=rtl --set "
                        "fpga.rtl_dir=DIR; docs/fpga.md)")


def rtl_sets(args: argparse.Namespace) -> list[str]:
    """The ``--set`` strings ``--rtl DIR`` stands for (none without it, or on a verb that
    has no ``--rtl``)."""
    rtl = vars(args).get("rtl")
    return [] if rtl is None else ["fpga.impl=rtl", f"fpga.rtl_dir={rtl}"]


def rtl_verdict(outcome: Outcome, ctx: Context) -> Outcome:
    """After a run: each RTL in the loop that differed from the board model, as one line on
    stderr naming the first tick and signal; exit 1 then, else the outcome as it is."""
    from hil.sim.verilator import take_divergences

    found = take_divergences()
    for d in found:
        print(f"{ctx.verb}: {d.line()}", file=sys.stderr)
    if found:
        outcome.code = EXIT_MISMATCH
    return outcome
COUNT = int_range(0, 100_000_000)
SEED = int_range(0, 2**32 - 1)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    verify = sub.add_parser("verify", help="check the firmware models bit for bit against "
                            "independent builds (C on the host or a Cortex-M4 under QEMU; "
                            "RTL under Icarus/cocotb); exit 1 on any mismatch")
    vsub = verify.add_subparsers(dest="verify_command", metavar="CHECK", required=True)
    p = vsub.add_parser("mcu", parents=[common(plot=False)],
                        help="the MCU law: Python model against the C build")
    p.add_argument("--against", required=True, choices=("host-c", "qemu", "image"),
                   help="host-c: the C as a host shared library; qemu: the Cortex-M4F image "
                   "on QEMU's netduinoplus2; image: the law's firmware image on the "
                   "harness's emulator (Unicorn), with its execution time per set")
    p.add_argument("--steps", type=COUNT, default=10_000,
                   help="random input steps, split over the six controller variants "
                   "(default 10000)")
    p.add_argument("--stack-seconds", type=float_range(0.0, 60.0, unit="s"), default=0.4,
                   help="seconds of whole-stack run with faults recorded per variant "
                   "(default 0.4 s = 2000 steps; 0: none)")
    p.add_argument("--seed", type=SEED, default=1, help="random steps' seed (default 1)")
    p.add_argument("--contract", choices=("off", "fast"), default="off",
                   help="the build's -ffp-contract (default off, as the firmware is built; "
                   "fast shows what fused multiply-adds change)")
    command(p, cmd_verify_mcu)

    p = vsub.add_parser("current-loop", parents=[common(plot=False, mcu=False)],
                        help="the driver board's current loop: Python board model against "
                        "the RTL under Verilator or Icarus Verilog and cocotb")
    p.add_argument("--against", required=True, choices=("rtl",),
                   help="rtl: the Verilog of firmware_model/fpga/rtl (or --rtl DIR)")
    p.add_argument("--vectors", type=COUNT, default=10_000,
                   help="vectors in all: the golden and edge sets, then random (default "
                   "10000)")
    p.add_argument("--rtl", metavar="DIR", default=None, type=_rtl_dir,
                   help="a directory of Verilog with the same ports (default: the project's)")
    p.add_argument("--simulator", choices=("verilator", "icarus"), default="verilator",
                   help="verilator: the RTL compiled into the library the stack runs "
                   "(--set fpga.impl=rtl), all vectors in one call; icarus: Icarus Verilog "
                   "under cocotb, one vector per cocotb cycle (default verilator)")
    p.add_argument("--seed", type=SEED, default=1, help="random vectors' seed (default 1)")
    command(p, cmd_verify_current_loop)


def cmd_verify_mcu(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.sim import mcu_builds
    from hil.verify.mcu.verify import verify_mcu

    if args.steps == 0 and args.stack_seconds == 0:
        raise UsageError("--steps 0 and --stack-seconds 0 leave nothing to compare")
    target = args.against
    missing = mcu_builds.missing_tools(target)
    if missing:
        raise UsageError(f"--against {args.against}: {', '.join(missing)} not "
                          "installed (make system-deps installs them)")
    if args.against == "image" and args.contract != "off":
        raise UsageError("--against image: the image is built with -ffp-contract=off only")
    try:
        rep = verify_mcu(args.against, args.steps, args.seed, args.stack_seconds,
                         args.contract, args.config, args.set or ())
    except mcu_builds.BuildError as exc:
        return Outcome(code=EXIT_MISMATCH, error=str(exc))
    out = _report(rep, f"MCU law: Python model vs {args.against} "
                  f"(-ffp-contract={args.contract}, {rep.build})")
    if rep.profiles:
        out.text += "\n" + _profile_table(rep.profiles)
    if any(p.get("period_share_max", 0) > 1 for p in rep.profiles):  # overran its period
        out.code = EXIT_MISMATCH
    return out


def _profile_table(profiles: list[dict]) -> str:
    """The image's execution time per set, as processor-in-the-loop tools print it."""
    rows = [(p["label"], p["steps"], p["instructions_mean"], p["instructions_max"],
             p["cycles_mean"], p["cycles_max"], p["us_max"], 100 * p["period_share_max"],
             p["margin_us"]) for p in profiles if p.get("steps")]
    return table(["set", "steps", "instr mean", "instr max", "cycles mean", "cycles max",
                  "max [us]", "max [% of 200 us]", "margin [us]"], rows, fmt=".4g",
                 title="execution time on a Cortex-M4F at 168 MHz (estimated cycles, "
                 "docs/mcu.md)")


def _report(rep, title: str) -> Outcome:  # noqa: ANN001 - a verify report
    rows = [(c.source, c.vectors, c.mismatches) for c in rep.sets]
    lines = [table(["set", "vectors", "mismatches"], rows, title=title),
             f"{rep.vectors} vectors compared, {rep.mismatches} mismatches "
             f"({rep.seconds:.1f} s)"]
    first = rep.first
    if first is not None:
        m = first.first
        lines.append(f"first mismatch: {first.source}, step {m.step}, field {m.field}: "
                     f"model {m.model}, build {m.build}")
    return Outcome("\n".join(lines), rep.as_dict(),
                   EXIT_MISMATCH if rep.mismatches else EXIT_OK)


def cmd_verify_current_loop(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.sim import verilator as rtl_verilator
    from hil.verify.current_loop import rtl as rtl_run
    from hil.verify.current_loop.verify import verify_current_loop

    tools = rtl_verilator if args.simulator == "verilator" else rtl_run
    missing = tools.missing_tools()
    if missing:
        raise UsageError(f"--simulator {args.simulator}: {', '.join(missing)} not installed "
                         "(make system-deps; pip install 'eha-hil[test]')")
    from plant.config import load_config

    rtl_dir = Path(args.rtl) if args.rtl else rtl_run.RTL_DIR
    cfg = load_config(args.config, args.set or ())  # its --rtl is the RTL under test
    try:
        if args.simulator == "verilator":
            rtl_verilator.top_file(rtl_dir)
        rtl_run.rtl_sources(rtl_dir)
        rep = verify_current_loop(cfg, args.vectors, args.seed, rtl_dir, args.simulator)
    except rtl_run.RtlError as exc:  # the RTL is not a loop that builds: the input's fault
        raise UsageError(str(exc)) from None
    sim = "Verilator" if args.simulator == "verilator" else "Icarus Verilog + cocotb"
    return _report(rep, f"current loop: Python board model vs RTL ({rtl_dir}, {sim})")
