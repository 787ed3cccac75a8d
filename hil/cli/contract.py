"""The contract every ``eha-hil`` command keeps, and the one place its result is printed.

A command is a parser (its arguments, declared with the types of :mod:`hil.cli.args`) and a
``run(args, ctx) -> Outcome``. It computes; it does not print its result, look at
``--json``, choose how an error looks or catch Ctrl-C. The root (:mod:`hil.cli.root`) does
all of that, once, for every command:

* the result: :func:`emit` prints ``Outcome.text`` for people, or ``Outcome.data`` as
  strictly valid JSON with ``--json`` (NaN and infinities become ``null``;
  ``allow_nan=False`` proves none is left);
* a mistake: :class:`UsageError`, the one class for it, printed as one line
  ``eha-hil VERB: WHAT`` (the form argparse's own errors have too), exit 2;
* stdout that cannot be written (a full disk, ``/dev/full``, a closed pipe): one line on
  stderr, exit 1 (a reader that went away, ``| head``: quietly, exit 0);
* SIGINT, SIGTERM, SIGHUP: one line saying what was interrupted and written, exit
  128 + the signal (130, 143, 129) (:mod:`hil.cli.signals`).

Progress and notes go to stderr through the context (:meth:`Context.progress`,
:meth:`Context.say`), which keeps them off when ``--json`` asks for a clean machine
reading, as before.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

#: Exit codes: done; a requirement missed or a result incomplete; a usage mistake.
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


class UsageError(Exception):
    """A mistake in what the user asked (an option, a file, a configuration value): one line
    naming what and where, exit 2. The only class for it in the command line."""


class StdoutError(OSError):
    """stdout itself cannot be written (a full disk, ``/dev/full``, a closed pipe)."""


class GuardedStdout:
    """stdout for the length of a command: a write or flush that fails raises
    :class:`StdoutError` (so a command writing a file can tell its own failure from the
    terminal's), everything else is the wrapped stream's."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as exc:
            raise StdoutError(exc.errno, exc.strerror or str(exc)) from exc

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            raise StdoutError(exc.errno, exc.strerror or str(exc)) from exc

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@dataclass
class Outcome:
    """What a command produced.

    ``text``: what people read on stdout (None: nothing); ``data``: the same for machines,
    printed instead of ``text`` under ``--json`` (None: the command has no JSON form);
    ``code``: the exit code; ``error``: one line for stderr (the root prefixes the verb),
    e.g. a refusal whose JSON still goes to stdout; ``end``: what ends ``text`` (raw
    outputs, e.g. an XML file, carry their own newline)."""

    text: str | None = None
    data: Any = None
    code: int = EXIT_OK
    error: str | None = None
    end: str = "\n"
    #: files written after the result is printed (:class:`hil.cli.outputs.Later`): an
    #: interruption or a failure while they are written keeps the result
    files: tuple = ()


class Run(Protocol):
    def __call__(self, args: argparse.Namespace, ctx: Context) -> Outcome: ...


class Context:
    """What the root gives a command: the verb, the configuration and stderr channels."""

    def __init__(self, args: argparse.Namespace, verb: str) -> None:
        self.args = args
        self.verb = verb
        self.json = bool(getattr(args, "json", False))  # only commands that declare --json

    def config(self, args: argparse.Namespace | None = None):  # noqa: ANN201 - plant Config
        """The configuration of ``-c``/``--set``."""
        from hil.cli.verify import rtl_sets  # --rtl DIR: the board's loop as that RTL
        from plant.config import load_config

        a = args or self.args
        return load_config(a.config, [*(a.set or ()), *rtl_sets(a)])

    def config_if_given(self):  # noqa: ANN201
        """The configuration of ``-c``/``--set`` if either is given, else None (replay and
        serve then take the one their log or peer carries)."""
        a = self.args
        return self.config() if (a.config is not None or bool(a.set)) else None

    def progress(self, label: str, unit: str = "", note: bool = True
                 ) -> Callable[[int, int], None]:
        """A ``progress(i, n)`` callback: drawn on stderr unless ``--json``; always noting
        the position Ctrl-C reports."""
        from hil.cli import progress

        return progress.reporter(label, not self.json, unit=unit, note=note)

    def say(self, message: str) -> None:
        """A note for people on stderr while the command runs (off under ``--json``)."""
        if not self.json:
            print(message, file=sys.stderr, flush=True)


def command(parser: argparse.ArgumentParser, run: Run, verb: str | None = None
            ) -> argparse.ArgumentParser:
    """Register ``run`` as the command of ``parser`` (a leaf of the registry); ``verb``: how
    its lines name it, when not the words typed (the log verbs: ``eha-hil log``)."""
    parser.set_defaults(run=run, verb=verb)
    return parser


# --- the one printer ---------------------------------------------------------------------------
def finite(obj: Any) -> Any:
    """``obj`` as plain JSON values: numpy scalars and arrays as numbers and lists, a NaN
    or an infinity as None (strict JSON has no such numbers; ``null`` is a missing one)."""
    import numpy as np

    if isinstance(obj, float | np.floating):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def to_json(data: Any) -> str:
    """Strictly valid JSON text of ``data`` (what ``--json`` prints)."""
    return json.dumps(finite(data), indent=2, allow_nan=False, default=str)


def emit(outcome: Outcome, json_wanted: bool) -> None:
    """Print the outcome: its data as JSON with ``--json``, else its text. Raises
    :class:`StdoutError` when stdout cannot take it (the root says so)."""
    if json_wanted:
        if outcome.data is not None:
            sys.stdout.write(to_json(outcome.data) + "\n")
    elif outcome.text is not None:
        sys.stdout.write(outcome.text + outcome.end)
    sys.stdout.flush()


def error_line(verb: str, message: str) -> str:
    """The one form of a line on stderr that ends a command: ``eha-hil VERB: WHAT`` (a
    mistake, a refusal, a cut input, a failing stdout; the interruption line and argparse's
    own errors have the same form)."""
    return f"{verb}: {message}"


# --- running a command -------------------------------------------------------------------------
def _quiet_stdout() -> None:
    """After stdout failed: point its descriptor at /dev/null, so that the interpreter's
    last flush at exit does not fail a second time with a traceback of its own."""
    try:
        fd = sys.__stdout__.fileno()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except (AttributeError, OSError, ValueError):  # no real descriptor (a test's buffer)
        pass


def execute(run: Run, args: argparse.Namespace, verb: str) -> int:
    """Run one parsed command through the contract and return its exit code: its outcome
    printed (:func:`emit`), a mistake, a failing stdout or a signal as one line on stderr."""
    from hil.cli import outputs, progress
    from hil.cli.args import image_sets
    from hil.cli.signals import signal_of
    from hil.sim.image.errors import ImageFault
    from plant.config import ConfigError

    stdout = sys.stdout
    sys.stdout = GuardedStdout(stdout)
    try:
        progress.start(verb)
        outputs.reset()
        outputs.check_args(vars(args))  # an output that is also an input: refused
        image_sets(args)  # --mcu-image FILE: the --set entries it stands for
        ctx = Context(args, verb)
        outcome = run(args, ctx)
        if not isinstance(outcome, Outcome):
            raise TypeError(f"{verb}: a command returns an Outcome, not {outcome!r}")
        emit(outcome, ctx.json)
        if outcome.error:
            print(error_line(verb, outcome.error), file=sys.stderr, flush=True)
        outputs.write_later(outcome.files, ctx.json, lambda line: print(line, flush=True))
        return outputs.finish(verb, outcome.code)
    except (ConfigError, UsageError) as exc:
        print(error_line(verb, str(exc)), file=sys.stderr, flush=True)
        return EXIT_USAGE
    except outputs.StreamFailed:  # a log or capture of the run failed: the line says which
        return outputs.finish(verb, EXIT_FAILED)
    except ImageFault as exc:  # the firmware image broke the interface: the run failed
        print(error_line(verb, str(exc)), file=sys.stderr, flush=True)
        return EXIT_FAILED
    except (StdoutError, BrokenPipeError) as exc:
        _quiet_stdout()
        if isinstance(exc, BrokenPipeError) or exc.errno == 32:
            return EXIT_OK  # EPIPE: the reader went away (| head): nothing to report
        print(error_line(verb, f"cannot write to stdout: {exc.strerror}"), file=sys.stderr,
              flush=True)
        return EXIT_FAILED
    except KeyboardInterrupt as exc:
        # The one place a signal ends up. By now every `with` on the way out has run, so a
        # log being written is closed; the line says whether it reads back.
        signum = signal_of(exc)
        print(progress.interrupted_line(signum), file=sys.stderr, flush=True)
        return 128 + signum
    finally:
        sys.stdout = stdout


def standalone(verb: str) -> Callable[[Run], Callable[..., Any]]:
    """A command that can also be called as ``run(args)`` (no context) with a namespace of
    its own parser: then it runs through :func:`execute` as ``verb`` and returns the exit
    code, as the root would. The modules' own entry points keep working this way."""

    def wrap(run: Run) -> Callable[..., Any]:
        @functools.wraps(run)
        def call(args: argparse.Namespace, ctx: Context | None = None) -> Any:
            return run(args, ctx) if ctx is not None else execute(run, args, verb)

        return call

    return wrap
