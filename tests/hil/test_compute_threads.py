"""The compute threads that wait for each cycle in compiled code (hil.sim.compute_threads):
every posted cycle runs once on every helper, its writes are seen after the join, a helper
asleep in the futex is woken, a helper that fails or is gone makes the join raise (never
hang), and closing (or dropping) them ends the threads."""

from __future__ import annotations

import gc
import threading
import time

import numpy as np
import pytest
from numba import njit

from hil.sim import compute_threads as ct


@njit(nogil=True)
def _serve(ctl, job, seen, spins, out, k):
    """Helper ``k``: per posted cycle, ``out[k, :job[A]] += job[B]`` (written element by
    element, read by the joiner), and a division by ``job[B] - 7`` (a failure at 7)."""
    while True:
        seen = ct.await_post(ctl, seen, spins)
        if ct.stopping(ctl):
            return 0
        for i in range(job[ct.JOB_A]):
            out[k, i] += job[ct.JOB_B]
        out[k, -1] += 1 // (job[ct.JOB_B] - 7)
        ct.finished(ctl)


def _threads(helpers: int, **kw) -> tuple[ct.ComputeThreads, np.ndarray]:
    out = np.zeros((helpers, 65), dtype=np.int64)
    return ct.ComputeThreads(_serve, [(out, k) for k in range(helpers)], **kw), out


def test_every_cycle_runs_once_on_every_helper_and_its_writes_are_seen():
    th, out = _threads(2)
    try:
        want = np.zeros_like(out)
        for cycle in range(300):
            n, v = 1 + cycle % 64, cycle % 5 + 1  # (never 7: no failure)
            th.post(n, v)
            assert th.join()
            want[:, :n] += v
            # read right after the join: every write of the cycle is there
            np.testing.assert_array_equal(out[:, :-1], want[:, :-1])
    finally:
        th.close()


def test_a_helper_asleep_in_the_futex_is_woken():
    th, out = _threads(2, spins=0, join_spins=0)  # no spinning: every wait sleeps
    try:
        for _ in range(5):
            time.sleep(0.01)  # the helpers sleep in the futex by now
            th.post(3, 1)
            assert th.join(timeout_s=5.0), "a posted cycle did not wake the helpers"
        np.testing.assert_array_equal(out[:, :3], 5)
    finally:
        th.close()


def test_a_failing_helper_makes_the_join_raise_with_its_error():
    th, _ = _threads(1)
    th.post(1, 7)  # 1 // 0 in the helper
    with pytest.raises(RuntimeError, match="compute thread ended") as info:
        th.join(timeout_s=10.0)
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    th.close()


def test_close_ends_the_threads_and_a_later_cycle_raises():
    th, _ = _threads(2)
    th.post(2, 1)
    th.close()  # lets the posted cycle finish first
    assert not any(t.is_alive() for t in th.threads)
    th.post(2, 1)
    with pytest.raises(RuntimeError, match="compute thread ended"):
        th.join(timeout_s=10.0)


def test_dropped_threads_end():
    th, _ = _threads(2)
    threads = list(th.threads)
    del th
    gc.collect()
    for t in threads:
        t.join(timeout=10.0)
    assert not any(t.is_alive() for t in threads)
    assert not [t for t in threading.enumerate() if t.name.startswith("compute-")]


def test_a_join_with_nothing_posted_returns_and_a_second_post_is_refused():
    th, _ = _threads(1)
    try:
        assert th.join()
        th.post(1, 1)
        with pytest.raises(RuntimeError, match="posted already"):
            th.post(1, 1)
        assert th.join()
    finally:
        th.close()
