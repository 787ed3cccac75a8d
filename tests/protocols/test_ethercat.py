"""Tests of protocols.ethercat: datagrams, EtherCAT PDU, Ethernet II and UDP/IPv4 carriers.

Known answers:
* IPv4 header checksum: the worked example on Wikipedia's "Internet checksum" / "IPv4
  header checksum" pages — header 4500 0073 0000 4000 4011 ____ c0a8 0001 c0a8 00c7 has
  checksum 0xB861 (RFC 1071 algorithm).
* EtherCAT header word: a public capture on the etherlab-dev mailing list (2021-04-07,
  "Ethercat mailbox gateway and TwinSAFE loader issues") starts its EtherCAT data with
  ``10 50``: length 16, type 5 (mailbox gateway). Type 5 is not a command frame, so the
  decoder must reject it.
* No public hex dump of a command datagram was found; the BRD frame below is assembled by
  hand from the ETG.1000.4 field table (little endian; cmd, idx, ADP, ADO, length word,
  IRQ, data, WKC) and is cross-checked by Wireshark's dissector in test_tshark.py.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import ethercat as ec
from protocols.errors import CodecError, CrcError, FrameError, RangeError
from protocols.ethercat import Command, Datagram

datagrams_st = st.builds(
    Datagram,
    cmd=st.sampled_from(list(Command)),
    idx=st.integers(0, 255),
    adp=st.integers(0, 0xFFFF),
    ado=st.integers(0, 0xFFFF),
    data=st.binary(max_size=48),
    wkc=st.integers(0, 0xFFFF),
    irq=st.integers(0, 0xFFFF),
    circulating=st.booleans(),
)
frames_st = st.lists(datagrams_st, min_size=1, max_size=5)


# ---- known answers ------------------------------------------------------------------


def test_wikipedia_ipv4_checksum_example() -> None:
    header = bytes.fromhex("450000730000400040110000c0a80001c0a800c7")
    assert ec.internet_checksum(header) == 0xB861
    good = header[:10] + b"\xb8\x61" + header[12:]
    assert ec.ones_complement_sum(good) == 0xFFFF


def test_public_mailbox_gateway_header_is_rejected() -> None:
    word = ec.ECAT_HEADER_WORD.unpack(struct.unpack("<H", bytes.fromhex("1050"))[0])
    assert word == {"length": 16, "reserved": 0, "type": 5}
    payload = bytes.fromhex("10500a00e903002300204180f9020000000000")
    with pytest.raises(FrameError):
        ec.decode_pdu(payload)


def test_hand_assembled_brd_frame() -> None:
    d = Datagram(Command.BRD, idx=0x12, adp=0x0000, ado=0x0130, data=b"\x00\x00", wkc=3)
    expected_pdu = bytes.fromhex(
        "0e10"  # header: length 14 = 10 + 2 + 2, type 1 -> 0x100e little endian
        "07"  # BRD
        "12"  # index
        "0000"  # ADP
        "3001"  # ADO 0x0130 (AL status)
        "0200"  # length 2, C = 0, M = 0
        "0000"  # IRQ
        "0000"  # data
        "0300"  # WKC 3
    )
    assert ec.encode_pdu([d]) == expected_pdu
    frame = ec.encode_frame([d], dst=b"\xff" * 6, src=bytes.fromhex("020000000001"))
    assert len(frame) == 60  # padded to the Ethernet minimum (no FCS)
    assert frame[:14] == bytes.fromhex("ffffffffffff02000000000188a4")
    assert frame[14 : 14 + len(expected_pdu)] == expected_pdu
    assert frame[14 + len(expected_pdu) :] == bytes(60 - 14 - len(expected_pdu))


def test_more_bit_and_logical_address_layout() -> None:
    a = Datagram(Command.APRD, idx=1, adp=0xFFFF, ado=0x0010, data=b"\x00\x00")
    b = Datagram.logical(Command.LRW, 0x00010000, bytes(4), idx=2)
    pdu = ec.encode_pdu([a, b])
    # First datagram's length word: 2 | M (bit 15) -> 0x8002.
    assert pdu[2 + 6 : 2 + 8] == b"\x02\x80"
    # Logical address 0x00010000 little endian in the 4-byte address field.
    second = 2 + a.size
    assert pdu[second + 2 : second + 6] == bytes.fromhex("00000100")
    assert ec.decode_pdu(pdu)[1].lad == 0x00010000


def test_udp_frame_layout() -> None:
    d = Datagram(Command.FPRD, idx=7, adp=0x1001, ado=0x0130, data=b"\x00\x00", wkc=1)
    frame = ec.encode_udp_frame([d], src_ip="10.0.0.1", dst_ip="10.0.0.2")
    assert frame[12:14] == b"\x08\x00"
    ip = frame[14:34]
    assert ip[0] == 0x45 and ip[9] == 17
    assert ec.ones_complement_sum(ip) == 0xFFFF  # header checksum valid
    assert frame[36:38] == struct.pack(">H", 34980)  # UDP destination port
    assert frame[42 : 42 + len(ec.encode_pdu([d]))] == ec.encode_pdu([d])


def test_expected_wkc() -> None:
    assert ec.expected_wkc(Command.LRW, 2) == 6
    assert ec.expected_wkc(Command.BRD, 5) == 5
    with pytest.raises(RangeError):
        ec.expected_wkc(Command.ARMW, 1)


# ---- round trips --------------------------------------------------------------------


@pytest.mark.slow
@settings(max_examples=150)
@given(frames_st)
def test_ethernet_round_trip(dgs: list[Datagram]) -> None:
    frame = ec.encode_frame(dgs)
    assert len(frame) >= 60
    assert ec.decode_frame(frame) == dgs
    assert ec.decode_any(frame) == dgs


@settings(max_examples=100)
@given(frames_st, st.integers(0, 0xFFFF))
def test_udp_round_trip(dgs: list[Datagram], ident: int) -> None:
    frame = ec.encode_udp_frame(dgs, ident=ident)
    assert ec.decode_udp_frame(frame) == dgs
    assert ec.decode_any(frame) == dgs


@given(st.binary(max_size=64), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
def test_ipv4_udp_round_trip(payload: bytes, sport: int, dport: int) -> None:
    pkt = ec.encode_ipv4_udp(payload, "192.0.2.1", "198.51.100.7", sport, dport, ttl=3)
    u = ec.decode_ipv4_udp(pkt, allow_trailing=False)
    assert (u.payload, u.src_port, u.dst_port, u.ttl) == (payload, sport, dport, 3)
    assert (u.src_ip, u.dst_ip) == (bytes([192, 0, 2, 1]), bytes([198, 51, 100, 7]))


# ---- corrupted and arbitrary input --------------------------------------------------


@settings(max_examples=300)
@given(st.binary(max_size=80))
def test_arbitrary_bytes_only_codec_errors(buf: bytes) -> None:
    for fn in (
        ec.decode_pdu,
        ec.decode_frame,
        ec.decode_udp_frame,
        ec.decode_any,
        ec.decode_ipv4_udp,
        ec.decode_ethernet,
    ):
        try:
            fn(buf)
        except CodecError:
            pass


@pytest.mark.slow
@settings(max_examples=200)
@given(frames_st, st.integers(0, 0x7FF))
def test_length_field_inconsistent_is_frame_error(dgs: list[Datagram], new_len: int) -> None:
    pdu = bytearray(ec.encode_pdu(dgs))
    true_len = len(pdu) - 2
    if new_len == true_len:
        return
    struct.pack_into("<H", pdu, 0, new_len | 0x1000)
    with pytest.raises(FrameError):
        ec.decode_pdu(bytes(pdu))


@pytest.mark.slow
@settings(max_examples=200)
@given(st.lists(datagrams_st, min_size=2, max_size=5), st.data())
def test_broken_m_chain_is_frame_error(dgs: list[Datagram], data: st.DataObject) -> None:
    pdu = bytearray(ec.encode_pdu(dgs))
    i = data.draw(st.integers(0, len(dgs) - 1))
    pos = 2 + sum(d.size for d in dgs[:i]) + 6  # length word of datagram i
    pdu[pos + 1] ^= 0x80  # flip its M bit
    with pytest.raises(FrameError):
        ec.decode_pdu(bytes(pdu))


@settings(max_examples=100)
@given(frames_st, st.data())
def test_truncated_frame_is_frame_error(dgs: list[Datagram], data: st.DataObject) -> None:
    pdu = ec.encode_pdu(dgs)
    cut = data.draw(st.integers(0, len(pdu) - 1))
    with pytest.raises(FrameError):
        ec.decode_pdu(pdu[:cut])


@pytest.mark.slow
@settings(max_examples=200)
@given(frames_st, st.data())
def test_udp_single_bit_flip_never_yields_a_wrong_value(
    dgs: list[Datagram], data: st.DataObject
) -> None:
    frame = bytearray(ec.encode_udp_frame(dgs))
    bit = data.draw(st.integers(14 * 8, len(frame) * 8 - 1))
    frame[bit // 8] ^= 0x80 >> (bit % 8)
    try:
        got = ec.decode_udp_frame(bytes(frame))
    except CodecError:
        return
    assert got == dgs  # only flips of padding or of a checksum to 0 ("none") may pass


@given(st.integers(14 * 8, 34 * 8 - 1), frames_st)
def test_ipv4_header_bit_flip_is_detected(bit: int, dgs: list[Datagram]) -> None:
    frame = bytearray(ec.encode_udp_frame(dgs))
    frame[bit // 8] ^= 0x80 >> (bit % 8)
    with pytest.raises((CrcError, FrameError)):
        ec.decode_udp_frame(bytes(frame))


def test_encode_rejects_out_of_range() -> None:
    with pytest.raises(RangeError):
        ec.encode_pdu([])
    with pytest.raises(RangeError):
        ec.encode_pdu([Datagram(0x0F)])
    with pytest.raises(RangeError):
        ec.encode_pdu([Datagram(Command.BRD, idx=256)])
    with pytest.raises(RangeError):
        ec.encode_frame([Datagram(Command.LWR, data=bytes(1490))])
    with pytest.raises(RangeError):
        ec.encode_frame([Datagram(Command.BRD)], dst="zz:00")
