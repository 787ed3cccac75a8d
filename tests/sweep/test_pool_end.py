"""A pool ended early (Ctrl-C in the loop over its results) leaves nothing that prints at
interpreter exit: its workers and its manager thread are gone when the block is left."""

from __future__ import annotations

import time

import pytest

from hil.workers.pools import process_pool


def test_an_interrupted_pool_leaves_no_manager_thread():
    """concurrent.futures' exit hook wakes every live manager thread through a pipe the
    thread closes as it ends; a thread still ending then made the hook write to a closed
    pipe ("OSError: [Errno 9] Bad file descriptor" after a sweep's interrupt line)."""
    with pytest.raises(KeyboardInterrupt):
        with process_pool(2) as pool:
            futures = [pool.submit(time.sleep, 30.0) for _ in range(2)]
            procs = list(pool._processes.values())
            manager = pool._executor_manager_thread
            raise KeyboardInterrupt
    assert manager is not None and not manager.is_alive()
    assert not any(p.is_alive() for p in procs)
    assert all(f.done() for f in futures)
