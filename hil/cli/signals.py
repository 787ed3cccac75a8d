"""The signals the command line handles as Ctrl-C, and the exception they raise.

Light on purpose (the standard library only): :func:`install_early` runs before the command
line imports numpy and numba, so that SIGTERM or SIGHUP in that first second ends the
command with its one line, as Ctrl-C then does, instead of killing it silently or printing a
traceback. :mod:`hil.cli.interrupts` takes over once numba is loaded.
"""

from __future__ import annotations

import signal
from types import FrameType

#: The signals handled as Ctrl-C: SIGINT, SIGTERM (a service manager, ``kill``), SIGHUP (a
#: closed terminal).
SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None))
                if s is not None)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, SIGTERM or SIGHUP: what every ``except KeyboardInterrupt`` already handles,
    with the signal's number (``signum``) for the exit code (128 + it) and the line."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signum)
        self.signum = int(signum)


def signal_of(exc: BaseException) -> int:
    """The signal that raised ``exc`` (SIGINT for a plain KeyboardInterrupt)."""
    return getattr(exc, "signum", int(signal.SIGINT))


def raise_interrupted(signum: int, frame: FrameType | None) -> None:
    """A signal handler: raise :class:`Interrupted` at once."""
    raise Interrupted(signum)


def default_handler(signum: int) -> object:
    """What a signal's handler is when nobody set one."""
    return signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL


def install_early() -> None:
    """Raise :class:`Interrupted` on SIGTERM and SIGHUP from now on (SIGINT already raises
    KeyboardInterrupt); a signal the process ignores (nohup) or that somebody else handles is
    left as it is."""
    for signum in SIGNALS:
        if signum == signal.SIGINT:
            continue
        try:
            if signal.getsignal(signum) is default_handler(signum):
                signal.signal(signum, raise_interrupted)
        except ValueError:  # not the main thread: signals cannot be handled here
            return
