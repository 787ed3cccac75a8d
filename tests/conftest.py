"""Shared fixtures: configurations built from the shipped presets."""

from __future__ import annotations

import pytest

from plant.config import load_config


@pytest.fixture(scope="session")
def linear_cfg():
    """The thesis's linear model: every effect off."""
    return load_config("hydra_linear")


@pytest.fixture(scope="session")
def default_cfg():
    """The default preset, effects as shipped."""
    return load_config()


@pytest.fixture(autouse=True)
def _sigint_as_a_terminal_sends_it():
    """Each test starts with Ctrl-C handled as in a terminal (Python's default handler),
    and must leave it so (or as the command line installs it once per process,
    :func:`hil.cli.interrupts.install`). pytest-xdist's workers ignore SIGINT, and an ignored
    SIGINT is inherited by child processes: the tests of interrupted runs would otherwise
    pass or fail with the order the tests happen to run in."""
    import signal

    worker = signal.getsignal(signal.SIGINT)
    if worker is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    deferred = getattr(after, "__self__", None).__class__.__name__ == "DeferredInterrupt"
    signal.signal(signal.SIGINT, worker)
    if after is not before and not (before is signal.default_int_handler and deferred):
        pytest.fail(f"the test left the SIGINT handler changed: {before!r} -> {after!r}")


def pytest_configure(config):  # noqa: ANN001, ANN201 - pytest's hook
    """The cyclic garbage collector runs less often in the test processes. A worker's heap
    grows past a million objects (numba's typed functions, hypothesis, the modules of the
    whole project), and each full collection walks all of it: with Python's thresholds
    (700, 10, 10) a worker spent ~10 s of CPU in the collector over ``make test``, two
    thirds in ~20 full collections. With these, a third less; reference counting frees
    all but cyclic garbage as before, and the cycles are still collected."""
    import gc

    gc.set_threshold(7000, 10, 100)


def pytest_addoption(parser):  # noqa: ANN001, ANN201 - pytest's hook
    from tests.hypothesis_examples import MIN_EXAMPLES, fraction

    parser.addoption(
        "--examples-fraction", type=fraction, default=1.0, metavar="F",
        help="run each property test (hypothesis) with this fraction of its examples, at "
             f"least {MIN_EXAMPLES} (make test-fast: 0.25; make test runs them all)")


def pytest_collection_modifyitems(config, items):  # noqa: ANN001, ANN201 - pytest's hook
    """The test files that hold slow tests run first, each file's tests together and in
    their order. ``make test`` runs on two pytest-xdist workers that take work from each
    other (``--dist worksteal``): with the long tests first, the run ends on short tests
    and the workers finish together, instead of one waiting while the other runs a long
    test that happened to be collected last (tests/verify/ sorts after the rest).
    With ``--examples-fraction``, the property tests run that fraction of their examples."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)
    fraction = config.getoption("examples_fraction")
    if fraction < 1.0:
        from tests.hypothesis_examples import fewer_examples

        fewer_examples([getattr(item, "obj", None) for item in items], fraction)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):  # noqa: ANN001, ANN201 - pytest's hook
    """With ``EHA_HIL_TEST_CPU=FILE`` set, each test's CPU seconds (this process and the
    child processes it waited for, set-up and tear-down included: a module's fixtures are
    charged to its first test) are appended to FILE as ``user+sys<TAB>children<TAB>id``.
    The suite's budget is CPU on a loaded machine, where ``--durations`` (wall) misleads."""
    import os

    path = os.environ.get("EHA_HIL_TEST_CPU")
    if not path:
        return (yield)
    import resource

    def cpu() -> tuple[float, float]:
        me = resource.getrusage(resource.RUSAGE_SELF)
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime

    before = cpu()
    try:
        return (yield)
    finally:
        after = cpu()
        with open(path, "a") as fh:
            fh.write(f"{after[0] - before[0]:.3f}\t{after[1] - before[1]:.3f}\t{item.nodeid}\n")
