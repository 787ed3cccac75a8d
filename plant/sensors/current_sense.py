"""The driver board's phase-current sensing: 12-bit offset binary over +/- I_FS (nearest
code, saturated), phases a and b, sent to the FPGA as one 4-byte frame
(:data:`firmware_model.fpga.masters.CURRENT_FRAME`, an assumed format)."""

from __future__ import annotations

from numba import njit

from firmware_model.fpga.masters import pack_currents
from plant.sensors.chips import K_I_LSB, K_I_MAX, K_I_MID, adc_code


@njit(cache=True)
def current_code(i_a, k):
    return adc_code(i_a / k[K_I_LSB] + k[K_I_MID], k[K_I_MAX])


def zero_code_current(k) -> float:  # noqa: ANN001
    """A current the ADC reads as code 0 (a dead channel, for fault injection)."""
    return -(k[K_I_MID] + 1.0) * k[K_I_LSB]


def current_frame(i_a: float, i_b: float, k) -> bytes:  # noqa: ANN001
    """The frame of one sample of phases a and b."""
    return pack_currents(current_code(i_a, k), current_code(i_b, k))
