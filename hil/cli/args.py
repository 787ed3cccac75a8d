"""Argument types of the ``eha-hil`` command line: every number and path check in one place.

Each factory returns an argparse ``type=`` function. A bad value raises
:class:`argparse.ArgumentTypeError`, which the parser (:class:`Parser`) turns into one line
``eha-hil VERB: argument --opt: why`` and exit code 2, before any work starts. A
verb never re-checks a value it got through one of these types.

Numbers are checked for being finite first (``nan`` and ``inf`` parse as floats), then
against the range the option's meaning allows; the range is part of the option's help.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from hil.cli import outputs
from hil.cli.contract import EXIT_USAGE


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (no usage block) and whose help shows
    each option's default. Sub-parsers inherit the class, hence both behaviours."""

    def __init__(self, *args, **kwargs) -> None:  # noqa: ANN002, ANN003 - argparse's own
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    #: The deepest parser the last command line reached (``eha-hil log info``), so that an
    #: unknown option is named with the command it is not an option of.
    _leaf: Parser | None = None

    def parse_known_args(self, args=None, namespace=None):  # noqa: ANN001, ANN201 - argparse's
        ns, extras = super().parse_known_args(args, namespace)
        if args is not None:  # a sub-parser always gets its own list
            self._check_scopes([str(a) for a in args], ns)
        if Parser._leaf is None or len(self.prog) > len(Parser._leaf.prog):
            Parser._leaf = self
        return ns, extras

    def parse_args(self, args=None, namespace=None):  # noqa: ANN001, ANN201 - argparse's
        Parser._leaf = None
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            leaf = Parser._leaf or self
            # argparse lists every leftover, and an unknown option's value may have been
            # taken for a positional: name the option, the real mistake
            opts = [e for e in extras if e.startswith("-") and e not in ("-", "--")]
            if opts:
                leaf.error(f"argument {opts[0].split('=', 1)[0]}: not an option of "
                           f"{leaf.prog}")
            leaf.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def _check_scopes(self, argv: list[str], ns: argparse.Namespace) -> None:
        """The one place an option meant for another choice is refused (see
        :func:`only_with`): ``serve --transport udp --baudrate 9600`` would else be
        silently ignored."""
        for action in self._actions:
            scope = getattr(action, "only_with", None)
            if scope is None or not _given(action, argv):
                continue
            dest, allowed = scope
            chosen = getattr(ns, dest, None)
            if chosen not in allowed:
                flag = f"--{dest.replace('_', '-')}"
                if allowed == (True,):  # a switch: ``--wire``
                    need = f"only with {flag}"
                elif allowed == (False,):
                    need = f"not with {flag}"
                else:
                    need = f"only with {flag} {' or '.join(map(str, allowed))} (not {chosen})"
                self.error(f"argument {'/'.join(action.option_strings)}: {need}: it would "
                           "be ignored")

    def error(self, message: str) -> NoReturn:
        # argparse prints the whole usage block first; one line says the same and keeps
        # stderr readable for scripts (``--help`` has the usage).
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


def _given(action: argparse.Action, argv: list[str]) -> bool:
    """Whether the command line names ``action``'s option (also as ``--opt=V`` or an
    abbreviation argparse accepts); values after ``--`` are not options."""
    for token in argv:
        if token == "--":
            return False
        if not token.startswith("-"):
            continue
        name = token.split("=", 1)[0]
        for opt in action.option_strings:
            if name == opt or (opt.startswith("--") and len(name) > 2
                               and name.startswith("--") and opt.startswith(name)):
                return True
    return False


def only_with(action: argparse.Action, dest: str, *allowed: str | bool) -> argparse.Action:
    """Mark an option as meaningful only when option ``dest`` is one of ``allowed`` (e.g.
    ``--baudrate`` only with ``--transport serial``; ``True``: only with the switch
    ``--dest`` given, ``False``: only without it); :class:`Parser` refuses it otherwise with
    one line, before any work."""
    action.only_with = (dest, tuple(allowed))  # type: ignore[attr-defined]
    return action


