"""Box faults: the LVDS link and the sensors of a StackBox's actuator, switched on and off
at the windows a fault plan (:mod:`hil.fieldbus.faults`) declares. The faulty stack stands
in for one :class:`~hil.sim.actuator.FpgaStack` of the box (docs/fieldbus-faults.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from hil.fieldbus.faults import (
    CYCLE_TICKS,
    SENSOR_SIGNALS,
    Fault,
    FaultError,
    FaultPlan,
    check_topology,
)
from hil.sim.interfaces import BoardStack, members

if TYPE_CHECKING:
    from hil.sim.actuator import FpgaStack


def _dead_value(signal: str, k: np.ndarray) -> float:
    """Physical value whose chip code is 0 (for the ADC channels and the strain gauge)."""
    from plant.sensors.current_sense import zero_code_current
    from plant.sensors.pressure_sensors import zero_code_pressure, zero_code_temperature
    from plant.sensors.strain_gauge import zero_code_force

    chip = SENSOR_SIGNALS[signal][1]
    zero = {"pressure": zero_code_pressure, "temperature": zero_code_temperature,
            "current": zero_code_current, "strain": zero_code_force}
    if chip not in zero:
        raise AssertionError(signal)
    return zero[chip](k)


class FaultyStack:
    """Stands in for one :class:`~hil.sim.actuator.FpgaStack` of a StackBox: the LVDS faults
    are switched at cycle boundaries; while a sensor fault is active the stack advances
    tick by tick and the faulted plant outputs are overwritten just before each tick's
    sensor chips read them (the plant recomputes its outputs from its state every tick, so
    nothing else sees the override).

    It holds the stack (:attr:`stack`) and is a :class:`~hil.sim.interfaces.BoardStack`
    itself: ``advance`` is its own; every other member the interface declares reads the
    wrapped stack's (made below from the declaration, so none is forwarded by hand or
    forgotten). Anything else is reached through :attr:`stack`."""

    def __init__(self, stack: FpgaStack, faults: tuple[Fault, ...]) -> None:
        from plant import layout as L

        self.stack = stack
        self.lvds = [f for f in faults if f.link.startswith("lvds")]
        self.sensors = [f for f in faults if f.link == "sensor"]
        self._rows = [getattr(L, SENSOR_SIGNALS[f.signal][0]) for f in self.sensors]
        self._rngs = [np.random.default_rng(f.seed) for f in self.sensors]
        self._stuck: list[float | None] = [f.value for f in self.sensors]
        self._dead = [_dead_value(f.signal, stack.chips)
                      if f.kind == "dead" and SENSOR_SIGNALS[f.signal][1] != "encoder" else 0.0
                      for f in self.sensors]
        # Dead encoders are a chip flag (no valid frame), not a plant value.
        from plant.sensors import chips as sc

        self._enc_flag = [(sc.K_MOTOR_DEAD if f.signal == "theta_m" else sc.K_PISTON_DEAD)
                          if f.kind == "dead" and SENSOR_SIGNALS[f.signal][1] == "encoder"
                          else -1 for f in self.sensors]
        self._lvds_on = [False] * len(self.lvds)
        self.sensor_ticks = 0  # ticks run with a sensor fault applied

    def _switch_lvds(self, cycle: int) -> None:
        for i, f in enumerate(self.lvds):
            on = f.active(cycle)
            if on == self._lvds_on[i]:
                continue
            self._lvds_on[i] = on
            direction = f.link.split(".")[1]
            every = max(1, round(1.0 / f.rate)) if on else 0
            if f.kind == "dead":
                self.stack.link_fault(direction, stopped=on)
            elif f.kind == "bitflip":
                self.stack.link_fault(direction, corrupt_every=every)
            elif f.kind == "drop":
                self.stack.link_fault(direction, drop_every=every)
            elif f.kind == "duplicate":
                self.stack.link_fault(direction, dup_every=every)
            else:
                self.stack.link_fault(direction, delay_ticks=f.delay_ticks if on else 0)

    def advance(self, n_ticks: int, *args: Any, **kw: Any) -> int:
        st = self.stack
        self._switch_lvds(st.tick // CYCLE_TICKS)
        if not self.sensors:
            return st.advance(n_ticks, *args, **kw)
        row = 0
        trace = kw.get("trace")
        for j in range(n_ticks):
            one = {} if trace is None else {"trace": trace[j:j + 1]}
            cycle = st.tick // CYCLE_TICKS
            active = [i for i, f in enumerate(self.sensors) if f.active(cycle)]
            for i, flag in enumerate(self._enc_flag):
                if flag >= 0:
                    st.chips[flag] = 1.0 if i in active else 0.0
            if not active:
                row = st.advance(1, **one)
                continue
            y = st.plant.y
            for i in active:
                f, r = self.sensors[i], self._rows[i]
                if self._enc_flag[i] >= 0:
                    continue
                if f.kind == "stuck":
                    if self._stuck[i] is None:
                        self._stuck[i] = float(y[r])
                    y[r] = self._stuck[i]
                elif f.kind == "noisy":
                    y[r] = y[r] + f.sigma * self._rngs[i].standard_normal()
                else:
                    y[r] = self._dead[i]
            row = st.advance(1, **one)
            self.sensor_ticks += 1
        return row


def _forward(name: str) -> property:
    return property(lambda self: getattr(self.stack, name),
                    doc=f"The wrapped stack's ``{name}``.")


for _name in members(BoardStack):
    if _name not in vars(FaultyStack):
        setattr(FaultyStack, _name, _forward(_name))


def install_box_faults(chain: Any, plan: FaultPlan) -> list[FaultyStack]:
    """Put the LVDS and sensor faults on the StackBoxes of an in-process chain."""
    from hil.fieldbus.boxes import StackBox

    check_topology(plan, chain.topology)
    out = []
    for b, box in enumerate(chain.boxes):
        mine = [f for f in plan.box_faults if f.box == b]
        if not mine:
            continue
        if not isinstance(box, StackBox):
            raise FaultError(f"{plan.where}: {mine[0].name}: LVDS and sensor faults need the "
                             f"stack box model, box {b} runs {type(box).__name__}")
        for i, k in enumerate(box.act):
            here = tuple(f for f in mine if f.slot == k)
            if here:
                box.stacks[i] = FaultyStack(box.stacks[i], here)
                out.append(box.stacks[i])
    return out
