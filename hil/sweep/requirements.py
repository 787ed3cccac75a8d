"""The user's own requirements on a sweep's metrics (``--require 'NAME>=80'``).

A scenario judges its metrics against the thesis's figures; a robustness question often
has another bound ("which gains keep F5's bandwidth above 80 Hz", where the scenario's
"100 +/- 25 Hz" is a fidelity band). A ``--require`` replaces the scenario's judgement of
that metric; several on one metric must all hold. They are applied to the records when the
table is made, never stored in the journal: a finished sweep can be judged again with
``--resume --require ...`` without computing a point.
"""

from __future__ import annotations

import argparse
import copy
import math
import operator
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

_OPS: dict[str, Callable[[float, float], bool]] = {
    ">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}
_PATTERN = re.compile(r"^(?P<name>.+?)\s*(?P<op>>=|<=|>|<)\s*(?P<bound>[^<>=]+)$")


@dataclass(frozen=True)
class Requirement:
    metric: str
    op: str
    bound: float

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and _OPS[self.op](value, self.bound)

    def __str__(self) -> str:
        return f"{self.op} {self.bound:g}"


def parse_requirement(text: str) -> Requirement:
    """``METRIC>=BOUND`` (or ``<=``, ``>``, ``<``): the metric's name as the table shows it,
    without the unit."""
    m = _PATTERN.match(text.strip())
    if not m:
        raise argparse.ArgumentTypeError(f"{text!r}: expected METRIC>=BOUND (or <=, >, <)")
    try:
        bound = float(m["bound"])
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: {m['bound']!r} is not a number") from None
    if not math.isfinite(bound):
        raise argparse.ArgumentTypeError(f"{text!r}: need a finite bound")
    return Requirement(m["name"].strip(), m["op"], bound)


def apply(records: list[dict[str, Any]], reqs: list[Requirement]) -> list[dict[str, Any]]:
    """Copies of ``records`` with the required metrics judged by ``reqs``; ValueError names
    a metric no record has."""
    if not reqs:
        return records
    names = {m["name"] for r in records for m in r["metrics"]}
    for req in reqs:
        if names and req.metric not in names:
            raise ValueError(f"--require {req.metric!r}: no such metric (the scenario's are: "
                             f"{', '.join(sorted(names))})")
    by_metric: dict[str, list[Requirement]] = {}
    for req in reqs:
        by_metric.setdefault(req.metric, []).append(req)
    out = copy.deepcopy(records)
    for rec in out:
        for m in rec["metrics"]:
            mine = by_metric.get(m["name"])
            if mine:
                m["requirement"] = " and ".join(map(str, mine)) + " (--require)"
                m["ok"] = all(req.holds(m["value"]) for req in mine)
        judged = [m["ok"] for m in rec["metrics"] if m["ok"] is not None]
        rec["ok"] = all(judged) if judged else None
    return out
