"""One point of a sweep: base configuration + overrides -> scenario run -> a plain record.

:func:`evaluate` is what every backend runs, in this process or another one: a pure
function of its :class:`Task` (the configuration and, through ``sim.seed``, the noise). It
never raises for a failing point: the error is the record's ``error`` field, so one bad
point never ends a sweep. The linear algebra runs on one BLAS thread in every backend, so a
result cannot depend on how many threads a library chose in one process or another.

A record is a dict of JSON types (the journal stores it as it is)::

    {"point": 3, "sample": 1 or None, "params": {"mcu.kp_force": 2.0, ...},
     "metrics": [{"name", "value", "unit", "requirement", "ok"}, ...],
     "ok": True/False/None, "error": "" or "ValueError: ...", "cpu_s": 1.23}
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

from hil.scenarios.knobs import split_overrides
from hil.sweep.space import Point
from plant.config import Config

_blas_limited = False


@dataclass(frozen=True)
class Task:
    """What a worker needs for one point (picklable: plain data)."""

    scenario: str
    base: Config
    point: Point


def single_threaded_blas() -> None:
    """Hold BLAS to one thread in this process, for good (a worker's or a serial sweep's)."""
    global _blas_limited
    if not _blas_limited:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")
        _blas_limited = True


def _plain(value: Any) -> Any:
    """A metric value as a JSON number (numpy scalars -> float, bools -> float)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def evaluate(task: Task) -> dict[str, Any]:
    """Run the task's scenario on its configuration; the record (see the module docstring)."""
    from hil import scenarios

    single_threaded_blas()
    point = task.point
    record: dict[str, Any] = {"point": point.index, "sample": point.sample,
                              "params": dict(point.overrides), "metrics": [], "ok": None,
                              "error": ""}
    c0 = time.process_time()
    try:
        where = f"sweep point {point.index}"
        config, knob_values = split_overrides(point.overrides)
        cfg = task.base.with_overrides(config, where)
        res = scenarios.get(task.scenario).call(cfg, None, knob_values, where)
        record["metrics"] = [
            {"name": m.name, "value": _plain(m.value), "unit": m.unit,
             "requirement": m.requirement, "ok": None if m.ok is None else bool(m.ok)}
            for m in res.metrics]
        judged = [m["ok"] for m in record["metrics"] if m["ok"] is not None]
        record["ok"] = all(judged) if judged else None
    except Exception as exc:  # noqa: BLE001 - a failing point is a result, not the end
        text = " ".join(str(exc).split()) or "(no message)"
        record["error"] = f"{type(exc).__name__}: {text}"
    record["cpu_s"] = time.process_time() - c0
    return record
