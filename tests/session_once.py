"""An expensive fixture value made once per test session, not once per pytest-xdist worker.

A module-scoped fixture runs on every worker that runs one of the module's tests, and
``--dist worksteal`` hands a module's tests to both workers whenever one runs out of work.
:func:`made_once` keeps the value on disk in the session's base temporary directory (shared
by the workers of one run, fresh for each run): the first worker to ask makes it under an
exclusive ``fcntl.flock``, the others wait on the lock and read the pickle it left.
"""

from __future__ import annotations

import fcntl
import os
import pickle
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

T = TypeVar("T")


def session_dir(factory: pytest.TempPathFactory) -> Path:
    """The run's base temporary directory: each xdist worker's is a sub-directory of it."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def made_once(factory: pytest.TempPathFactory, name: str, make: Callable[[Path], T]) -> T:
    """``make(directory)``'s value, computed by one process of the run: its files go in
    ``directory`` (kept for the whole run), its value must pickle. After a ``make`` that
    raised, the next process to ask makes it again, in an emptied directory."""
    root = session_dir(factory)
    where = root / f"once-{name}"
    done = where / "value.pickle"
    with open(root / f"once-{name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if done.exists():
            return pickle.loads(done.read_bytes())
        shutil.rmtree(where, ignore_errors=True)
        where.mkdir()
        value = make(where)
        part = done.with_suffix(".part")
        part.write_bytes(pickle.dumps(value))
        part.replace(done)
        return value
