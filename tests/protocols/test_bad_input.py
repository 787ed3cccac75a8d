"""Wrong arguments to the codecs: a one-line CodecError naming what is wrong, never a
TypeError/ValueError/KeyError from inside, a silent answer, a runaway loop or a huge
allocation.

The table below lists every public encode/decode entry point of :mod:`protocols` with
arguments that work; the parametrised test puts each wrong value in turn into each of
those arguments.
"""

from __future__ import annotations

import io
import signal
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import (
    abi,
    ad7195,
    biss,
    bits,
    crc,
    ethercat,
    hall,
    lvds,
    pcap,
    pressure_adc,
    spi,
    ssi,
)
from protocols.errors import CodecError

BAD: list[object] = [None, "abc", {"a": 1}, -1, float("nan"), 10**30]
#: Values that are never a valid integer, float, bytes, sequence or array argument.
NEVER_VALID = (None, "abc", {"a": 1})


@contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Fail (instead of hanging the suite) if the block runs longer than ``seconds``."""

    def expire(signum: int, frame: object) -> None:
        raise AssertionError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def assert_codec_error(fn: Callable[..., Any], *args: object, names: str = "") -> str:
    """``fn(*args)`` raises a CodecError with a one-line message (containing ``names``,
    case-insensitive, if given); returns the message."""
    with deadline(5.0), pytest.raises(CodecError) as exc:
        fn(*args)
    msg = str(exc.value)
    assert msg and "\n" not in msg
    assert names.lower() in msg.lower(), msg
    return msg


# --- the cases found by hand ------------------------------------------------------------------
@pytest.mark.parametrize("nbits", [-1, -8, 10**12, None, 2.0])
def test_crc_rejects_absurd_lengths_at_once(nbits: object) -> None:
    # A negative length used to loop for ever building the chunk plan.
    assert_codec_error(crc.CRC8_AUTOSAR.compute, 5, nbits, names="nbits")
    assert_codec_error(crc.crc_bitwise, 5, nbits, 8, 0x2F, names="nbits")


def test_crc_rejects_a_message_wider_than_its_length() -> None:
    assert_codec_error(crc.CRC8_AUTOSAR.compute, 0x1FF, 8, names="does not fit")
    assert_codec_error(crc.CRC8_AUTOSAR.compute, -1, 8, names="message")
    assert crc.CRC8_AUTOSAR.compute(0xFF, 8) == crc.CRC8_AUTOSAR.compute_bytes(b"\xff")


@pytest.mark.parametrize("buf", [-1, 10**8, "abc", None])
def test_decode_pdu_checks_the_type_before_allocating(buf: object) -> None:
    # bytes(10**8) is 100 MB of zeros: the check must come first.
    tracemalloc.start()
    try:
        assert_codec_error(ethercat.decode_pdu, buf, names="EtherCAT PDU")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000


@pytest.mark.parametrize(("fn", "arg", "names"), [
    (pcap.parse_pcap, "abc", "pcap data: a str is not bytes"),
    (pressure_adc.decode_scan, 5, "pressure scan codes: 5 is not a sequence"),
    (biss.BissCodec().decode_line, {"a": 1}, "BiSS SLO samples"),
    (hall.decode_array, None, "hall codes: None is not an array of integers"),
    (ethercat.decode_frame, 60, "Ethernet frame: 60 is not bytes-like"),
    (ad7195.AD7195Master().parse_data_read, None, "data read response"),
])
def test_named_entry_points_say_what_is_wrong(fn: Callable[..., Any], arg: object,
                                              names: str) -> None:
    assert_codec_error(fn, arg, names=names)


def test_bool_flags_are_not_truth_values() -> None:
    codec = biss.BissCodec()
    assert codec.decode(codec.encode(7, error=1)).error
    assert_codec_error(codec.encode, 7, "no", names="error flag")
    assert_codec_error(ad7195.comms_byte, 3, "yes", names="read")


def test_huge_angles_give_the_sector_not_a_wrapped_integer() -> None:
    theta = np.array([1e30, -1e30, 2.5])
    want = [hall.sector_from_angle(float(t)) for t in theta]
    assert hall.sectors_from_angle_array(theta).tolist() == want


# --- every public entry point, every argument, every wrong value --------------------------
DG = ethercat.Datagram(ethercat.Command.LRW, 1, 0, 0, b"\x01\x02", 0)
FRAME = ethercat.encode_frame([DG])
UFRAME = ethercat.encode_udp_frame([DG])
PACKET = ethercat.decode_ethernet(UFRAME).payload
PCAP = pcap.build_pcap([pcap.PcapRecord(0, b"ab")])
BISS = biss.BissCodec()
SSI = ssi.SsiCodec()
LW = lvds.encode_word(1, 2)
LAYOUT = lvds.LAYOUT


def device() -> ad7195.AD7195Device:
    return ad7195.AD7195Device()


# (name, callable, arguments that work). Optional arguments left out keep their defaults.
ENTRIES: list[tuple[str, Callable[..., Any], tuple[Any, ...]]] = [
    ("abi.ab_from_count", abi.ab_from_count, (5,)),
    ("abi.abi_from_count", abi.abi_from_count, (5, 2048)),
    ("abi.count_from_angle", abi.count_from_angle, (1.0, 2048)),
    ("abi.abi_from_angle", abi.abi_from_angle, (1.0, 2048)),
    ("abi.QuadratureCounter", abi.QuadratureCounter, (0, 1, 0)),
    ("abi.QuadratureCounter.update", lambda *a: abi.QuadratureCounter().update(*a), (0, 1, 0)),
    ("abi.count_array", abi.count_array, (np.array([0, 1]), np.array([1, 1]), 0, 0, 0)),
    ("ad7195.comms_byte", ad7195.comms_byte, (3, True)),
    ("ad7195.voltage_to_code", ad7195.voltage_to_code, (0.1, 2.5, 1)),
    ("ad7195.code_to_voltage", ad7195.code_to_voltage, (100, 2.5, 1)),
    ("ad7195.code_to_force", ad7195.code_to_force, (100, 3000.0)),
    ("ad7195.force_to_code", ad7195.force_to_code, (10.0, 3000.0)),
    ("ad7195.clamp_force_to_code", ad7195.clamp_force_to_code, (10.0, 3000.0)),
    ("ad7195.parity_of", ad7195.parity_of, (5,)),
    ("ad7195.DataWord.encode", lambda c, s: ad7195.DataWord(c, s).encode(), (100, 0)),
    ("ad7195.DataWord.decode", ad7195.DataWord.decode, (0x1234,)),
    ("ad7195.check_status", ad7195.check_status, (0,)),
    ("ad7195.decode_data_words", ad7195.decode_data_words,
     (np.array([0x1234], np.uint32), 3000.0)),
    ("ad7195.Mode.decode", ad7195.Mode.decode, (0x080060,)),
    ("ad7195.Mode.encode", lambda v: ad7195.Mode(fs=v).encode(), (96,)),
    ("ad7195.AD7195Device.clock", lambda b: device().clock(b), (1,)),
    ("ad7195.AD7195Device.transfer", lambda d: device().transfer(d), (b"\x00",)),
    ("ad7195.AD7195Device.set_code", lambda c: device().set_code(c), (100,)),
    ("ad7195.AD7195Device.set_input", lambda v: device().set_input(v), (0.1,)),
    ("ad7195.AD7195Device.set_force", lambda f: device().set_force(f), (1.0,)),
    ("ad7195.AD7195Device.read_register_value", lambda a: device().read_register_value(a),
     (0,)),
    ("ad7195.AD7195Master.parse_data_read",
     lambda r: ad7195.AD7195Master().parse_data_read(r), (bytes([0, 0x80, 0, 0, 0]),)),
    ("ad7195.AD7195Master.read_register",
     lambda a: ad7195.AD7195Master().read_register(device().transfer, a), (0,)),
    ("ad7195.AD7195Master.write_register",
     lambda a, v: ad7195.AD7195Master().write_register(device().transfer, a, v), (1, 0)),
    ("biss.BissCodec", biss.BissCodec, (26,)),
    ("biss.BissCodec.encode", BISS.encode, (100, False, False)),
    ("biss.BissCodec.decode", BISS.decode, (BISS.encode(100),)),
    ("biss.BissCodec.encode_line", BISS.encode_line, (100, False, False, 1, 1, 1)),
    ("biss.BissCodec.decode_line", BISS.decode_line, (BISS.encode_line(100),)),
    ("biss.BissCodec.encode_array", BISS.encode_array, (np.array([100]), False, False)),
    ("biss.BissCodec.decode_array", BISS.decode_array, (np.array([BISS.encode(100)], np.uint64),)),
    ("biss.linear_position_m", biss.linear_position_m, (5,)),
    ("biss.counts_from_linear_m", biss.counts_from_linear_m, (1e-3, 26)),
    ("bits.as_word", bits.as_word, (5, 8)),
    ("bits.to_bits", bits.to_bits, (5, 8)),
    ("bits.from_bits", bits.from_bits, ([1, 0],)),
    ("bits.bits_from_words", bits.bits_from_words, (np.array([5]), 8)),
    ("bits.gray_encode", bits.gray_encode, (5,)),
    ("bits.gray_decode", bits.gray_decode, (5, 8)),
    ("bits.Layout.pack", LAYOUT.pack, (1, 2, 3)),
    ("bits.Layout.unpack", LAYOUT.unpack, (LW,)),
    ("bits.Layout.pack_array", LAYOUT.pack_array, (np.array([1]), np.array([2]), np.array([3]))),
    ("bits.Layout.unpack_array", LAYOUT.unpack_array, (np.array([LW], np.uint64),)),
    ("crc.crc_bitwise", crc.crc_bitwise, (5, 8, 8, 7, 0, 0)),
    ("crc.Crc", crc.Crc, (8, 7, 0, 0)),
    ("crc.Crc.compute", crc.CRC8_AUTOSAR.compute, (5, 8)),
    ("crc.Crc.compute_bytes", crc.CRC8_AUTOSAR.compute_bytes, (b"12",)),
    ("crc.Crc.compute_array", crc.CRC8_AUTOSAR.compute_array, (np.array([5], np.uint64), 8)),
    ("crc.hamming_distance", crc.hamming_distance, (8, 7, 16, 3)),
    ("ethercat.Datagram.logical", ethercat.Datagram.logical, (ethercat.Command.LRD, 0, b"ab")),
    ("ethercat.encode_datagrams", ethercat.encode_datagrams, ([DG],)),
    ("ethercat.encode_pdu", ethercat.encode_pdu, ([DG],)),
    ("ethercat.encode_pdu(Datagram fields)",
     lambda *f: ethercat.encode_pdu([ethercat.Datagram(*f)]), (1, 0, 0, 0, b"ab", 0, 0)),
    ("ethercat.decode_pdu", ethercat.decode_pdu, (ethercat.encode_pdu([DG]),)),
    ("ethercat.mac", ethercat.mac, ("aa:bb:cc:dd:ee:ff",)),
    ("ethercat.encode_ethernet", ethercat.encode_ethernet,
     (b"ab", "aa:bb:cc:dd:ee:ff", b"\x00" * 6, 0x88A4)),
    ("ethercat.decode_ethernet", ethercat.decode_ethernet, (FRAME,)),
    ("ethercat.encode_frame", ethercat.encode_frame, ([DG], b"\xff" * 6, b"\x02" * 6)),
    ("ethercat.decode_frame", ethercat.decode_frame, (FRAME,)),
    ("ethercat.ones_complement_sum", ethercat.ones_complement_sum, (b"ab",)),
    ("ethercat.internet_checksum", ethercat.internet_checksum, (b"ab",)),
    ("ethercat.ip4", ethercat.ip4, ("1.2.3.4",)),
    ("ethercat.encode_ipv4_udp", ethercat.encode_ipv4_udp,
     (b"ab", "1.2.3.4", "1.2.3.5", 1, 2, 64, 0)),
    ("ethercat.decode_ipv4_udp", ethercat.decode_ipv4_udp, (PACKET,)),
    ("ethercat.encode_udp_frame", ethercat.encode_udp_frame, ([DG], "1.2.3.4", "1.2.3.5")),
    ("ethercat.decode_udp_frame", ethercat.decode_udp_frame, (UFRAME,)),
    ("ethercat.decode_any", ethercat.decode_any, (FRAME,)),
    ("ethercat.expected_wkc", ethercat.expected_wkc, (1, 2)),
    ("ethercat.iter_datagrams", lambda f: list(ethercat.iter_datagrams(f)), ([FRAME],)),
    ("hall.sector_from_angle", hall.sector_from_angle, (1.0, 0.0)),
    ("hall.sector_center_rad", hall.sector_center_rad, (2,)),
    ("hall.encode", hall.encode, (2,)),
    ("hall.decode", hall.decode, (5,)),
    ("hall.code_from_angle", hall.code_from_angle, (1.0, 0.0)),
    ("hall.sector_step", hall.sector_step, (5, 4)),
    ("hall.sectors_from_angle_array", hall.sectors_from_angle_array, (np.array([1.0]), 0.0)),
    ("hall.encode_array", hall.encode_array, (np.array([1]),)),
    ("hall.decode_array", hall.decode_array, (np.array([5]),)),
    ("lvds.encode_word", lvds.encode_word, (1, 2)),
    ("lvds.decode_word", lvds.decode_word, (LW,)),
    ("lvds.word_bits", lvds.word_bits, (1, 2)),
    ("lvds.encode_stream", lvds.encode_stream, ([(1, 2)],)),
    ("lvds.encode_words_array", lvds.encode_words_array, (np.array([1]), np.array([2]))),
    ("lvds.decode_words_array", lvds.decode_words_array, (np.array([LW], np.uint64),)),
    ("lvds.LvdsStreamDecoder.feed", lambda b: lvds.LvdsStreamDecoder().feed(b), ("0" * 10,)),
    ("pcap.build_pcap", pcap.build_pcap, ([pcap.PcapRecord(0, b"ab")], 1, 65535)),
    ("pcap.build_pcap(PcapRecord fields)",
     lambda t, d: pcap.build_pcap([pcap.PcapRecord(t, d)]), (0, b"ab")),
    ("pcap.parse_pcap", pcap.parse_pcap, (PCAP,)),
    ("pcap.read_pcap", pcap.read_pcap, (io.BytesIO(PCAP),)),
    ("pressure_adc.pressure_to_voltage", pressure_adc.pressure_to_voltage, (1e6,)),
    ("pressure_adc.voltage_to_pressure", pressure_adc.voltage_to_pressure, (2.0,)),
    ("pressure_adc.voltage_to_code", pressure_adc.voltage_to_code, (2.0,)),
    ("pressure_adc.code_to_voltage", pressure_adc.code_to_voltage, (100,)),
    ("pressure_adc.pressure_to_code", pressure_adc.pressure_to_code, (1e6,)),
    ("pressure_adc.flags_of", pressure_adc.flags_of, (100,)),
    ("pressure_adc.code_to_pressure", pressure_adc.code_to_pressure, (100,)),
    ("pressure_adc.encode_scan", pressure_adc.encode_scan, ([1e6] * 8,)),
    ("pressure_adc.decode_scan", pressure_adc.decode_scan, ([100] * 8,)),
    ("pressure_adc.pack_scan", pressure_adc.pack_scan, ([100] * 8,)),
    ("pressure_adc.unpack_scan", pressure_adc.unpack_scan, (bytes(16),)),
    ("pressure_adc.decode_codes", pressure_adc.decode_codes, (np.array([100]),)),
    ("spi.bytes_to_bits", spi.bytes_to_bits, (b"ab",)),
    ("spi.bits_to_bytes", spi.bits_to_bytes, ([0] * 8,)),
    ("spi.encode_waveform", spi.encode_waveform, ([1, 0], [0, 1])),
    ("spi.decode_waveform", spi.decode_waveform, (spi.encode_waveform([1, 0], [0, 1]),)),
    ("spi.exchange_bits", lambda b: spi.exchange_bits(device(), b), ([1, 0],)),
    ("spi.exchange_bytes", lambda d: spi.exchange_bytes(device(), d), (b"\x00",)),
    ("spi.transfer_waveform", lambda b: spi.transfer_waveform(device(), b), ([1, 0],)),
    ("ssi.SsiFormat", ssi.SsiFormat, (11, 0, 0, False, "none")),
    ("ssi.SsiCodec.encode", SSI.encode, (5, 0)),
    ("ssi.SsiCodec.decode", SSI.decode, (SSI.encode(5),)),
    ("ssi.SsiCodec.encode_array", SSI.encode_array, (np.array([5]),)),
    ("ssi.SsiCodec.decode_array", SSI.decode_array, (np.array([5], np.uint64),)),
    ("ssi.SsiTiming", ssi.SsiTiming, (1_000_000, 20_000)),
    ("ssi.SsiSlave", ssi.SsiSlave, (11, 20_000)),
    ("ssi.SsiSlave.present", lambda w: ssi.SsiSlave(11).present(w), (5,)),
    ("ssi.SsiSlave.step", lambda t, c: ssi.SsiSlave(11).step(t, c), (10, 0)),
    ("ssi.SsiSlave.data_at", lambda t: ssi.SsiSlave(11).data_at(t), (10,)),
    ("ssi.SsiMaster.read", lambda n, t: ssi.SsiMaster(n).read(ssi.SsiSlave(11), t), (11, 0)),
]


#: Other exceptions that are right for one entry point: a str is a path to read_pcap.
ALSO_ALLOWED: dict[str, tuple[type[Exception], ...]] = {"pcap.read_pcap": (FileNotFoundError,)}


@pytest.mark.parametrize(("name", "fn", "good"), ENTRIES, ids=[e[0] for e in ENTRIES])
def test_every_entry_point_raises_only_codec_errors(name: str, fn: Callable[..., Any],
                                                    good: tuple[Any, ...]) -> None:
    with deadline(10.0):
        fn(*good)  # the table's arguments work, so each failure below is the bad value's
    for i in range(len(good)):
        for bad in BAD:
            args = list(good)
            args[i] = bad
            where = f"{name} argument {i} = {bad!r}"
            try:
                with deadline(2.0):
                    fn(*args)
            except CodecError as exc:
                assert str(exc) and "\n" not in str(exc), where
                continue
            except AssertionError:
                raise
            except ALSO_ALLOWED.get(name, ()):
                continue
            except Exception as exc:  # noqa: BLE001 - the point: nothing else may escape
                pytest.fail(f"{where}: {type(exc).__name__}: {exc}")
            # Negative and huge ints can be valid (a quadrature count); these never are.
            assert not any(bad is v for v in NEVER_VALID) and bad == bad, f"{where}: accepted"


BYTES_DECODERS = [ethercat.decode_pdu, ethercat.decode_ethernet, ethercat.decode_frame,
                  ethercat.decode_udp_frame, ethercat.decode_any, ethercat.decode_ipv4_udp,
                  pcap.parse_pcap, pressure_adc.unpack_scan, spi.bytes_to_bits,
                  crc.CRC8_AUTOSAR.compute_bytes, ad7195.AD7195Master().parse_data_read]
ANYTHING = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(),
                     st.text(max_size=20), st.binary(max_size=80),
                     st.lists(st.integers(-300, 300), max_size=20),
                     st.dictionaries(st.text(max_size=3), st.integers(), max_size=3))


@settings(max_examples=150, deadline=None)
@given(ANYTHING)
def test_byte_decoders_take_anything(x: object) -> None:
    """Arbitrary objects and arbitrary bytes: a result or a CodecError, nothing else."""
    for fn in BYTES_DECODERS:
        try:
            fn(x)
        except CodecError as exc:
            assert "\n" not in str(exc)
