"""The connecting rod's temperature sensor end to end: plant truth -> ADC code (value level
and bit level) -> the board's upstream register -> the MCU's measurement in degC."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from firmware_model.mcu.measure import Measurements
from hil.sim.actuator import FpgaStack
from plant import layout as L
from plant.config import load_config
from protocols.pressure_adc import DEFAULT as ADC

FITTED = ["sensors.rod_temperature_fitted=true", "effects.oil_temperature.ambient_c=20",
          "effects.strain_drift.rod_time_constant_s=0.05"]


def _heated_readings(cfg, bit_level: bool, n: int = 12) -> list[tuple[float, float]]:
    """(truth, MCU reading) of the rod temperature while a heat gun warms the rod."""
    stack = FpgaStack(cfg, bit_level=bit_level)
    meas = Measurements(calibration(cfg))
    stack.plant.set_ambient(90.0)
    out = []
    for _ in range(n):
        stack.advance(200)
        meas.update(stack.mcu_link.up)
        out.append((float(stack.plant.y[L.Y_T_ROD]), float(meas.rod_temperature_c)))
    return out


@pytest.mark.parametrize("bit_level", [False, True], ids=["value", "bit"])
def test_the_mcu_reads_the_rod_temperature_within_one_code(bit_level):
    cfg = load_config(None, FITTED)
    readings = _heated_readings(cfg, bit_level)
    truth = np.array([t for t, _ in readings])
    got = np.array([m for _, m in readings])
    lsb_c = ADC.lsb_v / cfg.get("sensors.rod_temperature_v_per_c")
    assert truth[-1] - truth[0] > 100 * lsb_c, "the rod did not warm: the test shows nothing"
    # Half a code of rounding, plus what the rod warms while the word crosses the link.
    lag_c = np.max(np.abs(np.diff(truth))) * 0.1
    assert np.all(np.abs(got - truth) <= 0.5 * lsb_c + lag_c + 1e-3), np.abs(got - truth).max()


def test_the_firmware_decodes_with_its_own_calibration():
    """Firmware built for another slope reads the same code as another temperature."""
    cfg = load_config(None, FITTED)
    wrong = cfg.with_overrides({"firmware.rod_temperature_v_per_c": 0.0200})
    (_, right), = _heated_readings(cfg, False, n=1)
    (_, other), = _heated_readings(wrong, False, n=1)
    assert abs(other - right * cfg.get("sensors.rod_temperature_v_per_c") / 0.0200) < 1e-3
    assert abs(other - right) > 0.5


def test_an_unfitted_sensor_leaves_its_channel_at_zero():
    stack = FpgaStack(load_config(None, []))
    stack.advance(200)
    assert stack.raw[B.RAW_NAMES.index("rod_temperature")] == 0
    assert stack.board.up[B.up_address("rod_temperature")] == 0
