"""The Python MCU model (``firmware_model.mcu``) stepped on ``mcu_input`` records, giving
``mcu_output`` records: the reference the C builds are compared with."""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    IN_GAINS,
    MODES,
    OUTPUT,
)
from firmware_model.mcu.mcu import Mcu

F32 = np.float32


def run_model(cal: FirmwareCalibration, inputs: np.ndarray) -> np.ndarray:
    """Step a fresh one-actuator :class:`Mcu` through ``inputs``; one output per input. The
    process data is handled as :meth:`McuBoard.apply` does: clear-fault, enable/disable,
    gains, command, then :meth:`Mcu.step`."""
    cal = calibration(cal)
    link = LinkMemory(cal)
    mcu = Mcu(cal, [link])
    ctrl, meas = mcu.ctrl[0], mcu.meas[0]
    defaults = (ctrl.k_pos, ctrl.kp)
    out = np.zeros(len(inputs), dtype=OUTPUT)
    for k, rec in enumerate(inputs):
        flags = int(rec["flags"])
        tick = int(rec["tick"])
        if flags & IN_CLEAR_FAULT:
            link.write("control", B.CTRL_CLEAR_FAULT)
        if flags & IN_ENABLE:
            mcu.enable(0, int(rec["angle_offset"]))
        elif flags & IN_DISABLE:
            link.write("control", 0)
        if flags & IN_GAINS:
            kp_pos, kp_force = rec["kp_position"], rec["kp_force"]
            ctrl.k_pos = F32(kp_pos) if kp_pos > 0 else defaults[0]
            ctrl.kp = F32(kp_force) if kp_force > 0 else defaults[1]
        if flags & IN_COMMAND:
            mcu.command(0, MODES[int(rec["mode"])], rec["value"], tick)
        link.up[:] = rec["up"]
        link.up_crc_errors = int(rec["up_crc_errors"])
        mcu.step(tick)
        o = out[k]
        o["down"] = link.down
        o["status"] = mcu.status[0]
        o["i_ref"], o["tau_ref"] = mcu.iq_ref[0], mcu.tau_ref[0]
        o["v_ff"] = mcu.vq_ff[0]
        o["tau_p"], o["f_fb"], o["f_fil"] = ctrl.tau_p, ctrl.f_fb, ctrl.f_fil
        o["f_strain"] = ctrl.f_strain
        o["observer_r"], o["observer_total"] = ctrl.observer.r, ctrl.observer.total
        o["derivative_y"], o["highpass_y"] = ctrl.derivative.y, ctrl.highpass.y
        o["seal_y"] = ctrl.seal_observer.y
        o["force_integral"] = ctrl.force_pi.integral
        o["velocity_integral"] = ctrl.velocity_pi.integral
        o["m_analog"] = [getattr(meas, a.si_name) for a in B.ANALOG_INPUTS]
        for name in ("f_pres", "tau_q", "f_strain_raw", "omega_m", "v_pump", "x_piston", "iq",
                     "theta_rotor"):
            o[name] = getattr(meas, name)
    return out
