"""A behavioural actuator for bus-level work where the full stack would cost too much (the
whole robot's 47 actuators): the force follows its command through a first-order lag of
:data:`TAU_FORCE_S`, the piston a position command through :data:`TAU_POSITION_S` (with a
10 N/mm spring for the force), and the MCU's command watchdog is kept as the firmware
has it, so timeouts and status words behave as the firmware's
(:class:`firmware_model.mcu.mcu.Mcu`: ``CMD_TIMEOUT`` then ``SAFE_OFF``).

It is a stand-in for plant, boards and MCU together; :class:`hil.fieldbus.boxes.EchoBox`
only decodes the process data into it and packs what it reports.
"""

from __future__ import annotations

import math

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.mcu.mcu import BOARD_ENABLED, CMD_TIMEOUT, SAFE_OFF, CommandMode

TAU_FORCE_S = 0.005
TAU_POSITION_S = 0.02
#: Force per m of position error in position mode, N/m.
POSITION_SPRING_N_PER_M = 1e4


class EchoActuators:
    """``n`` behavioural actuators: :meth:`command` once per fieldbus cycle, :meth:`advance`
    by whole ticks; ``x`` (m), ``v`` (m/s), ``f`` (N), ``iq`` (A) and ``status`` (the MCU's
    status bits) per actuator."""

    def __init__(self, n: int, cal: FirmwareCalibration) -> None:
        cal = calibration(cal)
        tick_s = cal.tick_ns * 1e-9
        self.tick_s = tick_s
        self.timeout = round(cal.mcu["command_timeout_s"] / tick_s)
        self.off = self.timeout + round(cal.mcu["safe_off_delay_s"] / tick_s)
        self.n_per_a = cal.kt_eq_n_per_a
        self.cmd: list[tuple[str, float]] = [(CommandMode.OFF, 0.0)] * n
        self.enabled = [False] * n
        self.last = [0] * n
        self.f = [0.0] * n
        self.x = [0.0] * n
        self.v = [0.0] * n
        self.status = [0] * n
        self.tick = 0

    def command(self, i: int, mode: str, value: float, enabled: bool) -> None:
        """A fresh command for actuator ``i`` at the current tick."""
        self.cmd[i] = (mode, value)
        self.enabled[i] = enabled
        self.last[i] = self.tick

    def iq(self, i: int) -> float:
        """The q-axis current the force takes, A."""
        return self.f[i] / self.n_per_a

    def advance(self, ticks: int) -> None:
        dt = ticks * self.tick_s
        af = 1.0 - math.exp(-dt / TAU_FORCE_S)
        ax = 1.0 - math.exp(-dt / TAU_POSITION_S)
        self.tick += ticks
        for i in range(len(self.cmd)):
            mode, value = self.cmd[i]
            age = self.tick - self.last[i]
            status = BOARD_ENABLED if self.enabled[i] else 0
            if age > self.timeout and mode != CommandMode.OFF:
                status |= CMD_TIMEOUT
                mode, value = CommandMode.FORCE, 0.0
                if age > self.off:
                    status = (status | SAFE_OFF) & ~BOARD_ENABLED
            if not status & BOARD_ENABLED:
                mode = CommandMode.OFF
            x0 = self.x[i]
            if mode == CommandMode.FORCE:
                self.f[i] += af * (value - self.f[i])
            elif mode == CommandMode.POSITION:
                self.x[i] += ax * (value - self.x[i])
                self.f[i] += af * (POSITION_SPRING_N_PER_M * (value - self.x[i]) - self.f[i])
            else:
                self.f[i] += af * (0.0 - self.f[i])
            self.v[i] = (self.x[i] - x0) / dt
            self.status[i] = status
