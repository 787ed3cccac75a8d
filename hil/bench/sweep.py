"""``eha-hil bench sweep``: the local process pool against a serial sweep.

The same sweep (a scenario over ``points`` noise seeds) runs serially in this process and
on a pool of worker processes. Wall time by ``time.perf_counter``; CPU time of this process
by ``time.process_time`` plus, for the pool, that of its workers (``RUSAGE_CHILDREN``: the
spawned workers are this process's children, counted once the pool has joined them), so
the pool's cost of starting workers and loading the compiled kernels in each shows. The
serial run goes first, after one untimed point that loads the kernels in this process.
"""

from __future__ import annotations

import json
import os
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass

from hil.sweep.backends import LocalPool, Serial, default_workers
from hil.sweep.engine import Outcome, run_sweep
from hil.sweep.point import Task, evaluate
from hil.sweep.space import build_plan
from plant.config import Config


@dataclass
class BenchRun:
    backend: str
    wall_s: float
    cpu_s: float          # this process, and the pool's workers
    cpu_points_s: float   # inside the points alone (what the scenario costs)


@dataclass
class SweepBench:
    runs: list[BenchRun]
    identical: bool
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    cores: int

    @property
    def speedup_wall(self) -> float:
        return self.runs[0].wall_s / self.runs[1].wall_s

    @property
    def cpu_ratio(self) -> float:
        return self.runs[1].cpu_s / self.runs[0].cpu_s


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _timed(scenario: str, base: Config, plan, backend) -> tuple[BenchRun, Outcome]:
    c0, k0, t0 = time.process_time(), _children_cpu(), time.perf_counter()
    out = run_sweep(scenario, base, plan, backend)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0 + _children_cpu() - k0
    points = sum(r["cpu_s"] for r in out.records)
    return BenchRun(backend.name, wall, cpu, points), out


def bench_sweep(scenario: str, base: Config, points: int, workers: int | None = None,
                say: Callable[[str], None] = lambda m: None) -> SweepBench:
    """Serial, then a pool of ``workers`` (default: one per core), on the same sweep."""
    from hil.sweep.space import parse_seeds

    plan = build_plan(base, seeds=parse_seeds(f"0..{points - 1}"))
    load_before = os.getloadavg()
    say(f"bench sweep: warming up {scenario} in this process ...")
    evaluate(Task(scenario, base, plan.points[0]))
    say(f"serial: {points} points ...")
    serial, s_out = _timed(scenario, base, plan, Serial())
    pool = LocalPool(workers or default_workers())
    say(f"{pool.name}: {points} points ...")
    pooled, p_out = _timed(scenario, base, plan, pool)

    def strip(records: list[dict]) -> str:  # as JSON: NaN equals NaN there
        return json.dumps([{k: v for k, v in r.items() if k != "cpu_s"} for r in records])

    same = strip(s_out.records) == strip(p_out.records)
    return SweepBench([serial, pooled], same, load_before, os.getloadavg(),
                      default_workers())
