"""The sensor chips' parameters, one flat float64 array for the compiled per-tick path.

Each physical part has its own module in :mod:`plant.sensors` (value-level digitising,
line-level model and fault knobs together); this module holds what they share: the index
layout ``K_*`` of their parameters, :func:`chip_params` that fills it from the
configuration (the parts' true scales: ``[sensors]``, not the firmware's calibration), and
the converter rounding :func:`adc_code`. :mod:`plant.sensors.harness` wires the parts to the
driver board's inputs.

The analog sensors on the board's 8-channel ADC are rows of
:data:`firmware_model.fpga.layout.ANALOG_INPUTS`; their parameters follow the named ones,
four per input (:func:`analog_base`): volts at zero, multiplier, divisor and fitted, so that
``V = v0 + x * mul / div`` (one of ``mul``, ``div`` is 1, so the products are exact) and
:func:`analog_code` digitises any of them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.fpga.layout import ANALOG_INPUTS, N_ANALOG, AnalogInput
from plant.config import Config
from protocols import pressure_adc as padc
from protocols.ad7195 import MIDSCALE

TWO_PI = 2.0 * math.pi

CHIP_NAMES = (
    "ssi_counts", "ssi_mount_counts", "abi_counts", "biss_zero", "biss_mod",
    "strain_scale", "odr_hz", "tick_ns",
    "adc_lsb_v", "adc_code_max",
    "i_lsb_a", "i_mid", "i_code_max",
    "pole_pairs", "hall_offset_rad",
    "motor_encoder_dead", "piston_encoder_dead",  # fault injection: 1 = no valid frame
)
(K_SSI_N, K_SSI_MOUNT, K_ABI_N, K_BISS_ZERO, K_BISS_MOD, K_STRAIN_SCALE, K_ODR, K_TICK_NS,
 K_ADC_LSB, K_ADC_MAX, K_I_LSB, K_I_MID, K_I_MAX, K_POLE_PAIRS, K_HALL_OFFSET, K_MOTOR_DEAD,
 K_PISTON_DEAD) = range(len(CHIP_NAMES))
#: First parameter of the analog inputs (four each: v0, mul, div, fitted).
K_ANALOG = len(CHIP_NAMES)
N_CHIP = K_ANALOG + 4 * N_ANALOG


def _analog(a: AnalogInput, sensors: dict) -> tuple[float, float, float, float]:
    """(v0, mul, div, fitted) of one analog input with the part's true scales."""
    v0, gain = a.scales(sensors)
    mul, div = (gain, 1.0) if a.volts_per_unit else (1.0, gain)
    fitted = 1.0 if a.fitted_key is None or sensors[a.fitted_key] else 0.0
    return v0, mul, div, fitted


def chip_params(cfg: Config) -> np.ndarray:
    """Parameters of the sensor chips (``K_*``) from the configuration."""
    s = cfg.section("sensors")
    adc = padc.DEFAULT
    k = np.zeros(N_CHIP)
    n = 1 << s["ssi_bits"]
    k[K_SSI_N] = n
    k[K_SSI_MOUNT] = s["ssi_mount_rad"] * n / TWO_PI
    k[K_ABI_N] = s["abi_counts_per_rev"]
    k[K_BISS_ZERO] = s["biss_zero_count"]
    k[K_BISS_MOD] = float(1 << s["biss_bits"])
    k[K_STRAIN_SCALE] = MIDSCALE / s["strain_full_scale_n"]
    k[K_ODR] = s["strain_odr_hz"]
    k[K_TICK_NS] = cfg.get("sim.tick_ns")
    k[K_ADC_LSB] = adc.lsb_v
    k[K_ADC_MAX] = adc.code_max
    k[K_I_LSB] = 2.0 * cfg.get("fpga.current_full_scale_a") / 4096.0
    k[K_I_MID] = 2048.0
    k[K_I_MAX] = 4095.0
    k[K_POLE_PAIRS] = cfg.get("motor.pole_pairs")
    k[K_HALL_OFFSET] = s["hall_offset_rad"]
    for j, a in enumerate(ANALOG_INPUTS):
        k[K_ANALOG + 4 * j:K_ANALOG + 4 * j + 4] = _analog(a, s)
    return k


@njit(cache=True, inline="always")
def adc_code(x, code_max):
    """Nearest code of ``x`` = V / LSB, saturated to 0..code_max (as the protocols codec)."""
    if x < 0.5:
        return 0
    if x >= code_max - 0.5:
        return int(code_max)
    return int(math.floor(x + 0.5))


@njit(cache=True)
def analog_code(x, k, j):
    """ADC code of analog input ``j`` (``ANALOG_INPUTS`` order) measuring ``x`` (SI); an
    input whose part is not fitted reads 0 V."""
    b = K_ANALOG + 4 * j
    if k[b + 3] < 0.5:
        return 0
    v = k[b] + x * k[b + 1] / k[b + 2]
    return adc_code(v / k[K_ADC_LSB], k[K_ADC_MAX])


def analog_zero_value(k: np.ndarray, j: int) -> float:
    """A value analog input ``j`` reads as code 0 (a dead sensor, for fault injection)."""
    b = K_ANALOG + 4 * j
    return (-k[b] - k[K_ADC_LSB]) * k[b + 2] / k[b + 1]
