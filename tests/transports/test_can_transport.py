"""The CAN transport: segmentation, reassembly under loss/duplication/reordering, the
virtual bus (classic and FD), and SocketCAN where the machine has a vcan device."""

from __future__ import annotations

import os
import uuid

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.transports import TransportError, TransportStats, open_transport, transport_pair
from hil.transports.canbus import (
    FD_LENGTHS,
    Reassembler,
    max_message_frame,
    segment,
)
from hil.transports.echo import image_frame, invert, round_trip_rate
from hil.transports.framing import crc32

# -- segment layout ---------------------------------------------------------------------


def test_segment_layout_fd() -> None:
    frame = bytes(range(1, 101))  # 100 bytes -> body 2 + 100 + 4 = 106 -> 62 + 44
    segs = segment(frame, seq=5, fd=True)
    assert len(segs) == 2
    assert segs[0][:2] == (5 << 10 | 0).to_bytes(2, "little")
    assert segs[1][:2] == (1 << 15 | 5 << 10 | 1).to_bytes(2, "little")
    assert len(segs[0]) == 64
    assert len(segs[1]) == 48  # 2 + 44 bytes padded up to a CAN-FD length
    body = segs[0][2:] + segs[1][2:46]
    assert body[:2] == (100).to_bytes(2, "little")
    assert body[2:102] == frame
    assert body[102:106] == crc32(body[:102]).to_bytes(4, "little")
    assert segs[1][46:] == bytes(2)  # padding


def test_segment_layout_classic() -> None:
    segs = segment(b"\xaa\xbb", seq=31, fd=False)  # body 2 + 2 + 4 = 8 -> 6 + 2
    assert [len(s) for s in segs] == [8, 4]
    assert segs[1][:2] == (1 << 15 | 31 << 10 | 1).to_bytes(2, "little")


@given(st.binary(min_size=1, max_size=2200), st.booleans(), st.integers(0, 100))
@settings(max_examples=100)
def test_segments_round_trip(frame: bytes, fd: bool, seq: int) -> None:
    reasm = Reassembler(fd=fd, max_frame=4096)
    segs = segment(frame, seq, fd)
    for data in segs:
        assert len(data) in (FD_LENGTHS if fd else range(3, 9))
    out = [reasm.feed(s) for s in segs]
    assert out[:-1] == [None] * (len(segs) - 1)
    assert out[-1] == frame
    assert reasm.stats == TransportStats()


def test_limits() -> None:
    assert max_message_frame(True) == 1024 * 62 - 6
    assert max_message_frame(False) == 1024 * 6 - 6
    with pytest.raises(ValueError):
        segment(bytes(max_message_frame(False) + 1), 0, fd=False)


# -- damaged segment streams ------------------------------------------------------------


def stream_of(frames: list[bytes], fd: bool) -> list[tuple[int, bytes]]:
    """(message number, segment data) for every segment, in sending order."""
    return [(k, s) for k, f in enumerate(frames) for s in segment(f, k, fd)]


def feed_all(reasm: Reassembler, stream: list[tuple[int, bytes]]) -> list[bytes]:
    return [f for _, s in stream if (f := reasm.feed(s)) is not None]


FRAMES = [image_frame(i, 300) for i in range(4)]  # 300 bytes: 5 FD segments each


def test_clean_stream() -> None:
    reasm = Reassembler()
    assert feed_all(reasm, stream_of(FRAMES, True)) == FRAMES


@pytest.mark.parametrize("where", [0, 2, 4])  # first, middle, last segment of message 1
def test_lost_segment_drops_that_message_only(where: int) -> None:
    stream = stream_of(FRAMES, True)
    del stream[5 + where]
    reasm = Reassembler()
    assert feed_all(reasm, stream) == [FRAMES[0], FRAMES[2], FRAMES[3]]
    assert reasm.stats.framing_errors == 1
    assert reasm.stats.crc_errors == 0


def test_duplicated_segment_drops_the_message() -> None:
    stream = stream_of(FRAMES, True)
    stream.insert(7, stream[6])
    reasm = Reassembler()
    assert feed_all(reasm, stream) == [FRAMES[0], FRAMES[2], FRAMES[3]]
    assert reasm.stats.framing_errors == 1


