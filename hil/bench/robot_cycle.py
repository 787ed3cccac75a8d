"""Where a robot run's CPU goes, by thread: the calling thread's compiled calls
(:meth:`RobotEngine._compute`), the rest of the calling thread (the master, the PC loop,
the chain's frame handling, the engine's hand-offs: outputs taken, inputs given, the
cycle's bookkeeping) and the engine's helper threads (their share of each cycle's compiled
call, their spins and sleeps between cycles)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass


@dataclass
class CpuSplit:
    """CPU seconds of a run's threads (see the module's docstring)."""

    compiled_s: float = 0.0  #: the calling thread's compiled calls
    calling_s: float = 0.0   #: the calling thread, all of it
    helpers_s: float = 0.0   #: the helper threads, all of them

    @property
    def python_s(self) -> float:
        """The calling thread outside its compiled calls."""
        return self.calling_s - self.compiled_s


def _thread_cpu(thread) -> float:  # noqa: ANN001 - a threading.Thread
    return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))


@contextmanager
def cpu_split(eng) -> Iterator[CpuSplit]:  # noqa: ANN001 - a RobotEngine
    """Time the block's run of ``eng`` by thread (run it in this thread); the split is
    filled in when the block ends, after the engine's last cycle has been joined. Costs
    two reads of the thread's clock per cycle (~0.3 us)."""
    split = CpuSplit()
    compute = eng._compute

    def timed(*args, **kw):  # noqa: ANN002, ANN003, ANN202 - RobotEngine._compute's
        c0 = time.thread_time()
        try:
            return compute(*args, **kw)
        finally:
            split.compiled_s += time.thread_time() - c0

    eng.wait()
    threads = list(eng._threads.threads) if eng._threads is not None else []
    h0 = [_thread_cpu(t) for t in threads]
    eng._compute = timed
    c0 = time.thread_time()
    try:
        yield split
    finally:
        del eng._compute
        eng.wait()
        split.calling_s = time.thread_time() - c0
        now = eng._threads.threads if eng._threads is not None else []
        if list(now) == threads:  # (made again during the run: not counted)
            split.helpers_s = sum(_thread_cpu(t) - c for t, c in zip(threads, h0, strict=True))


def python_per_cycle(bs, pc, cycles: int, repeats: int = 3) -> float:  # noqa: ANN001
    """CPU seconds per cycle the calling thread spends outside the engine's compiled call,
    best of ``repeats`` runs of ``cycles`` cycles of ``bs`` (a BusSystem; ``pc``: its PC
    loop) with its robot engine on one worker, so that this thread runs every part and
    nothing runs beside it."""
    eng = bs.chain.engine
    eng.wait()
    workers, eng.workers = eng.workers, 1
    best = float("inf")
    try:
        bs.run(2, pc, keep=0)
        for _ in range(repeats):
            with cpu_split(eng) as split:
                bs.run(cycles, pc, keep=0)
            best = min(best, split.python_s / cycles)
    finally:
        eng.workers = workers
    return best
