"""The MCU law's C build (``firmware_model/mcu/c/``, host shared library) in the stack in
place of the Python :class:`~firmware_model.mcu.mcu.Mcu` (``--set mcu.impl=c``), for one
actuator: the same calls (``command``, ``enable``, ``step``) and the values the stack
probes (``tau_ref``, ``iq_ref``, ``meas[0]``, ``ctrl[0]``), taken from the C's output
record after each step. The C's downstream words replace the link's."""

from __future__ import annotations

import ctypes
from types import SimpleNamespace

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    INPUT,
    MEASURED_FLOATS,
    MODES,
    OUTPUT,
    config_record,
)
from hil.sim.mcu_builds import BuildError, HostLaw, build_host
from plant.config import ConfigError

F32 = np.float32


class _Controller(SimpleNamespace):
    def strain_force(self, m: SimpleNamespace) -> np.float32:
        return self.cos_alpha * m.f_strain_raw


class CMcu:
    """One actuator's MCU program run by the host C build."""

    impl = "c"

    def __init__(self, cal: FirmwareCalibration, links: list[LinkMemory]) -> None:
        if len(links) != 1:
            raise ValueError(f"mcu.impl = '{self.impl}' runs one actuator, got {len(links)} "
                             "links")
        cal = calibration(cal)
        self.links = links
        self.period = cal.mcu["period_ticks"]
        config = config_record(cal)
        self._start(cal, config)
        self._in = np.zeros((), dtype=INPUT)
        self._out = np.zeros((), dtype=OUTPUT)
        self._flags = 0
        self.meas = [SimpleNamespace(**{n: F32(0.0) for n in MEASURED_FLOATS})]
        self.ctrl = [_Controller(cos_alpha=F32(config["cos_alpha"]), f_fil=F32(0.0),
                                 tau_used=F32(0.0))]
        self.tau_ref = [F32(0.0)]
        self.iq_ref = [F32(0.0)]
        self.vq_ff = [F32(0.0)]
        self.status = [0]
        self.mode, self.value, self.last_cmd_tick = ["off"], [0.0], [0]  # the last command

    def _start(self, cal: FirmwareCalibration, config: np.ndarray) -> None:
        """Load the law and give it a fresh state built from ``config``."""
        try:
            self._law = HostLaw(build_host())
        except BuildError as exc:
            raise ConfigError(f"mcu.impl = 'c': {exc}") from None
        self._state = ctypes.create_string_buffer(self._law.state_size)
        self._law.init(self._state, config)

    def _law_step(self, rec: np.ndarray, out: np.ndarray, link: LinkMemory) -> None:
        """One cycle of the law: ``rec`` (an ``mcu_input``) in, ``out`` (``mcu_output``)
        filled; the downstream words go to ``link``."""
        self._law.step(self._state, rec, out)
        link.down[:] = out["down"]

    def command(self, i: int, mode: str, value: float, tick: int) -> None:
        if mode not in MODES:
            raise ValueError(f"unknown command mode {mode!r}")
        self._flags |= IN_COMMAND
        self._in["mode"], self._in["value"], self._cmd_tick = MODES.index(mode), value, tick
        self.mode[0], self.value[0], self.last_cmd_tick[0] = mode, value, tick

    def enable(self, i: int, angle_offset: int) -> None:
        self._flags |= IN_ENABLE
        self._in["angle_offset"] = angle_offset

    def disable(self, i: int) -> None:
        self._flags |= IN_DISABLE

    def clear_fault(self, i: int) -> None:
        self._flags |= IN_CLEAR_FAULT

    def step(self, tick: int) -> None:
        link = self.links[0]
        rec = self._in
        if self._flags & IN_COMMAND and self._cmd_tick != tick:
            raise RuntimeError(f"command stamped {self._cmd_tick} reached the step at {tick}")
        rec["tick"], rec["flags"] = tick, self._flags
        rec["up"] = link.up
        rec["up_crc_errors"] = link.up_crc_errors
        self._law_step(rec, self._out, link)
        self._flags = 0
        out = self._out
        m = self.meas[0]
        for name in MEASURED_FLOATS:
            setattr(m, name, F32(out[name]))
        c = self.ctrl[0]
        c.f_fil, c.tau_used = F32(out["f_fil"]), F32(out["tau_ref"])
        self.tau_ref[0], self.iq_ref[0] = F32(out["tau_ref"]), F32(out["i_ref"])
        self.vq_ff[0] = F32(out["v_ff"])
        self.status[0] = int(out["status"])
