"""The sensor chips at value level: physical signals from the plant -> the codes their
serial links carry, compiled for the per-tick path.

Each function is the chip's quantisation only (the same rounding the bit-level slaves in
:mod:`hil.sensor_lines` apply before encoding), so the value-level and bit-level paths give
the FPGA identical raw words. Conventions:

* SSI (RMB30SI): count = floor((theta_m + mount) N / 2 pi) mod N, N = 2^ssi_bits;
* ABI: quadrature count = floor(theta_m N_abi / 2 pi), kept as a 16-bit counter value;
* BiSS (RESOLUTE): count = floor(x / 5 nm) + zero count, modulo 2^bits;
* AD7195: bipolar code = floor(F 2^23 / F_FS + 2^23 + 1/2), saturated (as
  :func:`protocols.ad7195.clamp_force_to_code`), a new conversion every 1/ODR; a clamped
  conversion carries the ERR status bit, so the master rejects it (strain_ok = 0);
* pressure and temperature ADC: code = floor(V / LSB + 1/2), saturated (as
  :func:`protocols.pressure_adc.voltage_to_code`);
* phase currents: 12-bit offset binary over +/- I_FS, same rounding;
* hall: the code of the electrical angle's 60-degree sector.

A small epsilon (1e-7 count) before each floor keeps an angle the plant has already
quantised to a whole count on that count despite float rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.fpga import layout as B
from plant import layout as L
from plant.config import Config
from protocols import hall
from protocols import pressure_adc as padc
from protocols.ad7195 import CODE_MAX, MIDSCALE
from protocols.biss import LINEAR_COUNT_M

EPS_COUNT = 1e-7
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

HALL_SEQUENCE = np.asarray(hall.SEQUENCE, dtype=np.int64)
#: Plant output rows read by the five pressure channels, in register order.
PRESSURE_ROWS = np.asarray((L.Y_P_ACC, L.Y_P_PUMP_A, L.Y_P_PUMP_B, L.Y_P_CYL_A, L.Y_P_CYL_B),
                           dtype=np.int64)


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


@njit(cache=True)
def strain_conversions(tick, k):
    """AD7195 conversions completed by the end of ``tick`` (integer clock, exact)."""
    return (tick * int(k[K_TICK_NS]) * int(k[K_ODR])) // 1_000_000_000


@njit(cache=True)
def ssi_count(theta_m, k):
    n = k[K_SSI_N]
    return int(math.floor(theta_m * n / TWO_PI + k[K_SSI_MOUNT] + EPS_COUNT)) % int(n)


@njit(cache=True)
def abi_count(theta_m, k):
    return int(math.floor(theta_m * k[K_ABI_N] / TWO_PI + EPS_COUNT))


@njit(cache=True)
def biss_count(x_m, k):
    c = int(math.floor(x_m / LINEAR_COUNT_M + EPS_COUNT)) + int(k[K_BISS_ZERO])
    return c % int(k[K_BISS_MOD])


@njit(cache=True)
def strain_code(force_n, k):
    x = force_n * k[K_STRAIN_SCALE] + MIDSCALE
    if x < -0.5:
        return 0
    if x >= CODE_MAX + 0.5:
        return CODE_MAX
    return int(math.floor(x + 0.5))


@njit(cache=True)
def strain_clamped(force_n, k):
    """True when the AD7195 clamps this force to 0 or CODE_MAX: the part then sets ERR in
    its status byte and the board's master rejects the read (strain_ok = 0)."""
    x = force_n * k[K_STRAIN_SCALE] + MIDSCALE
    return x < -0.5 or x >= CODE_MAX + 0.5


@njit(cache=True)
def pressure_code(p_pa, k):
    v = k[K_P_V0] + p_pa / k[K_P_PA_PER_V]
    return adc_code(v / k[K_ADC_LSB], k[K_ADC_MAX])


@njit(cache=True)
def temperature_code(t_c, k):
    v = k[K_T_V0] + t_c * k[K_T_V_PER_C]
    return adc_code(v / k[K_ADC_LSB], k[K_ADC_MAX])


@njit(cache=True)
def current_code(i_a, k):
    return adc_code(i_a / k[K_I_LSB] + k[K_I_MID], k[K_I_MAX])


@njit(cache=True)
def hall_code(theta_m, k):
    x = (k[K_POLE_PAIRS] * theta_m - k[K_HALL_OFFSET]) / (math.pi / 3.0)
    return HALL_SEQUENCE[int(math.floor(x)) % 6]


@njit(cache=True)
def digitise(y, k, tick, raw):
    """Fill the raw sensor words (``firmware_model.fpga.layout.R_*``) from plant outputs
    ``y`` at ``tick``. Every link delivers a valid frame unless an encoder is marked dead
    (``K_MOTOR_DEAD``/``K_PISTON_DEAD``, fault injection): its master then sees no valid
    frame (OK = 0) and its counts hold."""
    theta = y[L.Y_THETA_M]
    if k[K_MOTOR_DEAD] > 0.5:
        raw[B.R_SSI_OK] = 0
    else:
        raw[B.R_SSI] = ssi_count(theta, k)
        raw[B.R_SSI_OK] = 1
        raw[B.R_ABI] = abi_count(theta, k) & 0xFFFF
    if k[K_PISTON_DEAD] > 0.5:
        raw[B.R_BISS_OK] = 0
    else:
        raw[B.R_BISS] = biss_count(y[L.Y_X_PISTON], k)
        raw[B.R_BISS_OK] = 1
    new = strain_conversions(tick, k) != strain_conversions(tick - 1, k)
    raw[B.R_STRAIN_NEW] = 1 if new else 0
    if new:
        f = y[L.Y_F_STRAIN]
        if strain_clamped(f, k):
            raw[B.R_STRAIN_OK] = 0  # ERR set: the read is rejected, the last code held
        else:
            raw[B.R_STRAIN] = strain_code(f, k)
            raw[B.R_STRAIN_OK] = 1
    for j in range(5):
        raw[B.R_P_ACC + j] = pressure_code(y[PRESSURE_ROWS[j]], k)
    raw[B.R_TEMP] = temperature_code(y[L.Y_TEMP], k)
    raw[B.R_IA] = current_code(y[L.Y_IA], k)
    raw[B.R_IB] = current_code(y[L.Y_IB], k)
    raw[B.R_HALL] = hall_code(theta, k)
