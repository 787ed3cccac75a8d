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

Loading takes a fraction of a second; compiling a large kernel afresh (a cold cache, a
changed kernel source) takes minutes on a loaded machine, and a signal deferred that long
would leave a ``kill`` unanswered while the compiler's memory grows. So a signal still
deferred after :data:`FORCE_AFTER_S` is raised inside the lock after all (from a timer, at
the main thread's next bytecode: the compiler's own Python, which unwinds and releases the
lock), and again every :data:`FORCE_AFTER_S` should one land where it cannot leave.

numba is imported only by the commands that run a kernel (its import is most of a command's
start-up), so :func:`install` registers the listener when ``numba.core.event`` is first
imported (an import hook), or at once if it already is.

SIGTERM and SIGHUP (a service manager stopping the command, a closed terminal) are handled
as Ctrl-C: they raise :class:`Interrupted`, a ``KeyboardInterrupt`` that remembers its signal,
so every ``with`` on the way out closes its file as for Ctrl-C, and the command exits with
128 + the signal's number (143, 129) after the same one line.
"""

from __future__ import annotations

import _thread
import importlib.machinery
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from types import FrameType, ModuleType
from typing import Any

from hil.cli.signals import SIGNALS, Interrupted, default_handler, raise_interrupted

#: A signal deferred this long [s] is raised inside numba's compiler lock after all (loading
#: a cached kernel takes 0.1-0.3 s; this is a compile).
FORCE_AFTER_S = 3.0


#: numba's event module, whose compiler-lock events the handler listens to.
_EVENT_MODULE = "numba.core.event"


class DeferredInterrupt:
    """Signal handler and compiler-lock listener: raise now, at the lock's release, or
    ``force_after_s`` into a long compile (``interrupt(signum)``: runs the handler in the
    main thread again, from the timer's thread). numba's listener is :func:`_listener`
    of it (numba's ``Listener`` class is made where numba is loaded)."""

    def __init__(self, force_after_s: float = FORCE_AFTER_S,
                 interrupt: Callable[[int], None] = _thread.interrupt_main) -> None:
        self.depth = 0  # the main thread's nesting in the (re-entrant) compiler lock
        self.pending: int | None = None  # the signal waiting for the lock's release
        self.force_after_s = force_after_s
        self.interrupt = interrupt
        self.forcing = False  # the next call of the handler raises, lock or not
        self._timer: threading.Timer | None = None

    @staticmethod
    def _main() -> bool:
        return threading.current_thread() is threading.main_thread()

    def on_start(self, ev: Any) -> None:
        if self._main():
            self.depth += 1

    def on_end(self, ev: Any) -> None:
        if not self._main():
            return
        self.depth = max(self.depth - 1, 0)
        if self.depth == 0:
            self.forcing = False
            if self.pending is not None:
                signum, self.pending = self.pending, None
                raise Interrupted(signum)

    def handler(self, signum: int, frame: FrameType | None) -> None:
        if self.depth > 0 and not self.forcing:
            self.pending = signum  # raised when numba releases its lock ...
            self._arm()            # ... or FORCE_AFTER_S from now
            return
        if self.forcing:  # (kept pending: raised again at the lock's release, or forced
            self.forcing = False  # again should this one be lost inside the compiler)
            self._arm()
        raise Interrupted(signum)

    def _arm(self) -> None:
        if self._timer is not None and self._timer.is_alive():
            return
        self._timer = threading.Timer(self.force_after_s, self._force)
        self._timer.daemon = True
        self._timer.start()

    def _force(self) -> None:
        """(The timer's thread.) The signal is still deferred: raise it in the main thread."""
        signum = self.pending
        self._timer = None  # (the handler arms the next one)
        if signum is None:
            return
        self.forcing = True
        self.interrupt(signum)


def _listener(target: DeferredInterrupt, event: ModuleType) -> Any:
    """numba's ``Listener`` passing the compiler lock's start and end on to ``target``."""

    class _Lock(event.Listener):
        def on_start(self, ev: Any) -> None:
            target.on_start(ev)

        def on_end(self, ev: Any) -> None:
            target.on_end(ev)

    return _Lock()


def _register(event: ModuleType) -> None:
    if _INSTALLED is not None:
        event.register("numba:compiler_lock", _listener(_INSTALLED, event))


class _WhenImported:
    """Calls ``then(module)`` once the module ``name`` has been executed (its first import),
    and takes itself off ``sys.meta_path``: the module is found and loaded as usual.
    A finder on ``sys.meta_path`` needs only ``find_spec``: not deriving from
    ``importlib.abc.MetaPathFinder`` spares every start of the console script importing
    ``importlib.abc`` (and ``importlib.resources`` with it, ~30 ms)."""

    def __init__(self, name: str, then: Callable[[ModuleType], None]) -> None:
        self.name = name
        self.then = then

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != self.name:
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        loader = None if spec is None else spec.loader
        if loader is None or not hasattr(loader, "exec_module"):
            return spec  # (not a file-system module: imported as usual, nobody told)
        run = loader.exec_module
        then = self.then

        def exec_module(module: ModuleType) -> None:
            run(module)
            then(module)

        loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


_INSTALLED: DeferredInterrupt | None = None


def install() -> None:
    """Handle SIGINT, SIGTERM and SIGHUP as Ctrl-C, deferred out of numba's compiler lock,
    for this process (idempotent; a signal the process ignores, e.g. SIGINT in a background
    job or SIGHUP under nohup, stays ignored; one somebody else handles is left to them)."""
    global _INSTALLED
    if _INSTALLED is not None or not DeferredInterrupt._main():
        return
    _INSTALLED = DeferredInterrupt()
    event = sys.modules.get(_EVENT_MODULE)
    if event is not None:
        _register(event)
    else:  # numba not loaded (yet): listen from its import on, if it comes
        sys.meta_path.insert(0, _WhenImported(_EVENT_MODULE, _register))
    for signum in SIGNALS:
        if signal.getsignal(signum) in (default_handler(signum), raise_interrupted):
            signal.signal(signum, _INSTALLED.handler)


__all__ = ["DeferredInterrupt", "install"]
