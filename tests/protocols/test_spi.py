"""Tests of protocols.spi: bit order, waveform codec for the four modes, bit-clocked exchange.

Known answers: there is no public example waveform with sample-level values; the expected
levels below follow from the SPI mode definitions (Motorola SPI Block Guide: CPOL = idle
clock level, CPHA = 1 -> data driven on the leading edge and sampled on the trailing edge)
and from the AD7195 data sheet's statement that it uses mode 3, MSB first. The comms byte
0x58 (read data register) is taken from the AD7195 data sheet / ad7192.c register map.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.errors import CodecError, FrameError
from protocols.spi import (
    MODE0,
    MODE1,
    MODE2,
    MODE3,
    Sample,
    SpiMode,
    bits_to_bytes,
    bytes_to_bits,
    decode_waveform,
    encode_waveform,
    exchange_bytes,
    transfer_waveform,
)

MODES = [MODE0, MODE1, MODE2, MODE3]
bit_lists = st.lists(st.integers(0, 1), max_size=64)


def test_msb_first_bit_order_of_read_data_command() -> None:
    # 0x58 = 0b0101_1000: WEN=0, R/W=1, RS=011, CREAD=0, 00 — sent MSB first.
    assert bytes_to_bits(b"\x58") == [0, 1, 0, 1, 1, 0, 0, 0]
    assert bytes_to_bits(b"\x58", msb_first=False) == [0, 0, 0, 1, 1, 0, 1, 0]


def test_mode3_waveform_shape() -> None:
    wave = encode_waveform([1, 0], [0, 1], MODE3)
    # Idle: CS high, SCLK high (CPOL = 1).
    assert wave[0].cs_n == 1 and wave[0].sclk == 1
    clocks = [s.sclk for s in wave if s.cs_n == 0]
    # Each bit is one falling (shift) then one rising (sample) edge, ending idle high.
    assert clocks == [1, 0, 1, 0, 1]
    # On each rising edge (sampling edge) the data lines carry the bit.
    rising = [s for p, s in zip(wave, wave[1:], strict=False) if p.sclk == 0 and s.sclk == 1]
    assert [(s.mosi, s.miso) for s in rising] == [(1, 0), (0, 1)]


def test_mode0_first_bit_valid_before_first_edge() -> None:
    wave = encode_waveform([1], [1], MODE0)
    cs_fall = next(s for s in wave if s.cs_n == 0)
    assert cs_fall.sclk == 0 and cs_fall.mosi == 1 and cs_fall.miso == 1


@settings(max_examples=150)
@given(st.sampled_from(MODES), st.data())
def test_waveform_round_trip(mode: SpiMode, data: st.DataObject) -> None:
    mosi = data.draw(bit_lists)
    miso = data.draw(st.lists(st.integers(0, 1), min_size=len(mosi), max_size=len(mosi)))
    assert decode_waveform(encode_waveform(mosi, miso, mode), mode) == (mosi, miso)


@given(st.binary(max_size=32), st.booleans())
def test_bytes_bits_round_trip(data: bytes, msb_first: bool) -> None:
    assert bits_to_bytes(bytes_to_bits(data, msb_first), msb_first) == data


@pytest.mark.slow
@settings(max_examples=200)
@given(
    st.sampled_from(MODES),
    st.lists(
        st.one_of(
            st.tuples(*[st.integers(-1, 2)] * 4),
            st.lists(st.integers(0, 1), max_size=5),
            st.none(),
            st.text(max_size=3),
        ),
        max_size=40,
    ),
)
def test_decode_arbitrary_samples_only_codec_errors(mode: SpiMode, samples: list) -> None:
    try:
        mosi, miso = decode_waveform(samples, mode)
    except CodecError:
        return
    assert all(b in (0, 1) for b in mosi + miso)
    assert len(mosi) == len(miso)


def test_clock_glitch_at_chip_select_is_a_frame_error() -> None:
    bad = [Sample(1, 1, 1, 1), Sample(0, 0, 1, 1)]  # CS falls while SCLK is active (mode 3)
    try:
        decode_waveform(bad, MODE3)
    except FrameError:
        return
    raise AssertionError("expected FrameError")


@given(st.lists(st.integers(0, 1), max_size=30).filter(lambda b: len(b) % 8))
def test_partial_byte_is_frame_error(bits: list[int]) -> None:
    try:
        bits_to_bytes(bits)
    except FrameError:
        return
    raise AssertionError("expected FrameError")


class _Echo:
    """A shift-register slave: DOUT is the DIN bit of 8 clocks earlier (initially 1s)."""

    def __init__(self) -> None:
        self.reg = [1] * 8

    def clock(self, din: int) -> int:
        out = self.reg.pop(0)
        self.reg.append(din)
        return out


@given(st.binary(max_size=16))
def test_exchange_through_a_shift_register(data: bytes) -> None:
    out = exchange_bytes(_Echo(), data + b"\x00")
    assert out == b"\xff" + data


def test_transfer_waveform_decodes_to_the_slave_output() -> None:
    mosi = bytes_to_bits(b"\xa5\x3c")
    wave = transfer_waveform(_Echo(), mosi, MODE3)
    got_mosi, got_miso = decode_waveform(wave, MODE3)
    assert got_mosi == mosi
    assert bits_to_bytes(got_miso) == b"\xff\xa5"
