"""Worker processes that end with the command: one pool helper for every verb that uses one
(``identify-check``, ``sweep``).

A terminal's Ctrl-C reaches the whole process group, a ``kill`` or a service manager's stop
only the command. Either way the command alone decides: its workers ignore SIGINT and
SIGHUP (:func:`worker_signals`), and the pool of :func:`process_pool` ends them
(SIGTERM, then a join) as soon as the command leaves the block other than normally:
Ctrl-C, SIGTERM (raised as KeyboardInterrupt by the command line), an error. A worker whose
parent dies without cleaning up (SIGKILL) is sent SIGTERM by the kernel
(``PR_SET_PDEATHSIG``): no orphan keeps computing.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1


def worker_signals() -> None:
    """In a worker: leave SIGINT and SIGHUP to the parent, die with it (Linux)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() == 1:  # the parent died before the line above ran
            os._exit(1)


def _init(user: Callable[[], None] | None) -> None:
    worker_signals()
    if user is not None:
        user()


def terminate(pool: ProcessPoolExecutor) -> None:
    """End the pool's workers now (not after their current task) and wait for them.
    Python 3.11 has no public way (3.14: ``terminate_workers``)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    # (taken before the shutdown below, which forgets it)
    manager = getattr(pool, "_executor_manager_thread", None)
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError, AssertionError):
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join()
    # The pool's manager thread closes its wake-up pipe as it ends; concurrent.futures' exit
    # hook wakes every such thread without a lock, and a pipe closed between its check and
    # its write printed "OSError: [Errno 9] Bad file descriptor" after the command's last
    # line (Python 3.11). Once the thread has ended, the hook sees the pipe closed.
    if manager is not None:
        manager.join(5.0)


@contextlib.contextmanager
def process_pool(workers: int, initializer: Callable[[], None] | None = None
                 ) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers``; the workers end with the block, at once
    if it ends by an exception (KeyboardInterrupt included)."""
    pool = ProcessPoolExecutor(max_workers=workers,
                               mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init, initargs=(initializer,))
    try:
        yield pool
    except BaseException:
        terminate(pool)
        raise
    pool.shutdown(wait=True)


__all__ = ["process_pool", "terminate", "worker_signals"]
