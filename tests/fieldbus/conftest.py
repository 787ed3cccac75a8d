"""Shared helpers of the fieldbus tests: configuration, topologies, PC loops."""

from __future__ import annotations

import math

import pytest

from hil.fieldbus.topology import load_topology
from plant.config import load_config


@pytest.fixture(scope="session")
def cfg():
    return load_config("hydra_default")


@pytest.fixture(scope="session")
def full():
    return load_topology("hydra_full")


@pytest.fixture(scope="session")
def bench():
    return load_topology("bench_one_box")


def force_profile(cycle: int, m) -> None:
    """Bench PC loop: a 300 N step then a 20 Hz sine about it."""
    f = 300.0 + (200.0 * math.sin(2 * math.pi * 20.0 * (cycle - 100) * 1e-3) if cycle >= 100
                 else 0.0)
    m.set_actuator(0, "force", f)


def full_robot_pc(cycle: int, m) -> None:
    """Full-robot PC loop: every actuator its own force, changing each cycle."""
    for j in range(len(m.act_offsets)):
        m.set_actuator(j, "force", 10.0 * (j + 1) + 0.01 * cycle)
