"""The byte records the MCU law's C build reads and writes (``firmware_model/mcu/c/mcu_law.h``:
``mcu_config``, ``mcu_input``, ``mcu_output``) as numpy structured types, and the
configuration record, whose float32 constants are read from the Python model itself."""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu.controller import FEEDBACKS, V_FF_MAX
from firmware_model.mcu.mcu import Mcu

F32 = np.float32
N_ANALOG = B.N_ANALOG

CONFIG = np.dtype([
    ("adc_lsb_v", "<f4"), ("kc", "<f4"), ("rad_per_count", "<f4"), ("m_per_rad", "<f4"),
    ("n_per_code", "<f4"), ("m_per_count", "<f4"), ("rad_per_ssi", "<f4"), ("a_per_ma", "<f4"),
    ("strain_mid", "<i4"), ("biss_zero", "<i4"),
    ("analog_register", "<u4", N_ANALOG), ("analog_v0", "<f4", N_ANALOG),
    ("analog_mul", "<f4", N_ANALOG), ("analog_div", "<f4", N_ANALOG),
    ("dt", "<f4"), ("kt_eq", "<f4"), ("kp", "<f4"), ("kd", "<f4"), ("derivative_a", "<f4"),
    ("observer_j", "<f4"), ("observer_ko", "<f4"), ("bemf", "<f4"), ("vel_kp", "<f4"),
    ("vel_ki", "<f4"), ("force_kp", "<f4"), ("force_ki", "<f4"), ("highpass_a", "<f4"),
    ("seal_a", "<f4"), ("k_pos", "<f4"), ("cos_alpha", "<f4"), ("f_lim", "<f4"),
    ("p_lim", "<f4"), ("i_lim", "<f4"), ("vq_ff_max", "<f4"),
    ("velocity_based", "<u4"), ("feedback", "<u4"),
    ("timeout_ticks", "<i4"), ("off_ticks", "<i4"),
    ("down_init", "<u2", B.DOWN_WORDS),
])

#: ``mcu_input.flags``
IN_COMMAND, IN_ENABLE, IN_DISABLE, IN_CLEAR_FAULT, IN_GAINS = 1, 2, 4, 8, 16
MODES = ("off", "force", "position")

INPUT = np.dtype([
    ("tick", "<i4"), ("flags", "<u4"), ("mode", "<u4"), ("value", "<f4"),
    ("kp_position", "<f4"), ("kp_force", "<f4"), ("up_crc_errors", "<u4"),
    ("angle_offset", "<u4"), ("up", "<u2", B.UP_WORDS),
])

#: The float fields of ``mcu_output`` after ``down`` and ``status``, in order.
OUTPUT_FLOATS = ("i_ref", "v_ff", "tau_ref", "tau_p", "f_fb", "f_fil", "f_strain",
                 "observer_r", "observer_total", "derivative_y", "highpass_y", "seal_y",
                 "force_integral", "velocity_integral")
MEASURED_FLOATS = ("f_pres", "tau_q", "f_strain_raw", "omega_m", "v_pump", "x_piston", "iq",
                   "theta_rotor")

OUTPUT = np.dtype([("down", "<u2", B.DOWN_WORDS), ("status", "<u4"),
                   *((name, "<f4") for name in OUTPUT_FLOATS),
                   ("m_analog", "<f4", N_ANALOG),
                   *((name, "<f4") for name in MEASURED_FLOATS)])


#: The head of ``mcu_state``: its configuration, then the force and position gains in use
#: (a PC override or the configuration's). Nothing else in the state is written from here.
STATE_HEAD = np.dtype([("cfg", CONFIG), ("kp", "<f4"), ("k_pos", "<f4")])


def config_record(cal: FirmwareCalibration) -> np.ndarray:
    """The ``mcu_config`` for ``cal``: each constant read from the Python model built from
    ``cal`` (the float32 it holds), so the C and the model share one set of numbers."""
    cal = calibration(cal)
    return model_config(Mcu(cal, [LinkMemory(cal)]))


def model_config(mcu: Mcu) -> np.ndarray:
    """The ``mcu_config`` of actuator 0 of the Python program ``mcu`` as it stands (its
    tunables as written, :mod:`firmware_model.mcu.tunables`); ``down_init``: its link's
    downstream words (a program that has not stepped: the board's reset words)."""
    link = mcu.links[0]
    ctrl = mcu.ctrl[0]
    scales = mcu.meas[0].scales()
    c = np.zeros((), dtype=CONFIG)
    for name in ("adc_lsb_v", "kc", "rad_per_count", "m_per_rad", "n_per_code", "m_per_count",
                 "rad_per_ssi", "a_per_ma", "strain_mid", "biss_zero"):
        c[name] = scales[name]
    for k, (register, v0, mul, div) in enumerate(scales["analog"]):
        c["analog_register"][k] = register
        c["analog_v0"][k], c["analog_mul"][k], c["analog_div"][k] = v0, mul, div
    c["dt"], c["kt_eq"], c["kp"], c["kd"] = ctrl.dt, ctrl.kt_eq, ctrl.kp, ctrl.kd
    c["derivative_a"] = ctrl.derivative.a
    c["observer_j"], c["observer_ko"] = ctrl.observer.j, ctrl.observer.ko
    c["bemf"] = ctrl.bemf
    c["vel_kp"], c["vel_ki"] = ctrl.velocity_pi.kp, ctrl.velocity_pi.ki
    c["force_kp"], c["force_ki"] = ctrl.force_pi.kp, ctrl.force_pi.ki
    c["highpass_a"], c["seal_a"] = ctrl.highpass.a, ctrl.seal_observer.a
    c["k_pos"], c["cos_alpha"] = ctrl.k_pos, ctrl.cos_alpha
    c["f_lim"], c["p_lim"], c["i_lim"] = ctrl.f_lim, ctrl.p_lim, ctrl.i_lim
    c["vq_ff_max"] = V_FF_MAX
    c["velocity_based"] = ctrl.velocity_based
    c["feedback"] = FEEDBACKS.index(ctrl.feedback)
    c["timeout_ticks"], c["off_ticks"] = mcu.timeout_ticks, mcu.off_ticks
    c["down_init"] = link.down
    return c