def test_swapped_segments_drop_the_message() -> None:
    stream = stream_of(FRAMES, True)
    stream[6], stream[7] = stream[7], stream[6]
    reasm = Reassembler()
    assert feed_all(reasm, stream) == [FRAMES[0], FRAMES[2], FRAMES[3]]
    assert reasm.stats.framing_errors == 1


def test_tail_of_one_and_head_of_next_lost_is_caught_by_sequence_number() -> None:
    """Message 1 loses segments 3-4 and message 2 segments 0-2: the indices 0,1,2,3,4
    still run on, only the sequence number tells two messages apart."""
    stream = stream_of(FRAMES, True)
    del stream[8:13]
    reasm = Reassembler()
    assert feed_all(reasm, stream) == [FRAMES[0], FRAMES[3]]
    assert reasm.stats.framing_errors == 2


def test_repeated_single_segment_message_is_delivered_once() -> None:
    seg = segment(b"short", 3, True)
    assert len(seg) == 1
    reasm = Reassembler()
    assert [reasm.feed(seg[0]), reasm.feed(seg[0])] == [b"short", None]
    assert reasm.stats.framing_errors == 1


def test_corrupted_payload_is_a_crc_error() -> None:
    stream = stream_of(FRAMES, True)
    k, data = stream[7]
    bad = bytearray(data)
    bad[20] ^= 1
    stream[7] = (k, bytes(bad))
    reasm = Reassembler()
    assert feed_all(reasm, stream) == [FRAMES[0], FRAMES[2], FRAMES[3]]
    assert reasm.stats.crc_errors == 1
    assert reasm.stats.framing_errors == 0


def test_too_many_segments_is_oversize() -> None:
    reasm = Reassembler(fd=False, max_frame=20)  # at most ceil(26/6) = 5 segments
    stream = stream_of([bytes(range(1, 41)), b"ok"], False)
    assert feed_all(reasm, stream) == [b"ok"]
    assert reasm.stats.oversize == 1


ops_st = st.lists(
    st.tuples(st.sampled_from(["drop", "dup", "swap", "move"]), st.integers(0, 10**6),
              st.integers(0, 10**6)),
    max_size=5,
)


def apply_ops(stream: list, ops: list[tuple[str, int, int]]) -> list:
    stream = list(stream)
    for op, a, b in ops:
        if not stream:
            break
        i, j = a % len(stream), b % len(stream)
        if op == "drop":
            del stream[i]
        elif op == "dup":
            stream.insert(i, stream[i])
        elif op == "swap":
            stream[i], stream[j] = stream[j], stream[i]
        else:
            stream.insert(j, stream.pop(i))
    return stream


@pytest.mark.slow
@given(
    frames=st.lists(st.binary(min_size=1, max_size=200), min_size=1, max_size=12),
    fd=st.booleans(),
    ops=ops_st,
)
@settings(max_examples=300)
def test_damaged_streams_never_deliver_a_wrong_frame(
        frames: list[bytes], fd: bool, ops: list[tuple[str, int, int]]) -> None:
    """Drop, duplicate, swap or move segments anywhere, then send one clean message: every
    frame delivered is a frame that was sent; a message whose segments arrive in one run,
    in order, is delivered; a message partly lost is counted; the clean message at the
    end always gets through."""
    original = stream_of(frames, fd)
    stream = apply_ops(original, ops)
    sentinel = b"sentinel"
    reasm = Reassembler(fd=fd)
    out = feed_all(reasm, stream + [(-1, s) for s in segment(sentinel, len(frames), fd)])
    assert out[-1] == sentinel
    out = out[:-1]
    assert all(f in frames for f in out)
    for k, frame in enumerate(frames):
        want = [s for m, s in original if m == k]
        positions = [p for p, (m, _) in enumerate(stream) if m == k]
        got = [stream[p][1] for p in positions]
        contiguous = bool(positions) and positions == list(
            range(positions[0], positions[0] + len(positions)))
        if got == want and contiguous:
            assert frame in out
        elif got and any(seg not in got for seg in want):  # partly lost
            assert reasm.stats.framing_errors + reasm.stats.crc_errors >= 1