class HelpFormatter(argparse.HelpFormatter):
    """Appends ``(default: X)`` to an option's help when it has a default worth showing."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        # A flag's True/False default says nothing the help does not; None: no default.
        if (text and "default" not in text and action.option_strings
                and default is not None and default is not argparse.SUPPRESS
                and not isinstance(default, bool) and default != []):
            shown = " ".join(map(str, default)) if isinstance(default, list) else default
            text += f" (default: {shown})".replace("%", "%%")
        return text


def _interval(lo: float | None, hi: float | None, open_lo: bool, unit: str) -> str:
    left = "(" if open_lo else "["
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_s}, {hi_s}]" + (f" {unit}" if unit else "")


def finite_float(text: str) -> float:
    """A finite number from the command line (argparse type; one line for anything else)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: need a finite number")
    return value


def float_range(lo: float | None = None, hi: float | None = None, *, open_lo: bool = False,
                unit: str = "") -> Callable[[str], float]:
    """A finite float with ``lo <= x <= hi`` (``lo < x`` when ``open_lo``); None: unbounded."""
    span = _interval(lo, hi, open_lo, unit)

    def parse(text: str) -> float:
        value = finite_float(text)
        if lo is not None and (value < lo or (open_lo and value == lo)):
            raise argparse.ArgumentTypeError(f"{text}: need a number in {span}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"{text}: need a number in {span}")
        return value

    parse.__name__ = "number"  # argparse names the type in some messages
    parse.kind = "number"  # type: ignore[attr-defined]  # what the CLI tests feed it
    return parse


def positive_float(hi: float, unit: str = "") -> Callable[[str], float]:
    """A finite float with ``0 < x <= hi``."""
    return float_range(0.0, hi, open_lo=True, unit=unit)


def int_range(lo: int, hi: int, unit: str = "") -> Callable[[str], int]:
    """An integer with ``lo <= n <= hi``."""
    span = f"{lo}..{hi}" + (f" {unit}" if unit else "")

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{text}: need an integer in {span}")
        return value

    parse.__name__ = "integer"
    parse.kind = "number"  # type: ignore[attr-defined]
    return parse


def int_list(lo: int, hi: int, unit: str = "") -> Callable[[str], list[int]]:
    """Comma-separated integers, each with ``lo <= n <= hi``."""
    one = int_range(lo, hi, unit)

    def parse(text: str) -> list[int]:
        return [one(part.strip()) for part in text.split(",")]

    parse.__name__ = "integer list"
    parse.kind = "number"  # type: ignore[attr-defined]
    return parse


def input_file(what: str = "file") -> Callable[[str], str]:
    """An existing, readable, non-empty regular file (its content is the reader's to judge)."""

    def parse(text: str) -> str:
        p = Path(text)
        if p.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: is a directory; give a {what}")
        if not p.exists():
            raise argparse.ArgumentTypeError(f"{text}: no such file")
        if not p.is_file():
            raise argparse.ArgumentTypeError(f"{text}: not a regular file")
        try:
            with p.open("rb") as f:
                first = f.read(1)
        except OSError as exc:
            raise argparse.ArgumentTypeError(f"{text}: cannot read: {exc.strerror}") from None
        if not first:
            raise argparse.ArgumentTypeError(f"{text}: is empty; give a {what}")
        return text

    parse.__name__ = "file"
    parse.kind = "input"  # type: ignore[attr-defined]
    return parse


def _looks_like_text(p: Path) -> bool:
    with p.open("rb") as f:
        head = f.read(4096)
    if b"\0" in head:
        return False
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return exc.start >= len(head) - 3  # a multi-byte character cut by the 4 KiB read
    return True


def output_file(suffixes: Sequence[str] | None, text: bool = False,
                stdout: bool = False) -> Callable[[str], str]:
    """A file to write: one of ``suffixes`` (case-insensitive; None: any), its directory
    exists and takes a new file (:func:`hil.cli.outputs.check_writable`), not a directory.
    ``text``: an existing file is overwritten only if it holds text, so a mistyped name
    never replaces an image or a log. ``stdout``: ``-`` means stdout. The value comes back
    as a :class:`hil.cli.outputs.OutputPath` (the root refuses one that is also an input)."""
    names = ", ".join(suffixes or ("any name",))

    def parse(value: str) -> str:
        if stdout and value == "-":
            return value
        p = Path(value)
        if p.is_dir():
            raise argparse.ArgumentTypeError(f"{value}: is a directory; give a file name "
                                             f"({names})")
        if suffixes is not None and p.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{value}: use a file name ending {names}")
        parent = p.parent if str(p.parent) else Path(".")
        if parent.exists() and not parent.is_dir():
            raise argparse.ArgumentTypeError(f"{value}: {parent} is not a directory")
        if not parent.is_dir():
            raise argparse.ArgumentTypeError(f"{value}: directory {parent} does not exist")
        # a character device (/dev/null, /dev/full, also behind a link) is written in place
        if p.exists() and not outputs.is_device(p):
            if not p.is_file():
                raise argparse.ArgumentTypeError(f"{value}: exists and is not a regular file")
            if text and not _looks_like_text(p):
                raise argparse.ArgumentTypeError(f"{value}: exists and is not a text file; "
                                                 "not overwriting it")
        try:
            outputs.check_writable(p)  # before any work: a read-only or full directory
        except outputs.OutputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return outputs.OutputPath(value)

    parse.__name__ = "file name"
    parse.kind = "output"  # type: ignore[attr-defined]
    parse.suffixes = tuple(suffixes or (".csv",))  # type: ignore[attr-defined]
    return parse


def output_dir(value: str) -> str:
    """A directory to write into: an existing directory, or a new one whose parent exists;
    either must take new files (:func:`hil.cli.outputs.check_dir_writable`)."""
    try:
        outputs.check_dir_writable(value)
    except outputs.OutputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return outputs.OutputPath(value)


output_dir.kind = "dir"  # type: ignore[attr-defined]


def add_config_options(parser: argparse.ArgumentParser, mcu: bool = True) -> None:
    """``-c/--config`` and ``--set``, the same on every verb that simulates the actuator (the
    values are checked by :func:`plant.config.load_config`, against the schema's ranges);
    ``--mcu-image`` only where an MCU runs (``mcu``): elsewhere it would be ignored."""
    parser.add_argument("-c", "--config", metavar="PRESET|FILE",
                        help="actuator preset name or TOML file (default: hydra_default)")
    parser.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                        help="override one configuration value (repeatable)")
    if not mcu:
        return
    parser.add_argument("--mcu-image", metavar="FILE.elf", type=mcu_image,
                        help="run this Cortex-M4F firmware ELF as the MCU (sets mcu.impl="
                        "image and mcu.image; the interface: docs/mcu.md)")


