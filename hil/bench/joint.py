"""``eha-hil bench joint``: the hip joint through the whole stack (:mod:`hil.sim.hip_stack`)
against the wall clock and the CPU."""

from __future__ import annotations

from hil.bench.engines import TimedRun
from hil.sim.hip_stack import run_joint
from plant.config import Config


class JointBench(TimedRun):
    """Result of ``bench joint``: simulated, wall and CPU seconds."""


def bench_joint(cfg: Config, seconds: float = 1.0) -> JointBench:
    """Time the hip joint stack (PC loop + fieldbus + MCU + two coupled stacks + thigh)
    holding a 5 Hz 0.25 deg sine; a short run first compiles the kernels."""
    import math
    import time

    def ref(t: float) -> tuple[float, float]:
        return (math.radians(0.25) * math.sin(2 * math.pi * 5.0 * t), 0.0)

    run_joint(cfg, 0.01, ref)
    w0, c0 = time.perf_counter(), time.process_time()
    run_joint(cfg, seconds, ref)
    return JointBench(seconds, time.perf_counter() - w0, time.process_time() - c0)
