"""``--realtime``'s plan per thread (:mod:`hil.sim.realtime`): the box thread keeps its
real-time priority through a short catch-up and drops it only when it computed nearly all
of the last quarter second (a model slower than real time), regaining it on schedule."""

from __future__ import annotations

import os
import threading

import pytest

from hil.sim.realtime import DEMOTE_BUSY, RealtimePlan


def _in_thread(fn):  # noqa: ANN001, ANN202 - run fn in a fresh thread (its own scheduling)
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))
    t.start()
    t.join()
    return out[0]


def test_box_thread_drops_real_time_only_when_busy():
    if not hasattr(os, "SCHED_FIFO"):
        pytest.skip("no SCHED_FIFO on this platform")
    plan = RealtimePlan(True)

    def run() -> list[int]:
        plan.box_thread()
        if not plan.applied or "SCHED_FIFO" not in plan.applied[0]:
            return []
        seen = [os.sched_getscheduler(0)]
        plan.box_behind(30, 0.5)              # far behind after a stall, not busy: stays
        seen.append(os.sched_getscheduler(0))
        plan.box_behind(3, DEMOTE_BUSY)       # busy a whole window: drops
        seen.append(os.sched_getscheduler(0))
        plan.box_behind(2, 0.5)               # not busy but still behind: stays dropped
        seen.append(os.sched_getscheduler(0))
        plan.box_behind(0, 0.5)               # on schedule again: back
        seen.append(os.sched_getscheduler(0))
        return seen

    seen = _in_thread(run)
    if not seen:
        pytest.skip(f"SCHED_FIFO refused here: {plan.warnings}")
    fifo, other = os.SCHED_FIFO, os.SCHED_OTHER
    assert seen == [fifo, fifo, other, other, fifo]
    assert plan.demotions == 1