def mcu_image(text: str) -> str:
    """A firmware ELF the harness can run (checked here once: architecture, vector table,
    5 kHz entry); the path."""
    from hil.sim.image.elf import load
    from hil.sim.image.errors import ImageError

    try:
        load(text)
    except ImageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


mcu_image.kind = "input"  # type: ignore[attr-defined]


def image_sets(args: argparse.Namespace) -> None:
    """``--mcu-image FILE`` as the two ``--set`` entries it stands for."""
    path = getattr(args, "mcu_image", None)
    if path:
        args.set = [*(args.set or ()), "mcu.impl=image", f"mcu.image={path}"]


#: --plot: a figure file whose directory exists.
PLOT_FILE = output_file((".png", ".svg", ".pdf"))


def common(json_plot: bool = True, plot: bool = True, config: bool = True,
           mcu: bool = True) -> argparse.ArgumentParser:
    """The options verbs share: ``-c``/``--set`` (``config``), ``--mcu-image`` (``mcu``: the
    verb runs the MCU law), ``--json`` and ``--plot``."""
    parent = Parser(add_help=False)
    if config:
        add_config_options(parent, mcu=mcu)
    if json_plot:
        parent.add_argument("--json", action="store_true", help="print JSON instead of tables")
    if plot:
        parent.add_argument("--plot", metavar="FILE.png", type=PLOT_FILE,
                            help="also write a figure (.png, .svg or .pdf)")
    return parent


def plot_dir(path: str) -> Path:
    """The --plot-dir directory, created if missing (checked again: 'thesis' has a default
    that no argument type saw)."""
    outputs.check_dir_writable(path)
    out_dir = Path(path)
    out_dir.mkdir(exist_ok=True)
    return out_dir


def walk(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """This parser and every sub-parser below it (for checks over the whole command line)."""
    out = [parser]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):
                out += walk(sub)
    return out
