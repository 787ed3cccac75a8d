"""The declared interfaces of the engines (hil/sim/interfaces.py): the plant, the driver-board
stack, the faulty stack and the MCU law's Python and C builds each implement theirs, and the
faulty stack forwards exactly what the interface declares."""

from __future__ import annotations

import pytest

from firmware_model.mcu.mcu import Mcu
from hil.fieldbus.faults import parse_faults
from hil.fieldbus.stack_faults import FaultyStack
from hil.sim.actuator import FpgaStack
from hil.sim.interfaces import BoardStack, McuProgram, Ticked, members
from plant.model import Plant


def _faulty(cfg) -> FaultyStack:  # noqa: ANN001
    plan = parse_faults({"fault": [{"link": "sensor", "signal": "p_cyl_a", "kind": "stuck",
                                    "box": 0, "slot": 0}]}, "test")
    return FaultyStack(FpgaStack(cfg), tuple(plan.box_faults))


def test_the_plant_and_the_stacks_are_ticked(default_cfg):
    assert isinstance(Plant(default_cfg), Ticked)
    assert isinstance(FpgaStack(default_cfg), BoardStack)
    assert isinstance(_faulty(default_cfg), BoardStack)
    assert not isinstance(Plant(default_cfg), BoardStack)  # no board, no link


def test_the_faulty_stack_forwards_every_declared_member_to_its_stack(default_cfg):
    fs = _faulty(default_cfg)
    for name in members(BoardStack):
        if name == "advance":  # its own: the faults are applied there
            assert "advance" in vars(FaultyStack)
            continue
        mine, theirs = getattr(fs, name), getattr(fs.stack, name)
        assert mine is theirs or mine == theirs, name
    fs.advance(20)
    assert fs.tick == fs.stack.tick == 20


def test_a_class_missing_a_member_is_not_the_interface():
    class NoTick:
        tick_ns, tick_s, y, time_s = 50_000, 5e-5, None, 0.0

        def advance(self, n_ticks, rec=None, row0=0, every=1):  # noqa: ANN001, ANN201
            return 0

    assert not isinstance(NoTick(), Ticked)
    NoTick.tick = 0
    assert isinstance(NoTick(), Ticked)


def test_the_mcu_laws_are_mcu_programs(default_cfg):
    stack = FpgaStack(default_cfg)
    assert isinstance(Mcu(default_cfg, [stack.mcu_link]), McuProgram)
    from hil.sim import mcu_builds

    if mcu_builds.missing_tools("host-c"):
        pytest.skip("no host C compiler: the C build is not made here")
    from hil.sim.mcu_c import CMcu

    c = CMcu(default_cfg, [stack.mcu_link])
    assert isinstance(c, McuProgram)
