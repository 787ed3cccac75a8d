"""Ctrl-C that never lands inside numba's loading of machine code.

Python raises ``KeyboardInterrupt`` at the next bytecode its main thread runs. While numba
loads a kernel's cached machine code (the first call of each kernel in a process, 0.1-0.3 s),
that bytecode can be a Python callback that LLVM calls: the exception cannot leave it, Python
prints it ("Exception ignored in ...") and the command goes on as if nothing had happened.

:func:`install` replaces the SIGINT handler with one that defers a Ctrl-C arriving while the
main thread holds numba's compiler lock (which covers compiling and loading) and raises it
when the lock is released, in ordinary Python code, where the command's one-line
interruption message takes over. numba announces the lock through its event API
(``numba.core.event``, kind ``numba:compiler_lock``).
"""

from __future__ import annotations

import signal
import threading
from types import FrameType

from numba.core import event


class DeferredInterrupt(event.Listener):
    """SIGINT handler and compiler-lock listener: raise now, or at the lock's release."""

    def __init__(self) -> None:
        self.depth = 0  # the main thread's nesting in the (re-entrant) compiler lock
        self.pending = False

    @staticmethod
    def _main() -> bool:
        return threading.current_thread() is threading.main_thread()

    def on_start(self, ev: event.Event) -> None:
        if self._main():
            self.depth += 1

    def on_end(self, ev: event.Event) -> None:
        if not self._main():
            return
        self.depth = max(self.depth - 1, 0)
        if self.depth == 0 and self.pending:
            self.pending = False
            raise KeyboardInterrupt

    def handler(self, signum: int, frame: FrameType | None) -> None:
        from hil.cli import progress as cli_progress

        cli_progress.noted(signum)  # the exit code says which signal (130, 143, 129)
        if self.depth > 0:
            self.pending = True  # raised when numba releases its lock
            return
        raise KeyboardInterrupt


_INSTALLED: DeferredInterrupt | None = None


def install() -> None:
    """Defer Ctrl-C out of numba's compiler lock for this process, and take SIGTERM and
    SIGHUP as Ctrl-C (idempotent; a process that ignores one of them, e.g. started in the
    background or under nohup, keeps ignoring it)."""
    global _INSTALLED
    if _INSTALLED is not None or not DeferredInterrupt._main():
        return
    _INSTALLED = DeferredInterrupt()
    event.register("numba:compiler_lock", _INSTALLED)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _INSTALLED.handler)
    # SIGTERM (kill, a service manager's stop) and SIGHUP (the terminal closed) end the
    # command as Ctrl-C does: files closed, one line; an ignored one (nohup) stays ignored
    for sig in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is signal.SIG_DFL:
            signal.signal(sig, _INSTALLED.handler)


__all__ = ["DeferredInterrupt", "install"]
