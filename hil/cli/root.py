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
from collections.abc import Callable, Sequence

from hil.cli import interrupts
from hil.cli.args import Parser
from hil.cli.contract import execute


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("eha-hil")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown (not installed)"


class _Version(argparse._VersionAction):
    """``--version``, argparse's, with the installed version looked up only when asked for:
    reading the package metadata costs every start of the console script ~25 ms."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        self.version = f"{parser.prog} {_version()}"
        super().__call__(parser, namespace, values, option_string)


def _preset_names() -> list[str]:
    """The shipped presets, as :func:`plant.config.preset_names` lists them, found without
    importing :mod:`plant.config` (it loads numpy: the root's help would pay for it at every
    start). ``find_spec`` of the top package does not run its ``__init__`` either."""
    from importlib.util import find_spec
    from pathlib import Path

    spec = find_spec("plant")
    folders = [] if spec is None else list(spec.submodule_search_locations or ())
    return sorted(p.stem for f in folders for p in Path(f, "presets").glob("*.toml"))


def _plant(sub, bsub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    from hil.cli import plant

    plant.add_parsers(sub)


def _bus(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import bus

    bus.add_parsers(sub, bsub)


def _serve(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import serve

    serve.add_parser(sub)


def _ethercat(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import ethercat

    ethercat.add_parsers(sub, bsub)


def _log(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli.log import configure_log

    configure_log(sub.add_parser("log", help="frame logs (MCAP, captures, CAN logs): info, "
                                 "export to CSV or Parquet"))


def _identify(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import identify

    identify.add_parsers(sub, bsub)


def _sweep(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import sweep

    sweep.add_parsers(sub, bsub)


def _run(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import run

    run.add_parser(sub)


def _verify(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import verify

    verify.add_parsers(sub)


def _config(sub, bsub) -> None:  # noqa: ANN001
    from hil.cli import config

    config.add_parser(sub)


#: The groups of commands in the order they are listed, each with the top-level words it
#: registers (``bench`` is the root's own: every group may add a target to it).
GROUPS: tuple[tuple[tuple[str, ...], Callable[..., None]], ...] = (
    (("main", "plant"), _plant),
    (("bus", "replay"), _bus),
    (("serve",), _serve),
    (("esi",), _ethercat),
    (("log",), _log),
    (("identify", "identify-synth", "identify-check"), _identify),
    (("sweep",), _sweep),
    (("run",), _run),
    (("verify",), _verify),
    (("config",), _config),
)


def command_word(argv: Sequence[str] | None) -> str | None:
    """The command a command line names first (``bus`` of ``bus run --seconds 1``), when
    it is one of :data:`GROUPS`' words; None otherwise (``--help``, ``bench``, a typo)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv and any(argv[0] in words for words, _ in GROUPS):
        return argv[0]
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The registry: every command, or (``only``, a word of :data:`GROUPS`) the one group
    that holds that command. A command line parses the same either way; building one group
    imports only that group's modules, which the console script, started once per command,
    pays for at every start (the whole registry: ~0.5 s of imports)."""
    parser = Parser(
        prog="eha-hil",
        description="Emulator and HIL test harness for the Hydra electro-hydrostatic actuator.",
        epilog="Presets: " + ", ".join(_preset_names()) + ". Example: eha-hil plant bode "
        "--set effects.pulsation.enabled=false --plot bode.png. Exit codes: 0 ok, 1 a "
        "requirement missed (or stdout could not be written), 2 a mistake on the command "
        "line or in a configuration, 130 interrupted (Ctrl-C), 143 SIGTERM, 129 SIGHUP.",
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    if only is not None:
        register = next(reg for words, reg in GROUPS if only in words)
        # the group's bench targets go to a parser nobody parses with
        register(sub, argparse.ArgumentParser().add_subparsers())
        return parser

    from hil.cli import bench

    GROUPS[0][1](sub, None)  # main, plant: listed before bench
    bench_parser = sub.add_parser("bench", help="benchmarks (real-time factor, throughput)")
    bsub = bench_parser.add_subparsers(dest="bench_command", metavar="TARGET", required=True)
    bench.add_parsers(bsub)
    for _, register in GROUPS[1:]:
        register(sub, bsub)
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
        word = command_word(argv)
        args = (build_parser(word) if word else build_parser()).parse_args(argv)
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
