"""The root of the ``eha-hil`` command line: the registry of every command, and the one
place that turns a command's outcome into output, an exit code and, on a mistake, a stop
or a failing stdout, one line on stderr (the contract: :mod:`hil.cli.contract`).

Every verb prints a readable table, takes ``--json`` for machines and (where a picture
helps) ``--plot FILE.png``; long runs report progress on stderr. A user mistake (bad
configuration, bad argument, unwritable plot file) prints one line ``eha-hil VERB:
WHAT`` and exits with code 2; numbers and paths are checked by the argument types of
:mod:`hil.cli.args`, configuration values by :mod:`plant.config`. A missed requirement
exits with code 1. Ctrl-C, SIGTERM and SIGHUP print one line saying what was interrupted
and what was written (:mod:`hil.cli.progress`), exit 130, 143, 129.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hil.cli import interrupts
from hil.cli.args import Parser
from hil.cli.contract import execute
from plant.config import preset_names


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("eha-hil")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="eha-hil",
        description="Emulator and HIL test harness for the Hydra electro-hydrostatic actuator.",
        epilog="Presets: " + ", ".join(preset_names()) + ". Example: eha-hil plant bode "
        "--set effects.pulsation.enabled=false --plot bode.png. Exit codes: 0 ok, 1 a "
        "requirement missed (or stdout could not be written), 2 a mistake on the command "
        "line or in a configuration, 130 interrupted (Ctrl-C), 143 SIGTERM, 129 SIGHUP.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    from hil.cli import bench, bus, config, ethercat, identify, plant, run, serve, sweep, verify
    from hil.cli.log import configure_log

    plant.add_parsers(sub)
    bench_parser = sub.add_parser("bench", help="benchmarks (real-time factor, throughput)")
    bsub = bench_parser.add_subparsers(dest="bench_command", metavar="TARGET", required=True)
    bench.add_parsers(bsub)
    bus.add_parsers(sub, bsub)
    serve.add_parser(sub)
    ethercat.add_parsers(sub, bsub)
    configure_log(sub.add_parser("log", help="frame logs (MCAP, captures, CAN logs): info, "
                                 "export to CSV or Parquet"))
    identify.add_parsers(sub, bsub)
    sweep.add_parsers(sub, bsub)
    run.add_parser(sub)
    verify.add_parsers(sub)
    config.add_parser(sub)
    return parser


def _verb(args: argparse.Namespace) -> str:
    """``eha-hil bus run``, ``eha-hil run thesis``: the command as the user typed it."""
    if getattr(args, "verb", None):  # declared by the command (hil.cli.contract.command)
        return args.verb
    words = ["eha-hil", args.command]
    action = getattr(args, f"{args.command}_command", None)
    if action:
        words.append(action)
    if args.command == "run":
        words.append(args.scenario)
    return " ".join(words)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command: parse, run, print its outcome; every error as one line."""
    interrupts.install()  # Ctrl-C, SIGTERM, SIGHUP raised, never lost in numba's loading
    try:
        args = build_parser().parse_args(argv)
    except KeyboardInterrupt as exc:
        return execute(_raise(exc), argparse.Namespace(), "eha-hil")
    return execute(args.run, args, _verb(args))


def _raise(exc: BaseException):  # noqa: ANN202
    """A command that only raises ``exc`` (a signal while the registry was built)."""

    def run(args: argparse.Namespace, ctx: object) -> None:
        raise exc

    return run


if __name__ == "__main__":
    sys.exit(main())
