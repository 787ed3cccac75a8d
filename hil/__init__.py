"""The harness: engines, fieldbus, transports, logs, replay, scenarios, identification,
sweeps, verification, benchmarks and the command line, one room each (docs/architecture.md).

Light on purpose: the console script imports this package before anything else. Each room
with numba kernels imports :mod:`firmware_model.jit_cache` in its own ``__init__``, before
any kernel is defined (``tests/hil/test_jit_cache.py`` checks that none is missed).
"""
