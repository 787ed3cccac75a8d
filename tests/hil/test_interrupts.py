"""A Ctrl-C inside numba's compiler lock is deferred to the lock's release, not lost."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest
from numba.core import event

from hil.cli.interrupts import DeferredInterrupt


def test_outside_the_lock_ctrl_c_raises_at_once():
    d = DeferredInterrupt()
    with pytest.raises(KeyboardInterrupt):
        d.handler(2, None)


def test_inside_the_lock_it_waits_for_the_outermost_release():
    d = DeferredInterrupt()
    ev = event.Event("numba:compiler_lock", event.EventStatus.START)
    d.on_start(ev)
    d.on_start(ev)  # the lock is re-entrant
    d.handler(2, None)  # deferred: no exception inside the lock
    d.on_end(ev)
    with pytest.raises(KeyboardInterrupt):
        d.on_end(ev)
    d.on_end(ev)  # once raised, a later release does not raise again
    assert not d.pending


def test_a_signal_deferred_into_a_long_compile_is_raised_there_after_a_while():
    """A compile of minutes (a cold cache on a loaded machine) does not leave a SIGTERM
    unanswered: after ``force_after_s`` the handler runs again and raises inside the lock,
    and keeps the signal for the lock's release (and for another try)."""
    forced: list[int] = []
    d = DeferredInterrupt(force_after_s=0.05, interrupt=forced.append)
    ev = event.Event("numba:compiler_lock", event.EventStatus.START)
    d.on_start(ev)
    d.handler(15, None)  # deferred at first
    deadline = time.monotonic() + 10
    while not forced and time.monotonic() < deadline:
        time.sleep(0.005)
    assert forced[:1] == [15]  # the timer asked for the handler again (the main thread's)
    with pytest.raises(KeyboardInterrupt) as exc:
        d.handler(15, None)
    assert exc.value.signum == 15 and d.pending == 15
    with pytest.raises(KeyboardInterrupt):  # once more at the release, then done
        d.on_end(ev)
    assert d.pending is None
    tries = len(forced)
    time.sleep(0.2)
    assert len(forced) == tries  # nothing pending: no more tries


def test_other_threads_holding_the_lock_do_not_defer_the_main_threads_ctrl_c():
    d = DeferredInterrupt()
    ev = event.Event("numba:compiler_lock", event.EventStatus.START)
    t = threading.Thread(target=d.on_start, args=(ev,))
    t.start()
    t.join()
    with pytest.raises(KeyboardInterrupt):
        d.handler(2, None)


def test_numba_announces_its_compiler_lock():
    """The deferral rests on numba's event API: the lock's start and end reach a listener."""
    from numba import njit

    seen: list[str] = []

    class Rec(event.Listener):
        def on_start(self, ev):
            seen.append("start")

        def on_end(self, ev):
            seen.append("end")

    rec = Rec()
    event.register("numba:compiler_lock", rec)
    try:
        njit(lambda x: x + 1)(1)
    finally:
        event.unregister("numba:compiler_lock", rec)
    assert seen and seen.count("start") == seen.count("end") and seen[0] == "start"


def test_installed_before_numba_it_listens_once_numba_is_imported():
    """The command line installs the handlers before numba is loaded (numba's import is most
    of a start-up a command without kernels need not pay): the listener is registered when
    numba's event module is first imported, and a signal during a compile is deferred."""
    code = """
import sys
from hil.cli import interrupts
interrupts.install()
assert "numba" not in sys.modules, "install() imported numba"
from numba.core import event
from numba import njit
hit = []
real = interrupts._INSTALLED.on_start
def on_start(ev):
    real(ev)
    hit.append(interrupts._INSTALLED.depth)
interrupts._INSTALLED.on_start = on_start
njit(lambda x: x + 1)(1)
assert hit and hit[0] >= 1, hit
assert interrupts._INSTALLED.depth == 0
assert not any(isinstance(f, interrupts._WhenImported) for f in sys.meta_path)
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=False)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
