"""The five pressure sensors (0..7 MPa -> 1..3.3 V) and the oil temperature sensor on the
driver board's 8-channel ADC.

Value level (compiled): code = floor(V / LSB + 1/2), saturated (as
:func:`protocols.pressure_adc.voltage_to_code`). Line level: :func:`adc_scan`, one
8-channel scan (:func:`protocols.pressure_adc.pack_scan`): channels 0..4 the pressures in
register order, 5 the oil temperature, 6..7 zero.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.fpga.masters import PRESSURE_CHANNELS, TEMPERATURE_CHANNEL
from plant import layout as L
from plant.sensors.chips import (
    K_ADC_LSB,
    K_ADC_MAX,
    K_P_PA_PER_V,
    K_P_V0,
    K_T_V0,
    K_T_V_PER_C,
    adc_code,
)
from protocols.pressure_adc import DEFAULT as ADC
from protocols.pressure_adc import pack_scan

#: Plant output rows read by the five pressure channels, in register order.
PRESSURE_ROWS = np.asarray((L.Y_P_ACC, L.Y_P_PUMP_A, L.Y_P_PUMP_B, L.Y_P_CYL_A, L.Y_P_CYL_B),
                           dtype=np.int64)


@njit(cache=True)
def pressure_code(p_pa, k):
    v = k[K_P_V0] + p_pa / k[K_P_PA_PER_V]
    return adc_code(v / k[K_ADC_LSB], k[K_ADC_MAX])


@njit(cache=True)
def temperature_code(t_c, k):
    v = k[K_T_V0] + t_c * k[K_T_V_PER_C]
    return adc_code(v / k[K_ADC_LSB], k[K_ADC_MAX])


def zero_code_pressure(k) -> float:  # noqa: ANN001
    """A pressure the ADC reads as code 0 (a dead sensor, for fault injection)."""
    return (-k[K_P_V0] - k[K_ADC_LSB]) * k[K_P_PA_PER_V]


def zero_code_temperature(k) -> float:  # noqa: ANN001
    """A temperature the ADC reads as code 0 (a dead sensor, for fault injection)."""
    return (-k[K_T_V0] - k[K_ADC_LSB]) / k[K_T_V_PER_C]


def adc_scan(y: np.ndarray, k: np.ndarray, scan: list[int]) -> bytes:
    """The packed 8-channel scan of the plant outputs ``y`` (``scan``: a work list)."""
    for ch, row in zip(PRESSURE_CHANNELS, PRESSURE_ROWS, strict=True):
        scan[ch] = pressure_code(float(y[row]), k)
    scan[TEMPERATURE_CHANNEL] = temperature_code(float(y[L.Y_TEMP]), k)
    return pack_scan(scan)


SCAN_CHANNELS = ADC.channels
