"""``mcu.impl = "c"``: the C law (host build) in the whole stack in place of the Python
MCU gives the same plant, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from hil.sim import mcu_builds
from hil.sim.actuator import ActuatorStack
from plant.config import ConfigError, load_config


def _command(t_s: float) -> tuple[str, float]:
    return "force", 300.0 if t_s % 0.1 < 0.05 else -200.0


@pytest.mark.parametrize("feedback", ["complementary", "strain"])
def test_stack_with_the_c_mcu_is_bit_identical(feedback):
    if mcu_builds.missing_tools("host-c"):
        pytest.skip("no host C compiler (make system-deps)")
    runs = {}
    for impl in ("python", "c"):
        cfg = load_config(None, (f"mcu.impl={impl}", f"mcu.force_feedback={feedback}"))
        stack = ActuatorStack(cfg, _command)
        runs[impl] = stack.run(0.15)
    a, b = runs["python"], runs["c"]
    assert type(ActuatorStack(load_config(None, ("mcu.impl=c",)), _command).mcu).__name__ \
        == "CMcu"
    assert np.array_equal(a.plant, b.plant)
    assert np.abs(a.plant).max() > 0
    for name in a.probes:
        assert np.array_equal(a.probe(name)[1], b.probe(name)[1]), name


def test_mcu_impl_takes_only_known_values():
    with pytest.raises(ConfigError):
        load_config(None, ("mcu.impl=rust",))
