"""The byte records the MCU law's C build reads and writes (``firmware_model/mcu/c/mcu_law.h``:
``mcu_config``, ``mcu_input``, ``mcu_output``) as numpy structured types, and the
configuration record built from the firmware calibration exactly as the Python model builds
its float32 constants."""

from __future__ import annotations

import math

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.params import down_defaults
from firmware_model.mcu.controller import FEEDBACKS, V_FF_MAX
from firmware_model.mcu.measure import TWO_PI, analog_decoder
from protocols import pressure_adc as padc
from protocols.ad7195 import MIDSCALE

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


def _lowpass_a(cutoff_hz: float, dt: float) -> np.float32:
    return F32(1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt))


def config_record(cal: FirmwareCalibration) -> np.ndarray:
    """The ``mcu_config`` for ``cal``: each constant the float32 the Python model holds."""
    cal = calibration(cal)
    m = cal.mcu
    kc = cal.kc_m2
    tick_s = cal.tick_ns * 1e-9
    dt = m["period_ticks"] * tick_s
    window = cal.fpga["speed_window_ticks"]
    length, offset = m["conrod_length_m"], m["conrod_offset_m"]
    timeout = round(m["command_timeout_s"] / tick_s)
    c = np.zeros((), dtype=CONFIG)
    c["adc_lsb_v"] = F32(padc.DEFAULT.lsb_v)
    c["kc"] = F32(kc)
    c["rad_per_count"] = F32(TWO_PI / (cal.abi_counts_per_rev * window * tick_s))
    c["m_per_rad"] = F32(cal.kp_m3_per_rad / kc)
    c["n_per_code"] = F32(cal.strain_full_scale_n / MIDSCALE)
    c["m_per_count"] = F32(5e-9)
    c["rad_per_ssi"] = F32(TWO_PI / (1 << cal.ssi_bits))
    c["a_per_ma"] = F32(1e-3)
    c["strain_mid"] = MIDSCALE
    c["biss_zero"] = cal.biss_zero_count
    for k, a in enumerate(B.ANALOG_INPUTS):
        v0, mul, div = analog_decoder(a, cal)
        c["analog_register"][k] = a.register
        c["analog_v0"][k], c["analog_mul"][k], c["analog_div"][k] = F32(v0), F32(mul), F32(div)
    c["dt"] = F32(dt)
    c["kt_eq"] = F32(cal.kt_eq_n_per_a)
    c["kp"] = F32(m["kp_force"])
    c["kd"] = F32(m["kd_force_s"])
    c["derivative_a"] = _lowpass_a(m["derivative_filter_hz"], dt)
    c["observer_j"] = F32(cal.jp_kg)
    c["observer_ko"] = F32(2.0 * math.pi * m["friction_observer_hz"])
    c["bemf"] = F32(cal.kt_nm_per_a / 1.5) if m["backemf_ff"] else F32(0.0)
    c["vel_kp"], c["vel_ki"] = F32(m["vel_kp_n_per_m_s"]), F32(m["vel_ki_n_per_m"])
    c["force_kp"] = F32(m["vel_force_kp_m_s_per_n"])
    c["force_ki"] = F32(m["vel_force_ki_m_per_n"])
    c["highpass_a"] = F32(1.0 / (1.0 + 2.0 * math.pi * m["complementary_cutoff_hz"] * dt))
    c["seal_a"] = _lowpass_a(m["seal_observer_hz"], dt)
    c["k_pos"] = F32(m["position_kp_n_per_m"])
    c["cos_alpha"] = F32(math.sqrt(1.0 - (offset / length) ** 2) if length > 0 else 1.0)
    c["f_lim"] = F32(min(m["force_limit_n"], kc * m["pressure_limit_pa"]))
    c["p_lim"] = F32(m["pressure_limit_pa"])
    c["i_lim"] = F32(m["current_limit_a"])
    c["vq_ff_max"] = V_FF_MAX
    c["velocity_based"] = m["controller"] == "velocity"
    c["feedback"] = FEEDBACKS.index(m["force_feedback"])
    c["timeout_ticks"] = timeout
    c["off_ticks"] = timeout + round(m["safe_off_delay_s"] / tick_s)
    c["down_init"] = down_defaults(cal)
    return c
