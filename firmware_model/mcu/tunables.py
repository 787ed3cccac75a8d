"""The MCU's tunable parameters: what a master may change over CoE (objects from 0x2000,
:mod:`firmware_model.esc.objects`), with units, ranges and where each lives in the program.

Each is one value per actuator. A write is taken by :meth:`firmware_model.mcu.mcu.Mcu.tune`
and applied at the program's next step (:func:`apply`), as the firmware's parameter task
would hand it to the 5 kHz loop between two cycles; the filters keep their state, only their
coefficient changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_model.mcu.filters import DerivativeFilter, HighPassFilter, LowPassFilter

F32 = np.float32


@dataclass(frozen=True)
class Tunable:
    key: str        # the calibration key (``[mcu]`` in the presets)
    name: str
    unit: str
    low: float
    high: float


#: In object order: object 0x2000 + position. Ranges: what the firmware accepts (the
#: derivative filter below the 5 kHz loop's Nyquist rate; limits within the hardware's).
TUNABLES: tuple[Tunable, ...] = (
    Tunable("kp_force", "Force loop gain Kp", "N/N", 0.0, 20.0),
    Tunable("kd_force_s", "Force loop derivative gain Kd", "s", 0.0, 0.05),
    Tunable("derivative_filter_hz", "Derivative filter cutoff", "Hz", 1.0, 2000.0),
    Tunable("friction_observer_hz", "Friction observer bandwidth", "Hz", 0.0, 500.0),
    Tunable("seal_observer_hz", "Seal friction observer bandwidth", "Hz", 0.0, 500.0),
    Tunable("complementary_cutoff_hz", "Complementary filter cutoff", "Hz", 0.001, 100.0),
    Tunable("position_kp_n_per_m", "Local position loop gain", "N/m", 0.0, 1.0e6),
    Tunable("force_limit_n", "Force command limit", "N", 0.0, 3000.0),
    Tunable("pressure_limit_pa", "Pressure limit", "Pa", 0.0, 1.0e7),
    Tunable("current_limit_a", "Current reference limit", "A", 0.0, 30.0),
    Tunable("command_timeout_s", "Command watchdog timeout", "s", 0.001, 1.0),
)
BY_KEY = {t.key: t for t in TUNABLES}


def in_range(key: str, value: float) -> int:
    """0 if ``value`` is within the range of ``key``; +1 above it, -1 below (or NaN)."""
    t = BY_KEY[key]
    if math.isnan(value) or value < t.low:
        return -1
    return 1 if value > t.high else 0


def apply(mcu, i: int, key: str, value: float) -> None:  # noqa: ANN001 (Mcu: no cycle)
    """Set tunable ``key`` of actuator ``i`` of program ``mcu`` (between two steps)."""
    c = mcu.ctrl[i]
    dt = c.dt_s  # (not the float32 dt: the coefficient as a calibration with value gives it)
    if key == "kp_force":
        mcu.own_gains[i][1] = c.kp = F32(value)
    elif key == "kd_force_s":
        c.kd = F32(value)
    elif key == "derivative_filter_hz":
        c.derivative.a = DerivativeFilter(value, dt).a
    elif key == "friction_observer_hz":
        c.observer.ko = F32(2.0 * math.pi * value)
    elif key == "seal_observer_hz":
        c.seal_observer.a = LowPassFilter(value, dt).a
    elif key == "complementary_cutoff_hz":
        c.highpass.a = HighPassFilter(value, dt).a
    elif key == "position_kp_n_per_m":
        mcu.own_gains[i][0] = c.k_pos = F32(value)
    elif key == "force_limit_n":
        c.force_limit = value
        c.f_lim = F32(min(value, c.kc * c.pressure_limit))
    elif key == "pressure_limit_pa":
        c.pressure_limit = value
        c.p_lim = F32(value)
        c.f_lim = F32(min(c.force_limit, c.kc * value))
    elif key == "current_limit_a":
        c.i_lim = F32(value)
    elif key == "command_timeout_s":
        off = mcu.off_ticks - mcu.timeout_ticks
        mcu.timeout_ticks = round(value / mcu.tick_s)
        mcu.off_ticks = mcu.timeout_ticks + off
    else:
        raise KeyError(f"not a tunable MCU parameter: {key!r}")
