"""Pressure channels: sensor transfer (Pa <-> V) and the driver board's 8-channel ADC (V <-> code).

Chain: Measurement Specialties Model 89 (0..7 MPa) -> AD8290 amplifier -> 1.0 V at 0 MPa ..
3.3 V at 7 MPa (thesis) -> an 8-channel ADC on the driver board.

The thesis does not name the ADC chip, so no chip-specific serial frame is modelled; the
codec is value <-> code, plus a byte packing of one 8-channel scan for logs. Default
resolution: 12 bit with a 3.3 V reference (a common SAR ADC size on 3.3 V boards; all
numbers are in :class:`PressureAdcConfig`). Ideal ADC: ``code = round(V / LSB)`` with
``LSB = vref / 2**bits``, clamped to 0 .. 2**bits - 1. Because the sensor's full-scale
voltage equals the reference, the top code 4095 (3.2992 V, 6.9973 MPa) already means
"at or above full scale": it is flagged SATURATED.

Fault flags from the decoded voltage: WIRE_BREAK below 0.5 V (an open sensor line reads
near 0 V), UNDER_RANGE below 0.95 V (the live zero is 1.0 V; 50 mV tolerance),
OVER_RANGE above full-scale voltage + tolerance (only reachable if vref > 3.3 V).
"""

from __future__ import annotations

import enum
import math
import numbers
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from protocols.errors import (
    FrameError,
    RangeError,
    as_bytes,
    as_int_array,
    as_sequence,
    finite_number,
)


class PressureFlag(enum.IntFlag):
    """Per-sample fault flags of a pressure reading."""

    OK = 0
    WIRE_BREAK = 1  # voltage near 0 V: open sensor line or dead amplifier
    UNDER_RANGE = 2  # below the 1 V live zero by more than the tolerance
    OVER_RANGE = 4  # above the sensor's full-scale voltage by more than the tolerance
    SATURATED = 8  # ADC at its top code: true value at or beyond the top of the range


@dataclass(frozen=True)
class PressureAdcConfig:
    """Sensor transfer and ADC parameters (V, Pa). Defaults: Model 89 + AD8290, 12-bit 3.3 V."""

    bits: int = 12
    vref_v: float = 3.3
    v_at_zero: float = 1.0
    v_at_full: float = 3.3
    p_full_pa: float = 7.0e6
    wire_break_v: float = 0.5
    under_range_v: float = 0.95
    over_range_tol_v: float = 0.05
    channels: int = 8

    @property
    def code_max(self) -> int:
        """Largest ADC code (all ones)."""
        return (1 << self.bits) - 1

    @property
    def lsb_v(self) -> float:
        """Voltage of one code step (V)."""
        return self.vref_v / (1 << self.bits)

    @property
    def pa_per_v(self) -> float:
        """Sensor sensitivity seen at the ADC input (Pa per V)."""
        return self.p_full_pa / (self.v_at_full - self.v_at_zero)


DEFAULT = PressureAdcConfig()


@dataclass(frozen=True)
class PressureReading:
    """One decoded channel: pressure (Pa, gauge), ADC input voltage (V), code, flags."""

    pressure_pa: float
    voltage_v: float
    code: int
    flags: PressureFlag

    @property
    def ok(self) -> bool:
        """True when no fault flag is set."""
        return self.flags == PressureFlag.OK




def pressure_to_voltage(pressure_pa: float, cfg: PressureAdcConfig = DEFAULT) -> float:
    """Sensor + amplifier output (V) for a gauge pressure (Pa); linear, unclamped."""
    return cfg.v_at_zero + finite_number(pressure_pa, "pressure_pa") / cfg.pa_per_v


def voltage_to_pressure(voltage_v: float, cfg: PressureAdcConfig = DEFAULT) -> float:
    """Gauge pressure (Pa) for a sensor output voltage (V); linear, unclamped."""
    return (finite_number(voltage_v, "voltage_v") - cfg.v_at_zero) * cfg.pa_per_v


def voltage_to_code(voltage_v: float, cfg: PressureAdcConfig = DEFAULT) -> int:
    """ADC code for an input voltage: nearest code, clamped to the ADC range like the part."""
    x = finite_number(voltage_v, "voltage_v") / cfg.lsb_v
    if x < 0.5:
        return 0
    if x >= cfg.code_max - 0.5:
        return cfg.code_max
    return int(math.floor(x + 0.5))


def _check_code(code: int, cfg: PressureAdcConfig) -> int:
    """Return ``code`` as a Python int (numpy integers accepted) or raise RangeError."""
    if not isinstance(code, numbers.Integral) or isinstance(code, bool):
        raise RangeError(f"{code!r} is not a {cfg.bits}-bit code")
    code = int(code)
    if not 0 <= code <= cfg.code_max:
        raise RangeError(f"{code} is not a {cfg.bits}-bit code")
    return code


