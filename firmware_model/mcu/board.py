"""The MCU board of one joint driver box: the STM32 program (:class:`Mcu`) on the dual-port
memory of the board's FPGA (:class:`DualPortRam`), which copies to and from the LVDS link
memories of its driver boards each cycle, and the program's handling of what the fieldbus
brings: commands, the enable and clear-fault edges, gain overrides; and what it reports
back per actuator.

The fieldbus record's bytes are the harness's (:mod:`hil.fieldbus.pdo`); this class takes
and gives SI values and flags, as the firmware's process-data task would after decoding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu.dpram import DualPortRam
from firmware_model.mcu.mcu import Mcu

F32 = np.float32


@dataclass
class ActuatorReport:
    """What the box reports for one actuator each fieldbus cycle, SI units."""

    x_piston: float
    v_piston: float
    f_pressure: float
    f_strain: float
    f_filtered: float
    iq: float
    temperature_c: float
    status: int
    link_errors_down: int
    link_errors_up: int


class McuBoard:
    """The MCU board serving ``len(links)`` driver boards; ``offsets[k]``: board k's
    calibrated angle offset (the PC's calibration table)."""

    def __init__(self, cal: FirmwareCalibration, links: list[LinkMemory],
                 offsets: list[int]) -> None:
        cal = calibration(cal)
        self.links = links
        self.offsets = list(offsets)
        self.ram = DualPortRam(cal)
        self.ram.attach(links)
        self.mcu = Mcu(cal, [self.ram.board(k) for k in range(len(links))])
        self.period = self.mcu.period
        self.tick_s = cal.tick_s
        n = len(links)
        self._enabled = [False] * n
        self._clear = [False] * n
        self._x_prev = [0.0] * n

    def apply(self, i: int, mode: str, value: float, enable: bool, clear_fault: bool,
              kp_position: float, kp_force: float, tick: int) -> None:
        """This cycle's process data for actuator ``i``: a CLEAR_FAULT on its rising edge,
        enable (boot the board) on a rising and disable on a falling edge, the gains (0: the
        firmware's own), the command."""
        view = self.mcu.links[i]
        if clear_fault and not self._clear[i]:
            view.write("control", B.CTRL_CLEAR_FAULT)
        if enable and not self._enabled[i]:
            self.mcu.enable(i, self.offsets[i])
        elif self._enabled[i] and not enable:
            view.write("control", 0)
        self._enabled[i], self._clear[i] = enable, clear_fault
        ctrl = self.mcu.ctrl[i]
        own = self.mcu.own_gains[i]
        ctrl.k_pos = F32(kp_position) if kp_position > 0 else own[0]
        ctrl.kp = F32(kp_force) if kp_force > 0 else own[1]
        self.mcu.command(i, mode, value, tick)

    def step(self, tick: int) -> None:
        """One 5 kHz cycle: the DPRAM takes the links' upstream memories in, the program
        runs, the DPRAM gives the downstream blocks out."""
        self.ram.sync_up()
        self.mcu.step(tick)
        self.ram.sync_down()

    def report(self, i: int, ticks: int) -> ActuatorReport:
        """Actuator ``i`` as the MCU sees it now; the piston velocity is the position's
        change over the last ``ticks`` (0: none yet)."""
        m, c = self.mcu.meas[i], self.mcu.ctrl[i]
        x = float(m.x_piston)
        v = (x - self._x_prev[i]) / (ticks * self.tick_s) if ticks else 0.0
        self._x_prev[i] = x
        # The error counts as the MCU read them at its last step (what it reports).
        err_down, err_up = self.mcu.link_error_counts(i)
        return ActuatorReport(x, v, float(m.f_pres), float(c.cos_alpha * m.f_strain_raw),
                              float(c.f_fil), float(m.iq), float(m.temperature_c),
                              self.mcu.status[i], err_down, err_up)