@given(
    frames=st.lists(st.binary(min_size=1, max_size=200), min_size=1, max_size=12),
    fd=st.booleans(),
    ops=st.lists(st.tuples(st.sampled_from(["drop", "dup"]), st.integers(0, 10**6),
                           st.integers(0, 10**6)), max_size=5),
)
@settings(max_examples=200)
def test_without_reordering_frames_keep_their_order(
        frames: list[bytes], fd: bool, ops: list[tuple[str, int, int]]) -> None:
    """Lost and repeated segments (no reordering): the frames delivered are a subsequence
    of those sent; in particular a repeated one-segment message is delivered once."""
    out = feed_all(Reassembler(fd=fd), apply_ops(stream_of(frames, fd), ops))
    it = iter(frames)
    assert all(any(x == y for y in it) for x in out)


# -- on a bus ---------------------------------------------------------------------------


@pytest.mark.parametrize("fd", [True, False], ids=["fd", "classic"])
def test_virtual_bus_image_frames_both_ways(fd: bool) -> None:
    master, slave = transport_pair("can", fd=fd)
    try:
        for i in range(3):
            down = image_frame(i)
            master.send(down)
            assert slave.recv(timeout=2.0) == down
            slave.send(invert(down))
            assert master.recv(timeout=2.0) == invert(down)
    finally:
        master.close()
        slave.close()


def test_ids_and_frame_kinds_on_the_bus() -> None:
    channel = f"test-{uuid.uuid4().hex}"
    spy = can.Bus(interface="virtual", channel=channel, fd=True)
    master = open_transport("can", "master", channel=channel, base_id=0x300)
    slave = open_transport("can", "slave", channel=channel, base_id=0x300)
    try:
        master.send(image_frame(1, 200))
        assert slave.recv(2.0) == image_frame(1, 200)
        slave.send(b"up")
        seen = []
        while (msg := spy.recv(0)) is not None:
            seen.append(msg)
        assert {m.arbitration_id for m in seen[:-1]} == {0x300}
        assert seen[-1].arbitration_id == 0x301
        assert all(m.is_fd and not m.is_extended_id for m in seen)
        assert [len(m.data) for m in seen] == [64, 64, 64, 24, 12]  # 206 = 3*62 + 20
    finally:
        for end in (master, slave):
            end.close()
        spy.shutdown()


def test_stray_and_duplicated_segments_on_the_bus() -> None:
    """A third node injects a duplicate segment with the master's ID in the middle of a
    message: that message is dropped and counted, the next one gets through."""
    channel = f"test-{uuid.uuid4().hex}"
    rogue = can.Bus(interface="virtual", channel=channel, fd=True)
    master = open_transport("can", "master", channel=channel)
    slave = open_transport("can", "slave", channel=channel)
    try:
        segs = segment(image_frame(1), 0, True)
        for data in segs[:3] + segs[2:]:  # segment 2 twice
            rogue.send(can.Message(arbitration_id=0x100, data=data, is_fd=True,
                                   is_extended_id=False))
        rogue.send(can.Message(arbitration_id=0x7FF, data=b"other traffic", is_fd=True,
                               is_extended_id=False))
        master.send(image_frame(2))
        assert slave.recv(timeout=2.0) == image_frame(2)
        assert slave.stats.framing_errors == 1
        assert slave.stats.frames_received == 1
    finally:
        for end in (master, slave):
            end.close()
        rogue.shutdown()


def test_virtual_round_trip_rate_classic() -> None:
    master, slave = transport_pair("can", fd=False)
    try:
        assert round_trip_rate(master, slave, image_frame(0), 3, responder=invert) > 0
    finally:
        master.close()
        slave.close()


def _vcan() -> str | None:
    try:
        names = os.listdir("/sys/class/net")
    except OSError:
        return None
    return next((n for n in sorted(names) if n.startswith("vcan")), None)


def test_socketcan_when_available() -> None:
    dev = _vcan()
    if dev is None:
        pytest.skip("no vcan device: needs Linux with `ip link add dev vcan0 type vcan && "
                    "ip link set vcan0 mtu 72 up` (root)")
    try:
        master, slave = transport_pair("can", interface="socketcan", channel=dev)
    except TransportError as exc:
        pytest.skip(f"socketcan on {dev} unusable here: {exc}")
    try:
        frame = image_frame(4)
        master.send(frame)
        assert slave.recv(timeout=2.0) == frame
        slave.send(invert(frame))
        assert master.recv(timeout=2.0) == invert(frame)
    finally:
        master.close()
        slave.close()
