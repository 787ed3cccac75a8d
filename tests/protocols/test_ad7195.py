"""Tests of protocols.ad7195: registers, codes, device model and firmware-like master.

Known answers come from the AD7195 data sheet (Analog Devices, Rev. 0: register map,
"Power-on/reset" values, ADC transfer function) and Linux drivers/iio/adc/ad7192.c (bit
masks, ID_AD7195 = 0x6, the 48-ones reset it sends, ACX = configuration bit 22):

* mode register reset 0x080060, configuration register reset 0x000117, status reset 0x80,
  GPOCON reset 0x00, offset reset 0x800000; ID low nibble 0x6;
* comms byte 0x58 reads the data register once, 0x5C enters continuous read, 0x60 reads
  the ID, 0x08 / 0x10 write mode / configuration;
* bipolar code = 2^23 * (AIN * gain / VREF + 1): 0 V -> 0x800000, -VREF/gain -> 0x000000;
  unipolar code = 2^24 * AIN * gain / VREF.
The force scale (+/-3000 N onto the bipolar range) is this project's definition (thesis:
"full span at 3000 N"); its known answers follow from that definition, not a data sheet.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import ad7195 as ad
from protocols.errors import CodecError, CrcError, FrameError, RangeError
from protocols.spi import MODE3, bytes_to_bits, decode_waveform, exchange_bytes, transfer_waveform

REGISTERS = [ad.Comms, ad.Status, ad.Mode, ad.Config, ad.Gpocon]


def read_reg(dev: ad.AD7195Device, comms: int, nbytes: int) -> int:
    resp = dev.transfer(bytes([comms]) + bytes(nbytes))
    return int.from_bytes(resp[1:], "big")


# ---- known answers ------------------------------------------------------------------


def test_comms_bytes_from_datasheet() -> None:
    assert ad.comms_byte(ad.REG_DATA, read=True) == 0x58
    assert ad.comms_byte(ad.REG_DATA, read=True, cread=True) == 0x5C
    assert ad.comms_byte(ad.REG_ID, read=True) == 0x60
    assert ad.comms_byte(ad.REG_MODE, read=False) == 0x08
    assert ad.comms_byte(ad.REG_CONFIG, read=False) == 0x10
    assert ad.AD7195Master().data_read_request()[0] == 0x58


def test_reset_values_read_through_the_serial_protocol() -> None:
    dev = ad.AD7195Device()
    assert read_reg(dev, 0x48, 3) == 0x080060  # mode
    assert read_reg(dev, 0x50, 3) == 0x000117  # configuration
    assert read_reg(dev, 0x40, 1) == 0x80  # status: /RDY = 1, no result yet
    assert read_reg(dev, 0x68, 1) == 0x00  # GPOCON
    assert read_reg(dev, 0x70, 3) == 0x800000  # offset
    assert read_reg(dev, 0x78, 3) >> 20 == 0x5  # full-scale 0x5XXXX0
    assert read_reg(dev, 0x60, 1) & 0x0F == 0x6  # ID: AD7195


def test_reset_register_fields() -> None:
    mode = ad.Mode.decode(0x080060)
    assert (mode.md, mode.dat_sta, mode.clk, mode.fs) == (0, 0, 2, 96)
    cfg = ad.Config.decode(0x000117)
    assert (cfg.channels, cfg.buf, cfg.unipolar, cfg.gain) == (1, 1, 0, 7)
    assert ad.GAIN_OF_CODE[cfg.gain] == 128
    assert ad.Config(acx=1).encode() & (1 << 22)  # ACX is configuration bit 22
    assert ad.Mode(dat_sta=1).encode() == 0x180060


def test_transfer_function_known_codes() -> None:
    assert ad.voltage_to_code(0.0, 5.0, 1) == (0x800000, False)
    assert ad.voltage_to_code(-5.0, 5.0, 1) == (0x000000, False)
    assert ad.voltage_to_code(2.5, 5.0, 1) == (0xC00000, False)
    assert ad.voltage_to_code(5.0 / 128, 5.0, 128) == (0xFFFFFF, True)  # +FS clamps, ERR
    assert ad.voltage_to_code(0.0, 5.0, 1, bipolar=False) == (0, False)
    assert ad.voltage_to_code(2.5, 5.0, 1, bipolar=False) == (0x800000, False)
    assert ad.force_to_code(0.0) == 0x800000
    assert ad.force_to_code(-3000.0) == 0x000000
    assert ad.force_to_code(1500.0) == 0xC00000
    assert ad.code_to_force(0xFFFFFF) == pytest.approx(3000.0 - 3000.0 / 2**23)
    with pytest.raises(RangeError):
        ad.force_to_code(3000.0)


# ---- registers ----------------------------------------------------------------------


@pytest.mark.parametrize("reg", REGISTERS)
def test_reserved_mask_covers_the_unused_bits(reg: type[ad.BitRegister]) -> None:
    used = 0
    for _, msb, lsb in reg.layout():
        mask = ((1 << (msb - lsb + 1)) - 1) << lsb
        assert not used & mask, "fields overlap"
        used |= mask
    assert used | reg.reserved_mask() == (1 << reg.WIDTH) - 1


@settings(max_examples=60)
@given(st.sampled_from(REGISTERS), st.integers(0, 2**24 - 1))
def test_register_round_trip(reg: type[ad.BitRegister], raw: int) -> None:
    word = raw & ((1 << reg.WIDTH) - 1) & ~reg.reserved_mask()
    assert reg.decode(word).encode() == word


@settings(max_examples=100)
@given(st.sampled_from(REGISTERS), st.integers(-(2**33), 2**33))
def test_register_decode_arbitrary_only_frame_error(reg: type[ad.BitRegister], w: int) -> None:
    try:
        value = reg.decode(w)
    except FrameError:
        assert w < 0 or w >= 1 << reg.WIDTH or w & reg.reserved_mask()
        return
    assert value.encode() == w


# ---- codes --------------------------------------------------------------------------


@settings(max_examples=200)
@given(
    st.integers(0, ad.CODE_MAX),
    st.sampled_from(sorted(ad.GAIN_OF_CODE.values())),
    st.booleans(),
)
def test_code_voltage_round_trip(code: int, gain: int, bipolar: bool) -> None:
    v = ad.code_to_voltage(code, 4.096, gain, bipolar)
    assert ad.voltage_to_code(v, 4.096, gain, bipolar) == (code, False)


@settings(max_examples=200)
@given(st.integers(0, ad.CODE_MAX))
def test_code_force_round_trip(code: int) -> None:
    assert ad.force_to_code(ad.code_to_force(code)) == code


@given(st.floats(-2999.9, 2999.9))
def test_force_code_force_within_half_lsb(force: float) -> None:
    lsb = 3000.0 / 2**23
    assert abs(ad.code_to_force(ad.force_to_code(force)) - force) <= lsb / 2 + 1e-12


@given(st.one_of(st.floats(allow_nan=True), st.integers(), st.text(max_size=2), st.none()))
def test_force_encode_arbitrary_only_range_error(x: object) -> None:
    try:
        code = ad.force_to_code(x)  # type: ignore[arg-type]
    except RangeError:
        return
    assert 0 <= code <= ad.CODE_MAX


# ---- device protocol ----------------------------------------------------------------


def test_master_reads_force_from_device() -> None:
    dev, master = ad.AD7195Device(), ad.AD7195Master()
    assert master.start(dev.transfer) & 0x0F == 0x6
    dev.set_force(1234.5)
    sample = master.read_force(dev.transfer)
    assert sample.force_n == pytest.approx(1234.5, abs=3000.0 / 2**23)
    assert sample.status == 0x00  # fresh, no error, channel 0
    with pytest.raises(FrameError):  # second read without a new conversion: stale
        master.read_force(dev.transfer)


@settings(max_examples=150)
@given(st.integers(0, ad.CODE_MAX), st.integers(0, 7))
def test_data_read_round_trip_over_the_code_range(code: int, channel: int) -> None:
    dev = ad.AD7195Device()
    master = ad.AD7195Master(channel=channel)
    master.start(dev.transfer)
    dev.set_code(code, channel=channel)
    sample = master.read_force(dev.transfer)
    assert sample.code == code
    assert sample.force_n == ad.code_to_force(code)


def test_data_read_without_status_is_24_bit() -> None:
    dev = ad.AD7195Device()
    master = ad.AD7195Master(status_appended=False)
    master.start(dev.transfer)
    dev.set_code(0x123456)
    resp = dev.transfer(master.data_read_request())
    assert len(resp) == 4 and resp[1:] == bytes.fromhex("123456")
    assert master.parse_data_read(resp).code == 0x123456


def test_err_channel_and_parity_checks() -> None:
    dev = ad.AD7195Device()
    master = ad.AD7195Master(check_parity=True)
    master.start(dev.transfer)
    dev.set_input(1.0)  # 1 V at gain 128 with 5 V reference: far over range
    with pytest.raises(RangeError):
        master.read_force(dev.transfer)
    dev.set_code(0x800001, channel=1)
    with pytest.raises(FrameError):
        master.read_force(dev.transfer)
    dev.set_code(0x800000)  # one 1 bit (odd) -> PARITY = 1 with ENPAR
    resp = bytearray(dev.transfer(master.data_read_request()))
    assert resp[4] & 0x10
    resp[3] ^= 0x02  # corrupt one data bit
    with pytest.raises(CrcError):
        master.parse_data_read(bytes(resp))


def test_forty_ones_reset_but_not_thirty_nine() -> None:
    for ones, expect in ((39, 0x180060), (40, 0x080060)):
        dev = ad.AD7195Device()
        ad.AD7195Master.write_register(dev.transfer, ad.REG_MODE, 0x180060)
        bits = [1] * ones + bytes_to_bits(bytes([0x48, 0, 0, 0]))
        out = [dev.clock(b) for b in bits]
        assert int("".join(map(str, out[-24:])), 2) == expect


def test_wen_one_bits_are_skipped() -> None:
    dev = ad.AD7195Device()
    # Three leading 1s (WEN = 1) are ignored; the comms byte 0x60 then follows unaligned.
    bits = [1, 1, 1] + bytes_to_bits(b"\x60\x00")
    out = [dev.clock(b) for b in bits]
    assert int("".join(map(str, out[-8:])), 2) == ad.ID_DEFAULT


def test_write_to_read_only_register_is_swallowed() -> None:
    dev = ad.AD7195Device()
    dev.transfer(bytes([0x18, 0x12, 0x34, 0x56]))  # write "data": 24 bits consumed
    assert read_reg(dev, 0x60, 1) == ad.ID_DEFAULT
    assert dev.data == 0


def test_continuous_read_and_exit() -> None:
    dev = ad.AD7195Device()
    master = ad.AD7195Master()
    master.start(dev.transfer)
    dev.transfer(b"\x5c")
    assert dev.transfer(b"\x00") == b"\xff"  # no result yet: DOUT/RDY high, nothing read
    for code in (0x111111, 0x222222):
        dev.set_code(code)
        assert dev.transfer(bytes(4)) == bytes.fromhex(f"{code:06x}00")
    dev.set_code(0x333333)
    assert dev.transfer(b"\x58\x00\x00\x00") == bytes.fromhex("33333300")  # exit command
    assert not dev.cread
    assert read_reg(dev, 0x60, 1) == ad.ID_DEFAULT


ops = st.lists(
    st.one_of(
        st.binary(min_size=1, max_size=6).map(lambda b: ("bytes", b)),
        st.lists(
            st.sampled_from([0x58, 0x5C, 0x08, 0x10, 0x48, 0x50, 0x60, 0x40, 0x28, 0xFF, 0x00]),
            min_size=1,
            max_size=8,
        ).map(lambda b: ("bytes", bytes(b))),
        st.tuples(st.just("code"), st.integers(0, ad.CODE_MAX), st.integers(0, 7)),
        st.just(("mode", None)),
    ),
    max_size=25,
)


def _state(d: ad.AD7195Device) -> tuple:
    return (d.mode, d.config, d.status, d.data, d.gpocon, d.offset, d.fullscale, d.cread)


@pytest.mark.slow
@settings(max_examples=200)
@given(ops)
def test_byte_path_equals_bit_path(sequence: list) -> None:
    fast, slow = ad.AD7195Device(), ad.AD7195Device()
    for op in sequence:
        if op[0] == "bytes":
            assert fast.transfer(op[1]) == exchange_bytes(slow, op[1])
        elif op[0] == "code":
            fast.set_code(op[1], channel=op[2])
            slow.set_code(op[1], channel=op[2])
        else:  # DAT_STA on, via the protocol
            msg = bytes([0x08]) + (0x180060).to_bytes(3, "big")
            assert fast.transfer(msg) == exchange_bytes(slow, msg)
        assert _state(fast) == _state(slow)


@settings(max_examples=150)
@given(st.binary(max_size=64))
def test_arbitrary_bytes_never_crash_the_device(data: bytes) -> None:
    dev = ad.AD7195Device()
    dev.set_code(0x7FFFFF)
    out = dev.transfer(data)
    assert len(out) == len(data)
    assert 0 <= dev.mode < 2**24 and 0 <= dev.config < 2**24


@settings(max_examples=200)
@given(st.binary(max_size=8), st.booleans(), st.booleans())
def test_master_parse_arbitrary_response(resp: bytes, appended: bool, parity: bool) -> None:
    master = ad.AD7195Master(status_appended=appended, check_parity=parity)
    try:
        sample = master.parse_data_read(resp)
    except CodecError:
        return
    assert len(resp) == (5 if appended else 4)
    if appended:
        assert sample.status is not None
        assert sample.status & 0xC8 == 0 and sample.status & 7 == 0  # fresh, no ERR, ch 0


def test_spi_mode3_waveform_of_a_data_read() -> None:
    dev = ad.AD7195Device()
    ad.AD7195Master().start(dev.transfer)
    dev.set_code(0xABCDEF)
    wave = transfer_waveform(dev, bytes_to_bits(bytes([0x58, 0, 0, 0, 0])), MODE3)
    mosi, miso = decode_waveform(wave, MODE3)
    assert bytes_to_bits(b"\x58") == mosi[:8]
    word = int("".join(map(str, miso[8:])), 2)
    assert word == (0xABCDEF << 8) | 0x00


# ---- batch --------------------------------------------------------------------------


@settings(max_examples=50)
@given(st.lists(st.integers(0, 2**32 - 1), max_size=50))
def test_batch_decode_matches_scalar(words: list[int]) -> None:
    batch = ad.decode_data_words(np.array(words, dtype=np.uint32))
    for i, w in enumerate(words):
        dw = ad.DataWord.decode(w)
        assert batch.code[i] == dw.code
        assert batch.force_n[i] == ad.code_to_force(dw.code)
        assert batch.channel[i] == dw.status & 7
        try:
            ad.check_status(dw.status, channel=None)
            ok = True
        except CodecError:
            ok = False
        assert bool(batch.valid[i]) == ok


def test_batch_rejects_out_of_range_words() -> None:
    with pytest.raises(RangeError):
        ad.decode_data_words(np.array([-1, 5], dtype=np.int64))
    with pytest.raises(RangeError):
        ad.decode_data_words(np.array([1.5]))


def test_bus_bench_cases_run() -> None:
    # Smoke test only (no timing): every bus benchmark case processes what it is asked to.
    from hil.bench.codecs import buses

    names = {c.name for c in buses.CASES}
    assert {"AD7195 data read", "AD7195 batch decode"} <= names
    for case in buses.CASES:
        assert case.kind in ("frame", "batch")
        assert case.run(3) == 3


def test_numpy_scalar_codes_do_not_wrap() -> None:
    # An unsigned numpy scalar minus 2**23 would wrap around; the codec must not.
    assert ad.code_to_force(np.uint32(0)) == -3000.0
    assert ad.code_to_voltage(np.uint32(0), 5.0) == -5.0
    assert ad.DataWord(np.uint32(1), 0).encode() == 0x100
