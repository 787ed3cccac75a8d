"""Tests of protocols.pcap: classic libpcap file bytes and the file helpers.

Known answers: the byte layout of pcap-savefile(5) (tcpdump.org) and
draft-ietf-opsawg-pcap: magic 0xA1B2C3D4 written in the writer's byte order (little endian
here: d4 c3 b2 a1), version 2.4, thiszone 0, sigfigs 0, snaplen, LINKTYPE_ETHERNET = 1;
record header ts_sec, ts_usec, incl_len, orig_len. The expected bytes below are written
out by hand from that specification; the big-endian file is hand-built too.
"""

from __future__ import annotations

import io

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import pcap
from protocols.errors import FrameError, RangeError
from protocols.pcap import PcapRecord

GLOBAL_LE = bytes.fromhex("d4c3b2a1020004000000000000000000ffff000001000000")


def test_global_and_record_header_bytes() -> None:
    data = bytes(range(60))
    out = pcap.build_pcap([PcapRecord(1_500_000_000, data)])
    assert out[:24] == GLOBAL_LE
    # ts 1 s + 500000 us, incl_len = orig_len = 60
    assert out[24:40] == bytes.fromhex("0100000020a107003c0000003c000000")
    assert out[40:] == data


def test_nanosecond_magic() -> None:
    out = pcap.build_pcap([PcapRecord(7, b"x")], nanosecond=True)
    assert out[:4] == bytes.fromhex("4d3cb2a1")
    f = pcap.parse_pcap(out)
    assert f.nanosecond and f.records[0].ts_ns == 7


def test_reads_big_endian_file() -> None:
    be = (
        bytes.fromhex("a1b2c3d40002000400000000000000000000010000000001")
        + bytes.fromhex("00000002000000030000000200000005")
        + b"ab"
    )
    f = pcap.parse_pcap(be)
    assert (f.linktype, f.snaplen, f.nanosecond) == (1, 256, False)
    assert f.records == [PcapRecord(2_000_003_000, b"ab", orig_len=5)]


record_st = st.builds(
    PcapRecord,
    ts_ns=st.integers(0, 2**32 - 1).map(lambda us: us * 1000),
    data=st.binary(max_size=100),
    orig_len=st.none(),
)


@settings(max_examples=100)
@given(st.lists(record_st, max_size=8), st.integers(0, 300))
def test_round_trip_usec(records: list[PcapRecord], linktype: int) -> None:
    f = pcap.parse_pcap(pcap.build_pcap(records, linktype=linktype))
    assert f.records == records and f.linktype == linktype and not f.nanosecond


@settings(max_examples=100)
@given(
    st.lists(
        st.builds(
            PcapRecord,
            st.integers(0, 2**32 * 10**9 - 1),
            st.binary(max_size=40),
            st.none() | st.integers(40, 2**32 - 1),
        ),
        max_size=6,
    )
)
def test_round_trip_nsec(records: list[PcapRecord]) -> None:
    assert pcap.parse_pcap(pcap.build_pcap(records, nanosecond=True)).records == records


def test_usec_floors_timestamps() -> None:
    f = pcap.parse_pcap(pcap.build_pcap([PcapRecord(1_999, b"")]))
    assert f.records[0].ts_ns == 1_000


@settings(max_examples=300)
@given(st.binary(max_size=80))
def test_arbitrary_bytes_only_frame_error(buf: bytes) -> None:
    try:
        f = pcap.parse_pcap(GLOBAL_LE + buf if buf[:1] == b"\x00" else buf)
    except FrameError:
        return
    assert all(r.orig_len is None or r.orig_len >= len(r.data) for r in f.records)


@given(st.lists(record_st, min_size=1, max_size=4), st.data())
def test_truncation_is_frame_error_or_a_prefix(
    records: list[PcapRecord], data: st.DataObject
) -> None:
    raw = pcap.build_pcap(records)
    truncated = raw[: data.draw(st.integers(0, len(raw) - 1))]
    try:
        f = pcap.parse_pcap(truncated)
    except FrameError:
        return
    # Only a cut exactly at a record boundary parses: a shorter valid file, never a
    # corrupt record.
    assert f.records == records[: len(f.records)]
    assert len(f.records) < len(records)


def test_encode_range_errors() -> None:
    with pytest.raises(RangeError):
        pcap.build_pcap([PcapRecord(-1, b"")])
    with pytest.raises(RangeError):
        pcap.build_pcap([PcapRecord(0, bytes(10))], snaplen=5)
    with pytest.raises(RangeError):
        pcap.build_pcap([PcapRecord(0, bytes(10), orig_len=3)])


def test_file_helpers(tmp_path) -> None:
    records = [PcapRecord(1_000, b"\x01\x02"), PcapRecord(2_000, b"\x03")]
    path = tmp_path / "x.pcap"
    n = pcap.write_pcap(path, records)
    assert path.stat().st_size == n
    assert pcap.read_pcap(str(path)).records == records
    buf = io.BytesIO()
    pcap.write_pcap(buf, records)
    buf.seek(0)
    assert pcap.read_pcap(buf).records == records
