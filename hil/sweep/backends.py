"""Where the points of a sweep run: one seam, three backends.

A backend maps a function over tasks and yields the results as they finish (any order; the
engine sorts by point number). The function must not raise (:func:`hil.sweep.point.evaluate`
records a failing point); what a backend itself loses (a worker that died) it reports
through ``on_lost(task, why)``, which makes a record of it.

* :class:`Serial` — in this process, one point after another (``--workers 1``);
* :class:`LocalPool` — a pool of worker processes on this machine (the default: one per
  core). Workers are started with ``spawn``: they share nothing with this process, and
  they ignore Ctrl-C, which this process handles by ending them and saying where it was;
* :class:`DaskCluster` — a ``dask.distributed`` cluster (``--dask tcp://host:8786``) or a
  ``LocalCluster`` (``--dask local``). Its workers need the same eha-hil installed.
"""

from __future__ import annotations

import logging
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, Protocol

Lost = Callable[[Any, str], Any]


class Backend(Protocol):
    """Runs ``fn`` on every task; yields results in the order they finish."""

    name: str

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any], on_lost: Lost
            ) -> Iterator[Any]: ...

    def close(self) -> None: ...


class BackendError(Exception):
    """A backend cannot start (no such scheduler, ...): one line for the user."""


def default_workers() -> int:
    """Every core this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class Serial:
    """Every point in this process, in order."""

    name = "serial"

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any], on_lost: Lost
            ) -> Iterator[Any]:
        for task in tasks:
            yield fn(task)

    def close(self) -> None:
        pass


def _worker_init() -> None:
    # (hil.workers.pools: Ctrl-C reaches the whole process group; the parent decides what happens)
    from hil import scenarios
    from hil.sweep.point import single_threaded_blas

    scenarios.names()  # import every scenario module once, before the first point
    single_threaded_blas()


class LocalPool:
    """A pool of ``workers`` processes on this machine."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self.name = f"local pool, {workers} workers"

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any], on_lost: Lost
            ) -> Iterator[Any]:
        from concurrent.futures import as_completed
        from concurrent.futures.process import BrokenProcessPool

        from hil.workers.pools import process_pool

        if not tasks:
            return
        # Interrupted or abandoned (the generator closed): the pool ends the workers now
        # rather than after their current point.
        with process_pool(min(self.workers, len(tasks)), _worker_init) as pool:
            futures = {pool.submit(fn, task): task for task in tasks}
            for fut in as_completed(futures):
                try:
                    yield fut.result()
                except BrokenProcessPool as exc:
                    yield on_lost(futures[fut], f"worker process died ({exc})")

    def close(self) -> None:
        pass


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while child processes start (an ignored signal stays ignored across
    exec, and Python keeps it so), unless this is not the main thread."""
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _eha_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("eha-hil")
    except PackageNotFoundError:
        return "not installed"


class DaskCluster:
    """A ``dask.distributed`` cluster: ``address`` of its scheduler, or ``local`` for a
    ``LocalCluster`` of ``workers`` single-threaded workers (``processes``: each its own
    process; False: threads of this process, for tests)."""

    def __init__(self, address: str, workers: int | None = None, processes: bool = True,
                 warn: Callable[[str], None] | None = None, timeout_s: float = 10.0) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - a dependency of the package
            raise BackendError("--dask: dask.distributed is not installed "
                               "(pip install 'dask[distributed]')") from None
        self.cluster = None
        try:
            if address == "local":
                with _sigint_ignored():  # its processes inherit it: Ctrl-C is ours to handle
                    self.cluster = LocalCluster(
                        n_workers=workers or default_workers(), threads_per_worker=1,
                        processes=processes, dashboard_address=None,
                        silence_logs=logging.ERROR)
                self.client = Client(self.cluster)
            else:
                self.client = Client(address, timeout=timeout_s)
        except (OSError, TimeoutError, ValueError) as exc:
            raise BackendError(f"--dask {address}: cannot connect: "
                               f"{' '.join(str(exc).split())}") from None
        self.name = f"dask {address}, {len(self.client.scheduler_info()['workers'])} workers"
        if address != "local" and warn:
            mine = _eha_version()
            theirs = set(self.client.run(_eha_version).values())
            if theirs - {mine}:
                warn(f"--dask {address}: workers run eha-hil {', '.join(sorted(theirs))}, "
                     f"this process {mine}; results follow the workers' code")

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any], on_lost: Lost
            ) -> Iterator[Any]:
        from distributed import as_completed

        if not tasks:
            return
        futures = self.client.map(fn, list(tasks), pure=False)
        by_key = {f.key: t for f, t in zip(futures, tasks, strict=True)}
        clean = False
        try:
            for fut in as_completed(futures):
                if fut.status == "finished":
                    yield fut.result()
                else:
                    exc = fut.exception()
                    yield on_lost(by_key[fut.key], f"{type(exc).__name__}: {exc}")
            clean = True
        finally:
            if not clean:
                self.client.cancel(futures)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_backend(workers: int | None, dask: str | None, processes: bool = True,
                 warn: Callable[[str], None] | None = None) -> Backend:
    """The backend the options ask for: ``--dask`` if given, else ``--workers`` (1: serial,
    default: a pool with a worker per core)."""
    if dask:
        return DaskCluster(dask, workers, processes, warn)
    n = workers or default_workers()
    return Serial() if n == 1 else LocalPool(n)
