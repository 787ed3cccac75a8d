"""Real-time hygiene of a served chain (``serve --realtime``), each step per thread:

* the frame thread runs SCHED_FIFO (priority :data:`FRAME_PRIORITY`). It never busy-waits:
  it sleeps in ``poll`` until a frame arrives (or 1 ms passes) and spends tens of us per
  frame, so it stays far below the kernel's RT throttle (95 % of each second by default),
  which would otherwise stall every real-time task for the rest of the second;
* the box thread runs SCHED_FIFO below it (:data:`BOX_PRIORITY`, below a master's usual
  40 too) while it keeps its schedule: it sleeps to each cycle's absolute deadline, so its
  share of the CPU is its compute time. Once it computed :data:`DEMOTE_BUSY` of the last
  quarter second (a model slower than real time, running back to back) it drops to
  SCHED_OTHER until it is on schedule again: such a model falls behind (reported as lag)
  instead of running into the RT throttle and starving the machine, while a short stall
  (a few ms, caught up in tens of ms) is caught up at real-time priority;
* CPU affinity: with more than one CPU, the frame thread gets the last CPU and the box
  threads the others, so a compute burst never shares a core with a frame;
* ``mlockall``: every page of the process stays in memory (no page fault mid-frame);
* garbage collection: everything allocated before serving is frozen (``gc.freeze``) and
  the box loop runs with the collector off; the frame loop allocates nothing.

Each step that the system refuses (no CAP_SYS_NICE, no CAP_IPC_LOCK, ...) is reported in
one line and the run continues without it.
"""

from __future__ import annotations

import ctypes
import os

FRAME_PRIORITY = 50
BOX_PRIORITY = 20
#: The box thread drops to SCHED_OTHER when it was busy this share of the last quarter
#: second (a model slower than real time, catching up back to back).
DEMOTE_BUSY = 0.9
MCL_CURRENT, MCL_FUTURE = 1, 2


def cpus() -> list[int]:
    return sorted(os.sched_getaffinity(0))


def split_cpus() -> tuple[set[int] | None, set[int] | None]:
    """(frame CPUs, compute CPUs), or (None, None) on a single CPU."""
    c = cpus()
    if len(c) < 2:
        return None, None
    return {c[-1]}, set(c[:-1])


def compute_cpu_count(plan: RealtimePlan | None = None) -> int:
    """CPUs for the boxes' compute: the plan's compute CPUs, else all but one (the frames
    keep one), at least one."""
    if plan is not None and plan.compute_cpus is not None:
        return len(plan.compute_cpus)
    return max(1, len(cpus()) - 1)


def mlockall() -> str | None:
    """Lock every page; None, or why not."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        return f"mlockall: {os.strerror(ctypes.get_errno())}"
    return None


def fifo(priority: int = FRAME_PRIORITY) -> str | None:
    """SCHED_FIFO for the calling thread; None, or why not."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        return f"SCHED_FIFO {priority}: {exc}"
    return None


def other() -> None:
    """SCHED_OTHER for the calling thread."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass


def pin(cpu_set: set[int] | None) -> str | None:
    """The calling thread onto ``cpu_set`` (None: leave it); None, or why not."""
    if cpu_set is None:
        return None
    try:
        os.sched_setaffinity(0, cpu_set)
    except OSError as exc:
        return f"CPU affinity {sorted(cpu_set)}: {exc}"
    return None


class RealtimePlan:
    """What ``--realtime`` does, thread by thread; ``warnings`` collects refusals."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.frame_cpus, self.compute_cpus = split_cpus() if enabled else (None, None)
        self.warnings: list[str] = []
        self.applied: list[str] = []
        self._demoted = False
        #: Times the box thread dropped to SCHED_OTHER because it fell behind.
        self.demotions = 0

    def process(self) -> None:
        """The whole process: pages locked; the calling (main) thread at the box threads'
        priority, so that it is not preempted while it holds the interpreter lock."""
        if not self.enabled:
            return
        self._note(mlockall(), "mlockall")
        fifo(BOX_PRIORITY)

    def frame_thread(self) -> None:
        if not self.enabled:
            return
        self._note(fifo(), f"frame thread SCHED_FIFO {FRAME_PRIORITY}")
        self._note(pin(self.frame_cpus), f"frame thread on CPU {sorted(self.frame_cpus or [])}")

    def box_thread(self) -> None:
        if not self.enabled:
            return
        self._box_fifo = fifo(BOX_PRIORITY) is None
        if self._box_fifo:
            self.applied.append(f"box thread SCHED_FIFO {BOX_PRIORITY} while on schedule")
        self._note(pin(self.compute_cpus),
                   f"box threads on CPU {sorted(self.compute_cpus or [])}")

    def box_behind(self, cycles: int, busy: float) -> None:
        """Called by the box thread after each cycle with how many cycles it is behind and
        its busy share of the last quarter second."""
        if not self.enabled or not getattr(self, "_box_fifo", False):
            return
        if busy >= DEMOTE_BUSY and not self._demoted:
            other()
            self._demoted = True
            self.demotions += 1
        elif busy < DEMOTE_BUSY and self._demoted and cycles == 0:
            fifo(BOX_PRIORITY)
            self._demoted = False

    def _note(self, why_not: str | None, what: str) -> None:
        if why_not is None:
            self.applied.append(what)
        else:
            self.warnings.append(why_not)
