"""The MCU board: up to five actuator controllers, each talking to its driver board through
that board's link memory, with the command watchdog and a status word per actuator.

The PC side hands commands in with :meth:`Mcu.command` (at 1 kHz over the fieldbus); each
5 kHz :meth:`Mcu.step` reads the boards' upstream memories, runs the controllers and writes
the downstream registers (iq_ref in mA, vq_ff in mV, a sequence counter).

Safety: no fresh command for ``command_timeout_s`` -> the force command is zero
(``CMD_TIMEOUT``); ``safe_off_delay_s`` later the board is disabled (``SAFE_OFF``). Limits
hit and board/link trouble are reported in the status word.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu import tunables
from firmware_model.mcu.controller import (
    LIMIT_CURRENT,
    LIMIT_FORCE,
    LIMIT_PRESSURE,
    ActuatorController,
)
from firmware_model.mcu.measure import Measurements

F32 = np.float32
MAX_BOARDS = 5

STATUS_BITS = (
    (0, "CMD_TIMEOUT", "no fresh command within command_timeout_s: force command zero"),
    (1, "SAFE_OFF", "timeout lasted safe_off_delay_s more: driver board disabled"),
    (2, "FORCE_LIMITED", "force command clamped to the force/pressure limit"),
    (3, "CURRENT_LIMITED", "current reference clamped to the current limit"),
    (4, "PRESSURE_HIGH", "a measured pressure above the pressure limit"),
    (5, "BOARD_FAULT", "the driver board reports FAULT"),
    (6, "LINK_ERROR", "the driver board lost the link, or upstream words failed CRC"),
    (7, "BOARD_ENABLED", "the driver board reports ENABLED"),
    (8, "ENCODER_ERROR", "the driver board's latest SSI or BiSS read failed (value held)"),
    (9, "STRAIN_ERROR", "the driver board's latest AD7195 read failed (value held)"),
)
#: The board's 16-bit error counters saturate here (they do not wrap).
CRC_COUNT_MAX = 0xFFFF

(CMD_TIMEOUT, SAFE_OFF, FORCE_LIMITED, CURRENT_LIMITED, PRESSURE_HIGH, BOARD_FAULT,
 LINK_ERROR, BOARD_ENABLED, ENCODER_ERROR, STRAIN_ERROR) = (1 << b for b, _, _ in STATUS_BITS)


def flag_set(status: np.ndarray, flag: int) -> np.ndarray:
    """Where status word(s) ``status`` have ``flag`` (one of the bits above) set."""
    return (np.asarray(status) & flag) != 0



class CommandMode(StrEnum):
    """What the PC asks of one actuator (:meth:`Mcu.command`, the process data's ``mode``):
    nothing, a piston force (N) or a piston position (m). Neither the driver board's
    :class:`~firmware_model.fpga.layout.BoardMode` nor the plant's
    :class:`~plant.layout.DriveMode`. Members equal their names as text, so ``"force"``
    from a scenario or a command line is the same command."""

    OFF = "off"
    FORCE = "force"
    POSITION = "position"


_COMMAND_MODES = frozenset(m.value for m in CommandMode)


class Mcu:
    """The STM32F4 program for ``len(links)`` actuators (1..5)."""

    def __init__(self, cal: FirmwareCalibration, links: list[LinkMemory]) -> None:
        if not 1 <= len(links) <= MAX_BOARDS:
            raise ValueError(f"an MCU board serves 1..{MAX_BOARDS} driver boards, "
                             f"got {len(links)}")
        cal = calibration(cal)
        m = cal.mcu
        tick_s = cal.tick_ns * 1e-9
        self.links = links
        self.period = m["period_ticks"]
        self.meas = [Measurements(cal) for _ in links]
        self.ctrl = [ActuatorController(cal) for _ in links]
        n = len(links)
        self.mode = [CommandMode.OFF] * n
        self.value = [F32(0.0)] * n
        self.last_cmd_tick = [0] * n
        self.status = [0] * n
        self.tau_ref = [F32(0.0)] * n
        self.iq_ref = [F32(0.0)] * n
        self.vq_ff = [F32(0.0)] * n
        self.timeout_ticks = round(m["command_timeout_s"] / tick_s)
        self.off_ticks = self.timeout_ticks + round(m["safe_off_delay_s"] / tick_s)
        self._seq = 0
        self._crc_seen = [(0, 0)] * n
        self.tick_s = tick_s
        #: Per actuator: the firmware's own (position, force) gains, used when the process
        #: data's gain fields are 0 (tunable over CoE).
        self.own_gains = [[c.k_pos, c.kp] for c in self.ctrl]
        self._tuned: list[tuple[int, str, float]] = []

    def tune(self, i: int, key: str, value: float) -> None:
        """A new value of tunable ``key`` (:mod:`firmware_model.mcu.tunables`) for actuator
        ``i``, applied at the next :meth:`step`."""
        tunables.BY_KEY[key]  # (a KeyError now, not at the step)
        self._tuned.append((i, key, float(value)))

    def link_error_counts(self, i: int) -> tuple[int, int]:
        """(downstream words board ``i`` discarded, upstream words this side discarded) as
        read at the last step."""
        return self._crc_seen[i]

    def command(self, i: int, mode: str, value: float, tick: int) -> None:
        """A fresh command for actuator ``i``: mode "force" (N), "position" (m) or "off"."""
        if mode not in _COMMAND_MODES:
            raise ValueError(f"unknown command mode {mode!r}")
        self.mode[i] = CommandMode(mode)
        self.value[i] = F32(value)
        self.last_cmd_tick[i] = tick

    def enable(self, i: int, angle_offset: int) -> None:
        """Boot actuator ``i``'s board: calibrated offset, current mode, enable."""
        link = self.links[i]
        link.write("angle_offset", angle_offset)
        link.write("mode", B.BoardMode.CURRENT)
        link.write("control", B.CTRL_ENABLE)
        self.ctrl[i].reset()

    def disable(self, i: int) -> None:
        """Switch actuator ``i``'s board off (control = 0)."""
        self.links[i].write("control", 0)

    def clear_fault(self, i: int) -> None:
        """Ask actuator ``i``'s board to clear its latched fault."""
        self.links[i].write("control", B.CTRL_CLEAR_FAULT)

    def step(self, tick: int) -> None:
        """One 5 kHz cycle for every actuator."""
        if self._tuned:
            for i, key, value in self._tuned:
                tunables.apply(self, i, key, value)
            self._tuned.clear()
        self._seq = (self._seq + 1) & 0xFFFF
        for i, link in enumerate(self.links):
            m = self.meas[i]
            m.update(link.up)
            ctrl = self.ctrl[i]
            age = tick - self.last_cmd_tick[i]
            status = 0
            mode = self.mode[i]
            if age > self.timeout_ticks and mode != CommandMode.OFF:
                status |= CMD_TIMEOUT
                tau_ref = F32(0.0)
                if age > self.off_ticks:
                    status |= SAFE_OFF
                    link.down[B.D_CONTROL] = 0
            elif mode == CommandMode.FORCE:
                tau_ref = self.value[i]
            elif mode == CommandMode.POSITION:
                tau_ref = ctrl.k_pos * (self.value[i] - m.x_piston)
            else:
                tau_ref = F32(0.0)
            if mode == CommandMode.OFF:
                i_ref, v_ff = F32(0.0), F32(0.0)
                ctrl.reset()
            else:
                i_ref, v_ff = ctrl.step(m, tau_ref)
                tau_ref = ctrl.tau_used  # after the force/pressure limit
            self.tau_ref[i] = tau_ref
            self.iq_ref[i] = i_ref
            self.vq_ff[i] = v_ff
            down = link.down
            # round() on the exact float64 image of the float32 product rounds half to
            # even like np.rint, without numpy's per-call overhead.
            down[B.D_IQ_REF] = round(float(i_ref * F32(1000.0))) & 0xFFFF
            down[B.D_VQ_FF] = round(float(v_ff * F32(1000.0))) & 0xFFFF
            down[B.D_SEQUENCE] = self._seq
            lim = ctrl.limits
            if lim & LIMIT_FORCE:
                status |= FORCE_LIMITED
            if lim & LIMIT_CURRENT:
                status |= CURRENT_LIMITED
            if lim & LIMIT_PRESSURE:
                status |= PRESSURE_HIGH
            board = m.status
            if board & B.ST_FAULT:
                status |= BOARD_FAULT
            if board & B.ST_ENABLED:
                status |= BOARD_ENABLED
            if board & B.ST_ENCODER_ERROR:
                status |= ENCODER_ERROR
            if board & B.ST_STRAIN_ERROR:
                status |= STRAIN_ERROR
            # Downstream words the board discarded, upstream words this side discarded.
            # A saturated board counter can no longer show new errors, so it reports
            # LINK_ERROR for as long as it stays saturated (a board reset zeroes it).
            crc = (int(link.up[B.U_ERR_LINK_CRC]), link.up_crc_errors)
            if board & B.ST_LINK_LOST or crc != self._crc_seen[i] or crc[0] == CRC_COUNT_MAX:
                status |= LINK_ERROR
            self._crc_seen[i] = crc
            self.status[i] = status
