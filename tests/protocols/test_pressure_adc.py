"""Tests of protocols.pressure_adc: sensor transfer, ADC code, flags, scan packing, batch.

Known answers: the sensor chain (Model 89, 0..7 MPa, via AD8290 -> 1.0..3.3 V) is the
thesis's statement; the ADC chip on the driver board is not named anywhere public, so
there is no data-sheet example for its codes. The expected codes below are computed in the
test from the ideal-ADC definition ``code = round(V * 2**12 / 3.3 V)`` (half up), which is
this project's documented assumption, not a value produced by the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import pressure_adc as pa
from protocols.errors import CodecError, FrameError, RangeError
from protocols.pressure_adc import PressureFlag as F

CFG = pa.DEFAULT


def ideal_code(v: float, bits: int = 12, vref: float = 3.3) -> int:
    return min(max(math.floor(v * 2**bits / vref + 0.5), 0), 2**bits - 1)


def test_sensor_transfer_known_points() -> None:
    assert pa.pressure_to_voltage(0.0) == pytest.approx(1.0)
    assert pa.pressure_to_voltage(7e6) == pytest.approx(3.3)
    assert pa.pressure_to_voltage(3.5e6) == pytest.approx(2.15)
    assert pa.voltage_to_pressure(2.15) == pytest.approx(3.5e6)


def test_codes_and_flags_at_known_points() -> None:
    zero = pa.pressure_to_code(0.0)
    assert zero == ideal_code(1.0) == 1241
    assert pa.code_to_pressure(zero).flags == F.OK
    assert pa.pressure_to_code(3.5e6) == ideal_code(2.15)
    # Full scale (3.3 V = VREF) is beyond the top code: saturated.
    assert pa.pressure_to_code(7e6) == 4095
    assert pa.code_to_pressure(4095).flags == F.SATURATED
    # Wire break: the line floats to ~0 V.
    assert pa.code_to_pressure(pa.voltage_to_code(0.0)).flags == F.WIRE_BREAK | F.UNDER_RANGE
    # Below the live zero but not a wire break.
    assert pa.code_to_pressure(pa.voltage_to_code(0.8)).flags == F.UNDER_RANGE
    assert pa.code_to_pressure(pa.voltage_to_code(0.97)).flags == F.OK  # inside tolerance


def test_over_range_only_with_a_larger_reference() -> None:
    cfg = pa.PressureAdcConfig(vref_v=5.0)
    code = pa.voltage_to_code(3.5, cfg)
    assert pa.code_to_pressure(code, cfg).flags == F.OVER_RANGE


def test_exhaustive_code_round_trip() -> None:
    for code in range(CFG.code_max + 1):
        r = pa.code_to_pressure(code)
        assert pa.pressure_to_code(r.pressure_pa) == code
        assert pa.voltage_to_code(r.voltage_v) == code


@settings(max_examples=100)
@given(st.integers(8, 16), st.floats(2.5, 5.0), st.data())
def test_code_round_trip_other_resolutions(bits: int, vref: float, data: st.DataObject) -> None:
    cfg = pa.PressureAdcConfig(bits=bits, vref_v=vref)
    code = data.draw(st.integers(0, cfg.code_max))
    assert pa.pressure_to_code(pa.code_to_pressure(code, cfg).pressure_pa, cfg) == code


@given(st.floats(0.0, 6.99e6))
def test_pressure_within_half_lsb(p: float) -> None:
    half_lsb_pa = CFG.lsb_v * CFG.pa_per_v / 2
    assert abs(pa.code_to_pressure(pa.pressure_to_code(p)).pressure_pa - p) <= half_lsb_pa + 1e-6


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=2)))
def test_encode_arbitrary_only_range_error(x: object) -> None:
    try:
        code = pa.pressure_to_code(x)  # type: ignore[arg-type]
    except RangeError:
        return
    assert 0 <= code <= CFG.code_max


@given(st.integers(-(2**20), 2**20))
def test_decode_arbitrary_code_only_range_error(code: int) -> None:
    try:
        r = pa.code_to_pressure(code)
    except RangeError:
        assert not 0 <= code <= CFG.code_max
        return
    assert r.code == code


@given(st.lists(st.integers(0, 4095), min_size=8, max_size=8))
def test_scan_pack_round_trip(codes: list[int]) -> None:
    assert pa.unpack_scan(pa.pack_scan(codes)) == codes


@given(st.binary(max_size=20))
def test_unpack_arbitrary_bytes(data: bytes) -> None:
    try:
        codes = pa.unpack_scan(data)
    except FrameError:
        return
    assert len(data) == 16 and all(0 <= c <= 4095 for c in codes)


def test_unpack_rejects_high_bits() -> None:
    with pytest.raises(FrameError):
        pa.unpack_scan(b"\x00\x10" + bytes(14))


def test_scan_encode_decode() -> None:
    pressures = [0.0, 1e6, 2e6, 3e6, 4e6, 5e6, 6e6, 6.5e6]
    readings = pa.decode_scan(pa.encode_scan(pressures))
    for p, r in zip(pressures, readings, strict=True):
        assert r.pressure_pa == pytest.approx(p, abs=CFG.lsb_v * CFG.pa_per_v)
        assert r.ok
    with pytest.raises(CodecError):
        pa.decode_scan([0] * 7)


@settings(max_examples=30)
@given(st.lists(st.integers(0, 4095), max_size=64))
def test_batch_matches_scalar(codes: list[int]) -> None:
    p, flags = pa.decode_codes(np.array(codes, dtype=np.uint16))
    for i, c in enumerate(codes):
        r = pa.code_to_pressure(c)
        assert p[i] == r.pressure_pa
        assert flags[i] == int(r.flags)


def test_batch_rejects_bad_codes() -> None:
    with pytest.raises(RangeError):
        pa.decode_codes(np.array([4096], dtype=np.uint16))
    with pytest.raises(RangeError):
        pa.decode_codes(np.array([0.5]))


def test_numpy_scalar_codes_accepted() -> None:
    assert pa.code_to_pressure(np.uint16(0)).pressure_pa == pytest.approx(-1.0 * CFG.pa_per_v)
    assert pa.pack_scan([np.uint16(1)] * 8) == b"\x01\x00" * 8
