"""COBS + CRC-32 framing of the serial transport (pure: no port).

Known answers: the COBS examples of Wikipedia's "Consistent Overhead Byte Stuffing"
article (examples 1-11, delimiter not included), and the CRC-32 check value 0xCBF43926
(PROTOCOL_FACTS.md, CRC catalogue).
"""

from __future__ import annotations

import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.transports import TransportStats
from hil.transports.framing import (
    CobsError,
    FrameDecoder,
    cobs_decode,
    cobs_encode,
    cobs_max_encoded,
    crc32,
    encode_frame,
)

_RUN = bytes(range(1, 255))  # 01..FE, 254 non-zero bytes

COBS_VECTORS = [
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (_RUN, b"\xff" + _RUN),
    (b"\x00" + _RUN, b"\x01\xff" + _RUN),
    (_RUN + b"\xff", b"\xff" + _RUN + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01"),
    (b"", b"\x01"),
]


@pytest.mark.parametrize("raw, encoded", COBS_VECTORS)
def test_cobs_known_answers(raw: bytes, encoded: bytes) -> None:
    assert cobs_encode(raw) == encoded
    assert cobs_decode(encoded) == raw


def test_crc_is_crc32_ethernet() -> None:
    assert crc32(b"123456789") == 0xCBF43926


@pytest.mark.parametrize("bad", [b"\x05\x11\x22", b"\x02\x00", b"\x03\x11\x00\x22"])
def test_cobs_rejects_invalid(bad: bytes) -> None:
    with pytest.raises(CobsError):
        cobs_decode(bad)


@given(st.binary(max_size=3000))
@settings(max_examples=200)
def test_cobs_round_trip(data: bytes) -> None:
    encoded = cobs_encode(data)
    assert b"\x00" not in encoded
    assert len(encoded) <= cobs_max_encoded(len(data))
    assert cobs_decode(encoded) == data


def test_wire_layout() -> None:
    frame = b"\x11\x00\x22"
    crc = zlib.crc32(frame).to_bytes(4, "little")  # an independent CRC-32
    assert encode_frame(frame) == b"\x00" + cobs_encode(frame + crc) + b"\x00"
    # CRC-32(11 00 22) = 0x37C551B1, little endian b1 51 c5 37; the zero splits two groups
    assert encode_frame(frame) == bytes.fromhex("00 02 11 06 22 b1 51 c5 37 00")


@given(st.lists(st.binary(min_size=1, max_size=2100), min_size=1, max_size=4),
       st.data())
@settings(max_examples=100)
def test_round_trip_any_bytes_any_cuts(frames: list[bytes], data: st.DataObject) -> None:
    stream = b"".join(encode_frame(f) for f in frames)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=12)))
    decoder = FrameDecoder(max_frame=2100)
    out: list[bytes] = []
    for start, stop in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        out += decoder.feed(stream[start:stop])
    assert out == frames
    assert decoder.stats == TransportStats()
    assert decoder.buffered == 0


def is_subsequence(short: list[bytes], long: list[bytes]) -> bool:
    it = iter(long)
    return all(any(x == y for y in it) for x in short)


garbage_st = st.one_of(
    st.binary(min_size=1, max_size=80),
    st.binary(min_size=100, max_size=400),  # longer than max_frame: the oversize path
    st.sampled_from([b"\x00", b"\x00\x00\x00", b"\x01" * 9, b"\xff" * 300, b"\x01\x00"]),
)


@pytest.mark.slow
@given(
    frames=st.lists(st.binary(min_size=1, max_size=64), min_size=1, max_size=12),
    insertions=st.lists(st.tuples(st.integers(0, 10**6), garbage_st), max_size=6),
    chunk=st.integers(1, 97),
)
@settings(max_examples=300)
def test_garbage_never_yields_a_bad_frame_and_stream_recovers(
        frames: list[bytes], insertions: list[tuple[int, bytes]], chunk: int) -> None:
    """Garbage at any position (between frames or inside one): every frame returned is a
    frame that was sent, in order; every frame not touched by garbage is returned; and a
    frame that is lost is counted as an error."""
    wires = [encode_frame(f) for f in frames]
    stream = b"".join(wires)
    # Where each frame's bytes lie; garbage strictly inside (after its leading delimiter
    # and before its trailing one) may destroy it, garbage at a boundary must not.
    spans = []
    pos = 0
    for w in wires:
        spans.append((pos, pos + len(w)))
        pos += len(w)
    touched = set()
    # Insert from the back so earlier positions stay valid.
    points = sorted(((at % (len(stream) + 1), junk) for at, junk in insertions), reverse=True)
    for at, junk in points:
        for k, (lo, hi) in enumerate(spans):
            if lo < at < hi:
                touched.add(k)
        stream = stream[:at] + junk + stream[at:]
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=64, stats=stats)
    out: list[bytes] = []
    for start in range(0, len(stream), chunk):
        out += decoder.feed(stream[start:start + chunk])
    intact = [f for k, f in enumerate(frames) if k not in touched]
    assert is_subsequence(out, frames)
    assert is_subsequence(intact, out)
    if len(out) < len(frames):
        assert stats.framing_errors + stats.crc_errors + stats.oversize >= 1
    assert decoder.buffered <= cobs_max_encoded(64 + 4)


def test_crc_error_is_counted_and_next_frame_survives() -> None:
    frame = b"\x55" * 1600  # no zeros: every byte after a code byte is data
    wire = bytearray(encode_frame(frame))
    wire[10] ^= 0xFF  # a data byte (0x55 -> 0xAA): COBS structure intact, CRC broken
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=4096, stats=stats)
    assert decoder.feed(bytes(wire) + encode_frame(b"next")) == [b"next"]
    assert stats.crc_errors == 1
    assert stats.framing_errors == 0


def test_garbage_between_frames_is_one_framing_error() -> None:
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=4096, stats=stats)
    stream = encode_frame(b"a") + b"\x07\x01\x02" + encode_frame(b"b")
    assert decoder.feed(stream) == [b"a", b"b"]
    assert stats.framing_errors == 1
    assert stats.crc_errors == 0


def test_zero_runs_are_idle_not_frames() -> None:
    """An idle line (or a break) reads as zeros; five zero bytes decode to four-byte runs
    whose CRC would be zero for an empty frame: they must not deliver anything."""
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=4096, stats=stats)
    assert decoder.feed(bytes(50) + b"\x01\x01\x01\x01\x01\x00") == []
    assert stats.framing_errors == 1


def test_oversize_run_is_dropped_and_bounded() -> None:
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=100, stats=stats)
    assert decoder.feed(b"\x00" + b"\x07" * 5000) == []
    assert decoder.buffered == 0
    assert decoder.feed(b"\x07" * 5000 + encode_frame(b"ok")) == [b"ok"]
    assert stats.oversize == 1


def test_frame_longer_than_receiver_max_is_oversize() -> None:
    stats = TransportStats()
    decoder = FrameDecoder(max_frame=100, stats=stats)
    assert decoder.feed(encode_frame(bytes(101)) + encode_frame(bytes(100))) == [bytes(100)]
    assert stats.oversize == 1
