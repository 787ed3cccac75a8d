"""Deterministic multi-rate scheduler on one integer clock.

Time is an integer tick count (``tick_ns`` nanoseconds each, 50 us by default): the FPGA
runs every tick, the MCU every 4th, the PC every 20th, each at a declared period and phase.
The plant is continuous: between two ticks at which any task runs, it is advanced in one
compiled call, with its inputs held.

At tick ``t`` the order is fixed: the plant has already been integrated up to ``t``; then
every task due at ``t`` runs in registration order (register in data-flow order: sensors
first, controllers after), reading outputs at ``t`` and setting inputs that act from ``t``
on. Nothing reads the wall clock, so the same configuration and seed give bit-identical
records.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.sim.interfaces import Ticked
from plant.layout import N_OUTPUTS, OUTPUT_NAMES

TaskFn = Callable[[int], None]


@dataclass
class Task:
    """A discrete block: ``fn(tick)`` runs when ``(tick - phase) % period == 0``."""

    name: str
    period: int
    phase: int
    fn: TaskFn

    def next_due(self, tick: int) -> int:
        """First tick >= ``tick`` at which this task runs."""
        k = tick - self.phase
        if k <= 0:
            return self.phase
        return self.phase + -(-k // self.period) * self.period


@dataclass
class Probe:
    """A scalar signal sampled by a task-like getter at its own period."""

    name: str
    period: int
    phase: int
    getter: Callable[[], float]
    ticks: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    count: int = 0


@dataclass
class Record:
    """What a run recorded: plant outputs at a fixed decimation, and probes."""

    tick_ns: int
    plant_ticks: np.ndarray
    plant: np.ndarray  # rows x OUTPUT_NAMES
    probes: dict[str, tuple[np.ndarray, np.ndarray]]

    def t(self) -> np.ndarray:
        """Times of the plant rows, s."""
        return self.plant_ticks * (self.tick_ns * 1e-9)

    def col(self, name: str) -> np.ndarray:
        """A plant output column by name (see ``plant.layout.OUTPUT_NAMES``)."""
        return self.plant[:, OUTPUT_NAMES.index(name)]

    def probe(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(times in s, values) of a probe."""
        ticks, values = self.probes[name]
        return ticks * (self.tick_ns * 1e-9), values


class Scheduler:
    """Runs a plant and discrete tasks on an integer tick clock."""

    def __init__(self, plant: Ticked, record_every: int = 1) -> None:
        if record_every < 0:
            raise ValueError("record_every must be >= 0 (0 = record nothing)")
        self.plant = plant
        self.tick_ns = plant.tick_ns
        self.tasks: list[Task] = []
        self.probes: list[Probe] = []
        self.record_every = record_every

    def ticks(self, seconds: float) -> int:
        """Whole ticks in ``seconds`` (rounded to nearest)."""
        return int(round(seconds * 1e9 / self.tick_ns))

    def every(self, period: int, fn: TaskFn, name: str = "", phase: int = 0) -> Task:
        """Register ``fn(tick)`` to run every ``period`` ticks, offset by ``phase``."""
        if period < 1 or not 0 <= phase < period:
            raise ValueError(f"task {name or fn!r}: need period >= 1 and 0 <= phase < period")
        task = Task(name or getattr(fn, "__name__", "task"), period, phase, fn)
        self.tasks.append(task)
        return task

    def probe(self, name: str, getter: Callable[[], float], period: int, phase: int = 0) -> None:
        """Record ``getter()`` every ``period`` ticks under ``name``."""
        if any(p.name == name for p in self.probes):
            raise ValueError(f"probe {name!r} registered twice")
        self.probes.append(Probe(name, period, phase, getter))

    def run(self, n_ticks: int, progress: bool = False, label: str = "run") -> Record:
        """Run ``n_ticks`` ticks from the plant's current tick and return the record."""
        plant = self.plant
        start = plant.tick
        end = start + n_ticks
        every = self.record_every
        if every:
            first = start // every + 1
            n_rows = max(0, end // every - first + 1)
            rec = np.zeros((n_rows, N_OUTPUTS))
            rec_ticks = np.arange(first, first + n_rows, dtype=np.int64) * every
        else:
            rec = np.zeros((0, N_OUTPUTS))
            rec_ticks = np.zeros(0, dtype=np.int64)
        probe_fns: list[tuple[Task, Probe]] = []
        for pr in self.probes:
            n = len(range(Task(pr.name, pr.period, pr.phase, _noop).next_due(start), end,
                          pr.period))
            pr.ticks = np.zeros(n, dtype=np.int64)
            pr.values = np.zeros(n)
            pr.count = 0
            probe_fns.append((Task(pr.name, pr.period, pr.phase, _probe_fn(pr)), pr))
        tasks = self.tasks + [t for t, _ in probe_fns]
        # Bound each plant call so that progress can be shown on long runs.
        chunk = max(1, min(n_ticks // 50 or 1, 20000)) if progress else n_ticks or 1
        next_report = start
        row = 0
        t = start
        next_due = [task.next_due(t) for task in tasks]
        while t < end:
            for i, task in enumerate(tasks):
                if next_due[i] == t:
                    task.fn(t)
                    next_due[i] = t + task.period
            nxt = min(min(next_due, default=end), end, t + chunk)
            row = plant.advance(nxt - t, rec, row, every or 1)
            t = nxt
            if progress and t >= next_report:
                frac = (t - start) / max(n_ticks, 1)
                print(f"\r{label}: {100 * frac:5.1f} %", end="", file=sys.stderr, flush=True)
                next_report = t + max(n_ticks // 20, 1)
        if progress:
            print(file=sys.stderr)
        probes = {pr.name: (pr.ticks[: pr.count], pr.values[: pr.count]) for pr in self.probes}
        return Record(self.tick_ns, rec_ticks[:row], rec[:row], probes)


def _noop(_tick: int) -> None:
    return None


def _probe_fn(pr: Probe) -> TaskFn:
    def sample(tick: int) -> None:
        i = pr.count
        if i < pr.values.shape[0]:
            pr.ticks[i] = tick
            pr.values[i] = pr.getter()
            pr.count = i + 1

    return sample
