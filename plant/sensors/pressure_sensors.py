"""The five pressure sensors (0..7 MPa -> 1..3.3 V) and the oil temperature sensor (TMP36-like,
0.5 V + 10 mV/degC) on the driver board's 8-channel ADC.

Their channels, registers and transfer are rows of
:data:`firmware_model.fpga.layout.ANALOG_INPUTS`; what this part adds is what each one
measures in the plant (:data:`ANALOG_SOURCES`). The value-level code
(:func:`plant.sensors.chips.analog_code`) is ``floor(V / LSB + 1/2)``, saturated (as
:func:`protocols.pressure_adc.voltage_to_code`); the line level is the harness's ADC scan.
"""

from __future__ import annotations

from firmware_model.fpga.layout import ANALOG_INPUTS
from plant import layout as L
from plant.sensors.chips import analog_zero_value

#: Analog input (``ANALOG_INPUTS`` name) -> the plant output (``plant.layout.Y_*``) it reads.
ANALOG_SOURCES = {
    "p_acc": L.Y_P_ACC, "p_pump_a": L.Y_P_PUMP_A, "p_pump_b": L.Y_P_PUMP_B,
    "p_cyl_a": L.Y_P_CYL_A, "p_cyl_b": L.Y_P_CYL_B, "temperature": L.Y_TEMP,
}
_INDEX = {a.name: j for j, a in enumerate(ANALOG_INPUTS)}


def zero_code_pressure(k) -> float:  # noqa: ANN001
    """A pressure the ADC reads as code 0 (a dead sensor, for fault injection)."""
    return analog_zero_value(k, _INDEX["p_acc"])


def zero_code_temperature(k) -> float:  # noqa: ANN001
    """A temperature the ADC reads as code 0 (a dead sensor, for fault injection)."""
    return analog_zero_value(k, _INDEX["temperature"])
