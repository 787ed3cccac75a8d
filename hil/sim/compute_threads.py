"""Compute threads that wait in compiled code: the robot engine's helpers for a cycle.

A thread pool hands each cycle's work over through Python: a Future per thread and cycle,
a queue, a semaphore for the start, a condition for the end, and every one of them takes
the GIL in both threads (a cycle of the whole robot paid ~30-60 us of CPU for it, ~15 % of
its compiled call). Here each helper thread enters one compiled function once
(``serve``, written by the user of this module with :func:`await_post` and
:func:`finished`) and stays there, without the GIL, between cycles: it waits for the
calling thread to post a cycle (a counter in shared memory, :func:`post`), runs the
cycle's compiled call, counts itself done (:func:`join` waits for that count) and waits
again. A waiting thread spins a moment and then sleeps in the kernel (a Linux futex on
the counter), so a hand-off costs a few atomic operations when both threads are awake and
one system call each way when one sleeps.

Memory order: the poster's writes before :func:`post` (the cycle's inputs, its claim
counter) are seen by a helper after :func:`await_post` returns, and the helper's writes
before :func:`finished` by the joiner after :func:`join` returns (sequentially consistent
atomic operations on the counters).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import platform
import threading
import time
import weakref
from collections.abc import Callable, Sequence

import llvmlite.binding as llvm
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

#: The futex system call's number (Linux) on the machines the project runs on.
_SYS_FUTEX = {"x86_64": 202, "aarch64": 98}.get(platform.machine())
_FUTEX_WAIT_PRIVATE = 128
_FUTEX_WAKE_PRIVATE = 129
_EVERYONE = 0x7FFFFFFF

#: The control block (int32): the cycle counter the helpers wait on, how many of them
#: sleep on it, the stop flag; on their own cache line, the done counter the joiner
#: waits on and whether it sleeps. One int64 pair beside it: the posted job's values.
GEN, SLEEPERS, STOP = 0, 1, 2
DONE, JOINER = 16, 17
_CTL_WORDS = 32
#: A posted job: two int64 values the helpers read after :func:`await_post`.
JOB_A, JOB_B = 0, 1

#: Spins (the CPU's pause: ~25 ns each on the project's AMD EPYC cores) before a waiting
#: thread sleeps. A helper waits for the next cycle, which in a lockstep run comes after
#: the master's and the PC loop's Python (~50 us) and paced by the wall clock after up to
#: a millisecond: spinning for that long would cost more CPU than the sleep and wake-up
#: (a few us), so it hardly spins. The joiner waits for the helpers' last batch, often a
#: few us away: it spins ~2.5 us first.
SPINS_WAIT = 20
SPINS_JOIN = 100

if _SYS_FUTEX is not None:
    _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    # The compiled code calls libc's syscall() by name (also from the kernel cache).
    llvm.add_symbol("syscall", ctypes.cast(_libc.syscall, ctypes.c_void_p).value)
_syscall = types.ExternalFunction(
    "syscall", types.int64(types.int64, types.intp, types.int64, types.int64, types.intp))
_SYS = _SYS_FUTEX or 0


def _word_pointer(context, builder, aryty, ary, index):
    arr = context.make_array(aryty)(context, builder, ary)
    return cgutils.get_item_pointer(context, builder, aryty, arr, [index])


def _is_ctl(ctl) -> bool:  # noqa: ANN001 - a numba type
    return isinstance(ctl, types.Array) and ctl.dtype == types.int32 and ctl.ndim == 1


@intrinsic
def _load(typingctx, ctl, i):
    """``ctl[i]`` read as one atomic operation (sequentially consistent)."""
    if not _is_ctl(ctl):
        return None

    def codegen(context, builder, signature, args):
        ptr = _word_pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "seq_cst", 4)

    return types.int32(ctl, types.intp), codegen


@intrinsic
def _add(typingctx, ctl, i, v):
    """``ctl[i] += v`` as one atomic operation (sequentially consistent, wrapping)."""
    if not _is_ctl(ctl):
        return None

    def codegen(context, builder, signature, args):
        ptr = _word_pointer(context, builder, signature.args[0], args[0], args[1])
        value = context.cast(builder, args[2], signature.args[2], types.int32)
        return builder.atomic_rmw("add", ptr, value, "seq_cst")

    return types.int32(ctl, types.intp, types.int32), codegen


@intrinsic
def _pause(typingctx):
    """The CPU's spin-wait hint (x86 ``pause``; nothing elsewhere)."""

    def codegen(context, builder, signature, args):
        if platform.machine() == "x86_64":
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(
                ir.VoidType(), []), "llvm.x86.sse2.pause")
            builder.call(fn, [])
        return context.get_dummy_value()

    return types.void(), codegen


@njit(nogil=True, cache=True)
def _futex_wait(ctl, i, expected, timeout):
    """Sleep while ``ctl[i] == expected`` (woken by :func:`_futex_wake`, a signal or
    after ``timeout`` (sec, nsec; 0 address: none))."""
    _syscall(_SYS, ctl.ctypes.data + 4 * i, _FUTEX_WAIT_PRIVATE, expected, timeout)


@njit(nogil=True, cache=True)
def _futex_wake(ctl, i, n):
    _syscall(_SYS, ctl.ctypes.data + 4 * i, _FUTEX_WAKE_PRIVATE, n, 0)


