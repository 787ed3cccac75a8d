"""The per-cycle work outside the robot engine's compiled call: the master (frames out,
replies checked), the PC loop, the chain's frame handling, the engine's hand-offs (outputs
taken, inputs given, the cycle's bookkeeping), timed in the thread that runs them."""

from __future__ import annotations

import time


def python_per_cycle(bs, pc, cycles: int) -> float:  # noqa: ANN001 - a BusSystem, a PcFn
    """CPU seconds per cycle the calling thread spends outside the engine's compiled call,
    over ``cycles`` cycles of ``bs`` (its robot engine with one worker and no overlap, so
    that this thread runs every part and nothing runs beside it)."""
    eng = bs.chain.engine
    workers, overlap = eng.workers, eng.overlap
    eng.wait()
    eng.workers, eng.overlap = 1, False
    compiled = [0.0]
    compute = eng._compute

    def timed(*args, **kw):  # noqa: ANN002, ANN003, ANN202 - RobotEngine._compute's
        c0 = time.thread_time()
        try:
            return compute(*args, **kw)
        finally:
            compiled[0] += time.thread_time() - c0

    eng._compute = timed
    try:
        bs.run(2, pc, keep=0)
        compiled[0] = 0.0
        c0 = time.thread_time()
        bs.run(cycles, pc, keep=0)
        total = time.thread_time() - c0
    finally:
        del eng._compute
        eng.workers, eng.overlap = workers, overlap
    return (total - compiled[0]) / cycles
