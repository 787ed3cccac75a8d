"""The connecting rod's temperature sensor: a linear active thermistor (Microchip MCP9701,
400 mV at 0 degC, 19.5 mV/degC, -10..125 degC) glued on the rod beside the strain gauge,
on channel 6 of the driver board's 8-channel ADC.

Thesis 4.4 names it as the way to compensate the strain gauge's thermal drift (2.5 N/degC,
linear in the rod's temperature); the Hydra units of Table 6.3 do not have it, so it is
fitted only when ``sensors.rod_temperature_fitted`` is true (an empty channel reads 0 V).
Its channel, register and transfer are its row of
:data:`firmware_model.fpga.layout.ANALOG_INPUTS`; it measures the plant's rod temperature.
"""

from __future__ import annotations

from plant import layout as L

#: Analog input (``ANALOG_INPUTS`` name) -> the plant output (``plant.layout.Y_*``) it reads.
ANALOG_SOURCES = {"rod_temperature": L.Y_T_ROD}