@njit(nogil=True, cache=True)
def await_post(ctl, seen, spins):
    """Wait (in a helper) until a cycle after the one numbered ``seen`` is posted, or the
    threads are told to stop; returns the posted cycle's number."""
    for _ in range(spins):
        g = _load(ctl, GEN)
        if g != seen:
            return g
        _pause()
    while True:
        _add(ctl, SLEEPERS, 1)
        g = _load(ctl, GEN)
        if g == seen:
            _futex_wait(ctl, GEN, seen, 0)
        _add(ctl, SLEEPERS, -1)
        g = _load(ctl, GEN)
        if g != seen:
            return g


@njit(nogil=True, cache=True)
def finished(ctl):
    """A helper has done its part of the posted cycle (wakes a sleeping joiner)."""
    _add(ctl, DONE, 1)
    if _load(ctl, JOINER) != 0:
        _futex_wake(ctl, DONE, 1)


@njit(nogil=True, cache=True)
def stopping(ctl):
    """The helpers are told to return (checked after each :func:`await_post`)."""
    return _load(ctl, STOP) != 0


@njit(nogil=True, cache=True)
def post(ctl, job, a, b):
    """Post a cycle with the job values ``a`` and ``b`` (read by the helpers as
    ``job[JOB_A]``, ``job[JOB_B]``) and wake the helpers that sleep."""
    job[JOB_A] = a
    job[JOB_B] = b
    _add(ctl, GEN, 1)
    if _load(ctl, SLEEPERS) != 0:
        _futex_wake(ctl, GEN, _EVERYONE)


@njit(nogil=True, cache=True)
def join(ctl, target, spins, timeout):
    """Wait until the done counter is ``target`` (every helper finished the cycle):
    True; False once ``timeout`` (an int64 (sec, nsec) array's address) has passed while
    it sleeps, so that the caller can look at its helpers."""
    for _ in range(spins):
        if _load(ctl, DONE) == target:
            return True
        _pause()
    _add(ctl, JOINER, 1)
    done = _load(ctl, DONE)
    if done != target:
        _futex_wait(ctl, DONE, done, timeout)
    _add(ctl, JOINER, -1)
    return _load(ctl, DONE) == target


def _wrap32(v: int) -> int:
    return (v + 2**31) % 2**32 - 2**31


class ComputeThreads:
    """``len(args)`` helper threads, helper ``k`` running ``serve(ctl, job, gen0, spins,
    *args[k])`` (a compiled function with ``nogil``: see the module's docstring) until
    :meth:`close`. :meth:`post` starts a cycle on all of them, :meth:`join` waits for it.
    Closed when garbage collected too (the threads are daemons holding only ``args``)."""

    def __init__(self, serve: Callable, args: Sequence[tuple], spins: int = SPINS_WAIT,
                 join_spins: int = SPINS_JOIN, name: str = "compute") -> None:
        if _SYS_FUTEX is None:
            raise RuntimeError(f"compute threads need Linux futexes on x86_64 or aarch64, "
                               f"not {platform.machine()}")
        self.ctl = np.zeros(_CTL_WORDS, dtype=np.int32)
        self.job = np.zeros(2, dtype=np.int64)
        self.join_spins = join_spins
        self.helpers = len(args)
        self._timeout = np.array([0, 100_000_000], dtype=np.int64)  # 0.1 s: look, wait on
        self._pending = False
        self._errors: list[BaseException] = []
        self.threads = [threading.Thread(target=_run, name=f"{name}-{k + 1}", daemon=True,
                                         args=(serve, self.ctl, self.job, self.ctl[GEN], spins,
                                               a, self._errors))
                        for k, a in enumerate(args)]
        for t in self.threads:
            t.start()
        self._finalizer = weakref.finalize(self, _stop, self.ctl, self.threads)

    @property
    def pending(self) -> bool:
        """A posted cycle not joined yet."""
        return self._pending

    def post(self, a: int, b: int) -> None:
        """Start a cycle on every helper with the job values ``a``, ``b``."""
        if self._pending:
            raise RuntimeError("a cycle is posted already (join it first)")
        self._target = _wrap32(int(self.ctl[DONE]) + self.helpers)
        self._pending = True
        post(self.ctl, self.job, a, b)

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait until every helper has finished the posted cycle (none posted: at once):
        True; False if ``timeout_s`` (None: no limit) passed first (the cycle stays
        posted). Raises if a helper ended (its exception, if any, as the cause)."""
        if not self._pending:
            return True
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while not join(self.ctl, self._target, self.join_spins, self._timeout.ctypes.data):
            if self._errors or not all(t.is_alive() for t in self.threads):
                self._pending = False
                raise RuntimeError("a compute thread ended during a cycle") from (
                    self._errors[0] if self._errors else None)
            if end is not None and time.monotonic() >= end:
                return False
        self._pending = False
        return True

    def close(self) -> None:
        """Let a posted cycle finish, then stop the helpers and wait for them."""
        try:
            self.join()
        finally:
            self._finalizer()


def _run(serve: Callable, ctl: np.ndarray, job: np.ndarray, gen0: np.int32, spins: int,
         args: tuple, errors: list) -> None:
    try:
        serve(ctl, job, gen0, spins, *args)
    except BaseException as exc:  # noqa: BLE001 - handed to the joiner, which raises it
        errors.append(exc)


def _stop(ctl: np.ndarray, threads: list[threading.Thread]) -> None:
    ctl[STOP] = 1
    post(ctl, np.zeros(2, dtype=np.int64), 0, 0)
    for t in threads:
        if t is not threading.current_thread():
            t.join()


__all__ = ["ComputeThreads", "await_post", "finished", "join", "post", "stopping", "JOB_A",
           "JOB_B"]
