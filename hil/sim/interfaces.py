"""The interfaces the engines are built on, declared once (structural: a class implements
one by having its members, as :func:`isinstance` checks at run time).

* :class:`Ticked`: what advances on the integer clock, tick by tick, and shows its outputs:
  the plant (:class:`plant.model.Plant`), one actuator below the MCU
  (:class:`~hil.sim.actuator.FpgaStack`) and the same with faults injected
  (:class:`~hil.fieldbus.stack_faults.FaultyStack`). The scheduler runs any of them.
* :class:`BoardStack`: a :class:`Ticked` that is one actuator below the MCU, with its
  parts by name (what a box, the recorder and the robot engine use of it).
* :class:`McuProgram`: the MCU law a box runs on its links, as Python
  (:class:`firmware_model.mcu.mcu.Mcu`) or as the firmware's C built for the host
  (:class:`~hil.sim.mcu_c.CMcu`, ``--set mcu.impl=c``).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Ticked(Protocol):
    """Advances on the 50 us integer clock; ``y`` holds the plant's outputs (plant/layout)."""

    tick_ns: int
    tick_s: float

    @property
    def y(self) -> np.ndarray: ...

    @property
    def tick(self) -> int: ...

    @property
    def time_s(self) -> float: ...

    def advance(self, n_ticks: int, rec: np.ndarray | None = None, row0: int = 0,
                every: int = 1) -> int:
        """Advance ``n_ticks`` ticks, recording every ``every``-th tick's outputs into
        ``rec`` from row ``row0``; the next free row."""
        ...


@runtime_checkable
class BoardStack(Ticked, Protocol):
    """One actuator below the MCU: plant, sensor chips, driver board, LVDS link."""

    config: Any           # plant.config.Config
    plant: Any            # plant.model.Plant
    board: Any            # firmware_model.fpga.driver_board.DriverBoard
    mcu_link: Any         # firmware_model.fpga.driver_board.LinkMemory (the MCU's end)
    link: np.ndarray      # the LVDS link's state (firmware_model.lvds.link)
    chips: np.ndarray     # the sensor chips' parameters (plant.sensors.chips)

    def link_fault(self, direction: str = "down", stopped: bool | None = None,
                   corrupt_every: int | None = None, drop_every: int | None = None,
                   dup_every: int | None = None, delay_ticks: int | None = None) -> None: ...


@runtime_checkable
class McuProgram(Protocol):
    """The MCU law over the links of its driver boards (slot ``i``), and what the harness
    probes of it per slot: the measurements, the controller, the torque reference."""

    period: int           # MCU period in ticks (4: 5 kHz)
    meas: list[Any]       # per slot: the SI measurements (firmware_model.mcu.measure)
    ctrl: list[Any]       # per slot: the force controller (its filter state, strain_force)
    tau_ref: Any          # per slot: the torque reference, float32

    def command(self, i: int, mode: str, value: float, tick: int) -> None: ...

    def enable(self, i: int, angle_offset: int) -> None: ...

    def step(self, tick: int) -> None: ...


def members(protocol: type) -> tuple[str, ...]:
    """The names a protocol declares (attributes, properties and methods), its bases' too."""
    names: dict[str, None] = {}
    for cls in reversed(protocol.__mro__):
        if cls in (object, Protocol) or not getattr(cls, "_is_protocol", False):
            continue
        for n in (*getattr(cls, "__annotations__", {}), *vars(cls)):
            if not n.startswith("_"):
                names[n] = None
    return tuple(names)


__all__ = ["BoardStack", "McuProgram", "Ticked", "members"]
