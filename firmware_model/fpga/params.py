"""The driver board's constants and boot values from its calibration set: the parameter
array its compiled tick reads (``layout.C_*``), the reset contents of its downstream memory
(limits and PI gains) and the calibrated angle offset the PC sends at start-up."""

from __future__ import annotations

import math

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.foc import V_LIMIT_Q15
from firmware_model.fpga.layout import (
    C_ADC_MID,
    C_ADC_SHIFT,
    C_I_TO_MA,
    C_KI_SHIFT,
    C_KP_SHIFT,
    C_MA_TO_I,
    C_MV_TO_V,
    C_POLE_PAIRS,
    C_PWM_TOP,
    C_SPEED_WINDOW,
    C_SSI_SHIFT,
    C_V_LIMIT,
    C_V_TO_MV,
    C_WD_TICKS,
    D_CURRENT_LIMIT,
    D_KI,
    D_KP,
    D_TRIP_CURRENT,
)

#: Fixed shifts of the PI gain multipliers (the registers hold the multipliers).
KP_SHIFT = 12
KI_SHIFT = 16
#: Bits of the current ADC.
CURRENT_ADC_BITS = 12


def _k15(x: float) -> int:
    """A constant factor as a multiplier for ``mul_shift(.., k, 15)``."""
    return round(x * (1 << 15))


def board_params(cal: FirmwareCalibration) -> np.ndarray:
    """The constant parameter array of the board (``layout.C_*``) from its calibration."""
    cal = calibration(cal)
    f = cal.fpga
    c = np.zeros(B.N_PARAMS, dtype=np.int64)
    c[C_POLE_PAIRS] = cal.pole_pairs
    c[C_SSI_SHIFT] = 16 - cal.ssi_bits
    c[C_ADC_MID] = 1 << (CURRENT_ADC_BITS - 1)
    c[C_ADC_SHIFT] = 16 - CURRENT_ADC_BITS
    c[C_PWM_TOP] = pwm_top(cal)
    c[C_V_LIMIT] = V_LIMIT_Q15
    c[C_KP_SHIFT] = KP_SHIFT
    c[C_KI_SHIFT] = KI_SHIFT
    i_lsb_ma = 1000.0 * f["current_full_scale_a"] / 32768.0      # mA per s16 current LSB
    v_lsb_mv = 1000.0 * cal.dc_bus_v / 32768.0    # mV per s16 voltage LSB
    c[C_MA_TO_I] = _k15(1.0 / i_lsb_ma)
    c[C_I_TO_MA] = _k15(i_lsb_ma)
    c[C_MV_TO_V] = _k15(1.0 / v_lsb_mv)
    c[C_V_TO_MV] = _k15(v_lsb_mv)
    c[C_WD_TICKS] = max(1, round(f["watchdog_s"] / (cal.tick_ns * 1e-9)))
    c[C_SPEED_WINDOW] = f["speed_window_ticks"]
    return c


def pwm_top(cal: FirmwareCalibration) -> int:
    """Compare counts of half a carrier period: f_clk / (2 f_pwm) (centre-aligned)."""
    cal = calibration(cal)
    top = cal.fpga["clock_hz"] / (2.0 * cal.pwm_hz)
    return int(round(top))


def gain_registers(cal: FirmwareCalibration) -> tuple[int, int]:
    """(kp, ki) register values for the configured PI gains in V/A and V/(A s).

    In the s16 units the PI sees (current LSB I_FS/2^15, voltage LSB V_dc/2^15):
    kp_reg = Kp (I_FS/V_dc) 2^12, ki_reg = Ki T_s (I_FS/V_dc) 2^16, each saturated to u16.
    """
    cal = calibration(cal)
    f = cal.fpga
    ratio = f["current_full_scale_a"] / cal.dc_bus_v
    ts = cal.tick_ns * 1e-9
    kp = round(f["current_kp_v_per_a"] * ratio * (1 << KP_SHIFT))
    ki = round(f["current_ki_v_per_a_s"] * ts * ratio * (1 << KI_SHIFT))
    return min(kp, 0xFFFF), min(ki, 0xFFFF)


def calibrated_offset(cal: FirmwareCalibration) -> int:
    """The angle_offset register value that aligns the SSI with the rotor's d axis.

    What the PC's calibration table holds: -p * (SSI zero's mounting angle), 2^16 per
    electrical turn, rounded. The encoder reads count = (theta_m + mount) N / 2 pi.
    """
    cal = calibration(cal)
    pp = cal.pole_pairs
    mount = cal.ssi_mount_rad
    return round(-pp * mount * 65536.0 / (2.0 * math.pi)) & 0xFFFF


def down_defaults(cal: FirmwareCalibration) -> np.ndarray:
    """Reset contents of the downstream memory: limits and gains from the configuration,
    everything else zero (disabled, mode off, offset not yet calibrated)."""
    cal = calibration(cal)
    d = np.zeros(B.DOWN_WORDS, dtype=np.int64)
    d[D_CURRENT_LIMIT] = min(0xFFFF, round(cal.fpga["current_limit_a"] * 1000.0))
    d[D_TRIP_CURRENT] = min(0xFFFF, round(cal.fpga["trip_current_a"] * 1000.0))
    d[D_KP], d[D_KI] = gain_registers(cal)
    return d


