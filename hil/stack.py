"""The full single-actuator stack: plant + driver board + LVDS link + MCU, on the scheduler.

The MCU runs every ``mcu.period_ticks`` ticks (5 kHz) on what the link brought up; a PC-side
command function runs at 1 kHz and hands the MCU a fresh command, as the fieldbus would.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from firmware_model.mcu.mcu import Mcu
from hil.fpga_stack import FpgaStack
from hil.scheduler import Record, Scheduler
from plant.config import Config

PC_PERIOD_TICKS = 20  # 1 kHz

#: command(t_s) -> (mode, value): "force" N, "position" m, or "off".
CommandFn = Callable[[float], tuple[str, float]]


class ActuatorStack:
    """Plant, driver board, link and MCU for one actuator."""

    def __init__(self, cfg: Config, command: CommandFn, record_every: int = 4) -> None:
        self.config = cfg
        self.fpga = FpgaStack(cfg)
        self.mcu = Mcu(cfg, [self.fpga.mcu_link])
        self.command = command
        self.tick_s = self.fpga.tick_s
        self.sched = Scheduler(self.fpga, record_every=record_every)
        period = self.mcu.period
        self.sched.every(PC_PERIOD_TICKS, self._pc, "pc")
        self.sched.every(period, self.mcu.step, "mcu")
        ctrl = self.mcu.ctrl[0]
        self.sched.probe("tau_ref", lambda: float(self.mcu.tau_ref[0]), period)
        self.sched.probe("f_pres", lambda: float(self.mcu.meas[0].f_pres), period)
        self.sched.probe("f_strain", lambda: float(ctrl.cos_alpha * self.mcu.meas[0]
                                                   .f_strain_raw), period)
        self.sched.probe("f_fil", lambda: float(ctrl.f_fil), period)
        self.sched.probe("iq_ref", lambda: float(self.mcu.iq_ref[0]), period)
        self.sched.probe("x_meas", lambda: float(self.mcu.meas[0].x_piston), period)
        self.mcu.command(0, *command(0.0), tick=0)
        self.mcu.enable(0, self.fpga.board.calibrated_offset)

    def _pc(self, tick: int) -> None:
        self.mcu.command(0, *self.command(tick * self.tick_s), tick=tick)

    def run(self, seconds: float, progress: bool = False, label: str = "stack") -> Record:
        """Run for ``seconds`` of simulated time; the record holds plant outputs and probes."""
        return self.sched.run(self.sched.ticks(seconds), progress, label)


def probe_times(rec: Record, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(t in s, values) of a probe."""
    return rec.probe(name)
