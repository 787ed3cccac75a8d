"""pytest-benchmark cases for the plant's per-tick path.

The suite runs with ``--benchmark-disable`` (each case once, as a smoke test); time them with
``.venv/bin/python -m pytest tests/bench --benchmark-enable``. No timing is asserted.
"""

from __future__ import annotations

from plant.model import Plant


def test_plant_kernel_one_second(benchmark, default_cfg):
    plant = Plant(default_cfg)
    plant.set_current(5.0)
    plant.advance(10)  # compile outside the measurement
    benchmark(plant.advance, 20000)
    assert plant.tick > 20000


def test_plant_single_tick_calls(benchmark, default_cfg):
    """The cost of a Python-side call per tick, as a tick-rate task in the loop pays it."""
    plant = Plant(default_cfg)
    plant.advance(1)

    def thousand_ticks() -> None:
        for _ in range(1000):
            plant.advance(1)

    benchmark(thousand_ticks)
