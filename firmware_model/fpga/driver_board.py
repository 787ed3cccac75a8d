"""The driver board as an object: its integer arrays, register access by name, one tick.

The per-tick work is :func:`firmware_model.fpga.tick.control_tick` (compiled); this class
owns the arrays and gives people and tests names and units. It never touches the plant or
a link: the harness (:mod:`hil.sim.actuator`) wires raw sensor words in, duty counts out,
and the LVDS words in both directions.
"""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.params import board_params, calibrated_offset, down_defaults
from firmware_model.fpga.tick import control_tick

_DOWN_TYPE = {name: typ for _, name, typ, *_ in B.DOWN_REGISTERS}
_UP_TYPE = {name: typ for _, name, typ, *_ in B.UP_REGISTERS}


def to_word(value: int, typ: str, name: str) -> int:
    """A register value as its 16-bit word; ValueError if it does not fit the type."""
    lo, hi = (-32768, 32767) if typ == "s16" else (0, 65535)
    v = int(value)
    if not lo <= v <= hi:
        raise ValueError(f"register {name}: {v} outside {typ} range {lo}..{hi}")
    return v & 0xFFFF


def from_word(word: int, typ: str) -> int:
    """A 16-bit word as the register's value (two's complement for s16)."""
    w = int(word) & 0xFFFF
    return w - 0x10000 if typ == "s16" and w & 0x8000 else w


class DriverBoard:
    """One motor driver board (FPGA state, downstream and upstream memories)."""

    def __init__(self, cal: FirmwareCalibration) -> None:
        cal = calibration(cal)
        self.calibration = cal
        self.params = board_params(cal)
        self.state = np.zeros(B.N_STATE, dtype=np.int64)
        self.down = down_defaults(cal)
        self.up = np.zeros(B.UP_WORDS, dtype=np.int64)
        self.pwm_top = int(self.params[B.C_PWM_TOP])
        self.calibrated_offset = calibrated_offset(cal)
        #: What ``params[C_RTL_*]`` point at (the harness's compiled RTL of the current loop,
        #: ``fpga.impl = "rtl"``), held here so that it lives as long as the board.
        self.rtl = None

    def tick(self, raw: np.ndarray) -> int:
        """One 50 us tick with the raw sensor words ``raw``; returns 1 while PWM is on."""
        return control_tick(self.params, self.state, self.down, self.up, raw)

    # --- inspection -------------------------------------------------------------------------
    def duty_counts(self) -> tuple[int, int, int]:
        """PWM compare counts of legs a, b, c (0..pwm_top)."""
        s = self.state
        return int(s[B.F_DUTY_A]), int(s[B.F_DUTY_B]), int(s[B.F_DUTY_C])

    @property
    def pwm_on(self) -> bool:
        return bool(self.state[B.F_PWM_ON])

    @property
    def fsm_state(self) -> str:
        """Enable state machine: 'disabled', 'enabled' or 'fault'."""
        return B.STATE_NAMES[int(self.state[B.F_STATE])]

    def up_value(self, name: str) -> int:
        """An upstream register by name, as its typed value."""
        return from_word(self.up[B.up_address(name)], _UP_TYPE[name])

    def down_value(self, name: str) -> int:
        """A downstream register (as the board last received it) by name."""
        return from_word(self.down[B.down_address(name)], _DOWN_TYPE[name])


class LinkMemory:
    """The MCU side's view of one driver board: the memory it sends (down) and the one it
    receives (up), with typed access by register name (what the MCU program reads as plain
    variables through the dual-port RAM, thesis 6.3.1)."""

    def __init__(self, cal: FirmwareCalibration) -> None:
        self.down = down_defaults(cal)
        self.up = np.zeros(B.UP_WORDS, dtype=np.int64)
        #: Upstream words this side discarded for CRC (the MCU board FPGA's counter).
        self.up_crc_errors = 0

    def write(self, name: str, value: int) -> None:
        """Set a downstream register; it reaches the board with the next sweep."""
        addr = B.down_address(name)
        self.down[addr] = to_word(value, _DOWN_TYPE[name], name)

    def read(self, name: str) -> int:
        """An upstream register as last received from the board."""
        addr = B.up_address(name)
        return from_word(self.up[addr], _UP_TYPE[name])

    def status(self) -> set[str]:
        """Names of the status bits set in the last received status word."""
        word = int(self.up[B.U_STATUS])
        return {name for bit, name, _ in B.STATUS_BITS if word >> bit & 1}


__all__ = ["DriverBoard", "LinkMemory", "from_word", "to_word"]
