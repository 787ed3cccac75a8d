"""Run a sweep: the plan's points not yet in the journal, on a backend, in any order.

The engine owns what every backend shares: skipping the points a resumed journal holds,
journaling each record as it arrives, progress, and the records sorted by point number at
the end. Ctrl-C (KeyboardInterrupt) passes through after the backend has stopped its
workers; every point finished before it is in the journal.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hil.sweep.backends import Backend
from hil.sweep.journal import Journal
from hil.sweep.point import Task, evaluate
from hil.sweep.space import Plan
from plant.config import Config


@dataclass
class Progress:
    """Where a sweep is: points done of all, failed ones, and the time of this run."""

    total: int
    resumed: int = 0
    computed: int = 0
    failed: int = 0
    started: float = field(default_factory=time.perf_counter)

    @property
    def done(self) -> int:
        return self.resumed + self.computed

    @property
    def elapsed_s(self) -> float:
        return time.perf_counter() - self.started

    @property
    def eta_s(self) -> float | None:
        """Seconds left at this run's pace so far (None before the first point)."""
        if not self.computed:
            return None
        return self.elapsed_s / self.computed * (self.total - self.done)


@dataclass
class Outcome:
    """What a sweep produced: every record (sorted by point) and how it got them."""

    records: list[dict[str, Any]]
    computed: int
    resumed: int
    wall_s: float
    backend: str


#: How the error of a point its backend lost begins.
LOST = "lost: "


def lost_record(task: Task, why: str) -> dict[str, Any]:
    """The record of a point its backend lost (a worker died): an error, like a raise."""
    p = task.point
    return {"point": p.index, "sample": p.sample, "params": dict(p.overrides), "metrics": [],
            "ok": None, "error": LOST + why, "cpu_s": 0.0}


def run_sweep(scenario: str, base: Config, plan: Plan, backend: Backend,
              journal: Journal | None = None, resume: bool = False,
              on_point: Callable[[dict[str, Any], Progress], None] | None = None,
              fn: Callable[[Task], dict[str, Any]] = evaluate) -> Outcome:
    """Evaluate every point of ``plan`` (those a resumed ``journal`` lacks) on ``backend``.

    ``on_point(record, progress)`` is called after each point is journaled (and once with
    None before the first, with the resumed count known)."""
    total = len(plan.points)
    done: dict[int, dict[str, Any]] = {}
    if journal is not None:
        done = journal.start(plan.fingerprint(scenario, base), scenario, total, resume)
        # A point a backend lost (a worker died) is run again; one that raised is not: it
        # would raise again.
        done = {i: r for i, r in done.items()
                if i < total and not r.get("error", "").startswith(LOST)}
    prog = Progress(total, resumed=len(done))
    prog.failed = sum(1 for r in done.values() if r.get("error"))
    if on_point:
        on_point(None, prog)
    tasks = [Task(scenario, base, p) for p in plan.points if p.index not in done]
    try:
        for record in backend.map(fn, tasks, lost_record):
            if journal is not None:
                journal.append(record)
            done[record["point"]] = record
            prog.computed += 1
            prog.failed += bool(record.get("error"))
            if on_point:
                on_point(record, prog)
    finally:
        if journal is not None:
            journal.close()
    return Outcome([done[i] for i in sorted(done)], prog.computed, prog.resumed,
                   prog.elapsed_s, backend.name)