def code_to_voltage(code: int, cfg: PressureAdcConfig = DEFAULT) -> float:
    """ADC input voltage (V) a code stands for (``code * LSB``)."""
    return _check_code(code, cfg) * cfg.lsb_v


def pressure_to_code(pressure_pa: float, cfg: PressureAdcConfig = DEFAULT) -> int:
    """Code the ADC gives for a pressure (Pa); saturates at the ADC's ends."""
    return voltage_to_code(pressure_to_voltage(pressure_pa, cfg), cfg)


def flags_of(code: int, cfg: PressureAdcConfig = DEFAULT) -> PressureFlag:
    """Fault flags of one code (see module docstring for the thresholds)."""
    code = _check_code(code, cfg)
    v = code * cfg.lsb_v
    flags = PressureFlag.OK
    if v < cfg.wire_break_v:
        flags |= PressureFlag.WIRE_BREAK
    if v < cfg.under_range_v:
        flags |= PressureFlag.UNDER_RANGE
    if v > cfg.v_at_full + cfg.over_range_tol_v:
        flags |= PressureFlag.OVER_RANGE
    if code == cfg.code_max:
        flags |= PressureFlag.SATURATED
    return flags


def code_to_pressure(code: int, cfg: PressureAdcConfig = DEFAULT) -> PressureReading:
    """Decode one code to pressure (Pa), voltage (V) and fault flags.

    The pressure is the linear value even when flagged (negative below the live zero), so a
    caller can log it; it should act on ``flags``.
    """
    flags = flags_of(code, cfg)
    code = int(code)
    v = code * cfg.lsb_v
    return PressureReading((v - cfg.v_at_zero) * cfg.pa_per_v, v, code, flags)


def encode_scan(pressures_pa: Sequence[float], cfg: PressureAdcConfig = DEFAULT) -> list[int]:
    """Codes of one scan of all channels (``cfg.channels`` pressures in Pa)."""
    pressures_pa = as_sequence(pressures_pa, "pressures_pa", RangeError)
    if len(pressures_pa) != cfg.channels:
        raise RangeError(f"a scan has {cfg.channels} channels, got {len(pressures_pa)}")
    return [pressure_to_code(p, cfg) for p in pressures_pa]


def decode_scan(codes: Sequence[int], cfg: PressureAdcConfig = DEFAULT) -> list[PressureReading]:
    """Readings of one scan of all channels."""
    codes = as_sequence(codes, "pressure scan codes")
    if len(codes) != cfg.channels:
        raise FrameError(f"a scan has {cfg.channels} channels, got {len(codes)}")
    return [code_to_pressure(c, cfg) for c in codes]


def pack_scan(codes: Sequence[int], cfg: PressureAdcConfig = DEFAULT) -> bytes:
    """Log format of one scan: one little-endian uint16 per channel, unused high bits 0."""
    codes = as_sequence(codes, "pressure scan codes", RangeError)
    if len(codes) != cfg.channels:
        raise RangeError(f"a scan has {cfg.channels} channels, got {len(codes)}")
    return struct.pack(f"<{cfg.channels}H", *(_check_code(c, cfg) for c in codes))


def unpack_scan(data: bytes, cfg: PressureAdcConfig = DEFAULT) -> list[int]:
    """Inverse of :func:`pack_scan`; :class:`FrameError` on wrong length or high bits set."""
    data = as_bytes(data, "pressure scan")
    if len(data) != 2 * cfg.channels:
        raise FrameError(f"scan needs {2 * cfg.channels} bytes, got {len(data)}")
    codes = list(struct.unpack(f"<{cfg.channels}H", data))
    if any(c > cfg.code_max for c in codes):
        raise FrameError(f"code above {cfg.bits} bits in scan")
    return codes


def decode_codes(
    codes: np.ndarray, cfg: PressureAdcConfig = DEFAULT
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised decode: ``(pressure_pa float64, flags uint8)`` for an array of codes.

    Same arithmetic and thresholds as :func:`code_to_pressure`. Raises :class:`RangeError`
    for a non-integer array or a code outside the ADC range.
    """
    c = as_int_array(codes, "pressure codes", 0, cfg.code_max)
    if c.dtype.kind == "b":
        raise RangeError("pressure codes: a bool array is not ADC codes")
    v = c * cfg.lsb_v
    pressure = (v - cfg.v_at_zero) * cfg.pa_per_v
    flags = (
        (v < cfg.wire_break_v) * np.uint8(PressureFlag.WIRE_BREAK)
        | (v < cfg.under_range_v) * np.uint8(PressureFlag.UNDER_RANGE)
        | (v > cfg.v_at_full + cfg.over_range_tol_v) * np.uint8(PressureFlag.OVER_RANGE)
        | (c == cfg.code_max) * np.uint8(PressureFlag.SATURATED)
    ).astype(np.uint8)
    return pressure, flags
