"""The sensor chips' parameters, one flat float64 array for the compiled per-tick path.

Each physical part has its own module in :mod:`plant.sensors` (value-level digitising,
line-level model and fault knobs together); this module holds what they share: the index
layout ``K_*`` of their parameters, :func:`chip_params` that fills it from the
configuration (the parts' true scales: ``[sensors]``, not the firmware's calibration), and
the converter rounding :func:`adc_code`. :mod:`plant.sensors.harness` wires the parts to the
driver board's inputs.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.config import Config
from protocols import pressure_adc as padc
from protocols.ad7195 import MIDSCALE

TWO_PI = 2.0 * math.pi

CHIP_NAMES = (
    "ssi_counts", "ssi_mount_counts", "abi_counts", "biss_zero", "biss_mod",
    "strain_scale", "odr_hz", "tick_ns",
    "adc_lsb_v", "adc_code_max", "p_v_zero", "p_pa_per_v",
    "t_v0", "t_v_per_c",
    "i_lsb_a", "i_mid", "i_code_max",
    "pole_pairs", "hall_offset_rad",
    "motor_encoder_dead", "piston_encoder_dead",  # fault injection: 1 = no valid frame
)
(K_SSI_N, K_SSI_MOUNT, K_ABI_N, K_BISS_ZERO, K_BISS_MOD, K_STRAIN_SCALE, K_ODR, K_TICK_NS,
 K_ADC_LSB, K_ADC_MAX, K_P_V0, K_P_PA_PER_V, K_T_V0, K_T_V_PER_C, K_I_LSB, K_I_MID,
 K_I_MAX, K_POLE_PAIRS, K_HALL_OFFSET, K_MOTOR_DEAD, K_PISTON_DEAD) = range(len(CHIP_NAMES))
N_CHIP = len(CHIP_NAMES)


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
    k[K_P_V0] = adc.v_at_zero
    k[K_P_PA_PER_V] = adc.pa_per_v
    k[K_T_V0] = s["temperature_v_at_0c"]
    k[K_T_V_PER_C] = s["temperature_v_per_c"]
    k[K_I_LSB] = 2.0 * cfg.get("fpga.current_full_scale_a") / 4096.0
    k[K_I_MID] = 2048.0
    k[K_I_MAX] = 4095.0
    k[K_POLE_PAIRS] = cfg.get("motor.pole_pairs")
    k[K_HALL_OFFSET] = s["hall_offset_rad"]
    return k


@njit(cache=True, inline="always")
def adc_code(x, code_max):
    """Nearest code of ``x`` = V / LSB, saturated to 0..code_max (as the protocols codec)."""
    if x < 0.5:
        return 0
    if x >= code_max - 0.5:
        return int(code_max)
    return int(math.floor(x + 0.5))
