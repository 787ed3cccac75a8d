"""The common interface: every backend moves 1.6 kB frames both ways unchanged, and bad
names, roles, options and frames give a one-line TransportError."""

from __future__ import annotations

import pytest

from hil.transports import (
    BACKENDS,
    SERVING_BACKENDS,
    Transport,
    TransportError,
    TransportStats,
    backend,
    open_transport,
    round_trip_rate,
    transport_pair,
)
from hil.transports.echo import IMAGE_BYTES, echo, image_frame, invert


def one_line(exc: pytest.ExceptionInfo[TransportError]) -> str:
    text = str(exc.value)
    assert text and "\n" not in text
    return text


def test_backends_listed() -> None:
    assert BACKENDS == ("inproc", "udp", "serial", "can")


def test_the_serving_backends_are_those_whose_class_says_so() -> None:
    """The command line lists ``SERVING_BACKENDS`` without importing the backends."""
    assert SERVING_BACKENDS == tuple(b for b in BACKENDS if backend(b).serves_remote_masters)


def test_image_frames_both_ways(pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    sent_down = [image_frame(i) for i in range(4)]
    sent_up = [invert(f) for f in sent_down]
    for down, up in zip(sent_down, sent_up, strict=True):
        master.send(down)
        assert slave.recv(timeout=2.0) == down
        slave.send(up)
        assert master.recv(timeout=2.0) == up
    if master is not slave:  # serial over loop:// is one transport serving as both ends
        assert master.stats.frames_sent == slave.stats.frames_received == 4
        assert master.stats.bytes_sent == slave.stats.bytes_received == 4 * IMAGE_BYTES
        assert slave.stats.frames_sent == master.stats.frames_received == 4
    for stats in (master.stats, slave.stats):
        assert stats.crc_errors == stats.framing_errors == stats.oversize == 0


def test_two_frames_in_flight_keep_their_order(pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    a, b = image_frame(10), image_frame(11)
    master.send(a)
    master.send(b)
    assert slave.recv(timeout=2.0) == a
    assert slave.recv(timeout=2.0) == b


def test_recv_times_out_with_none_and_counts(pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    assert slave.recv(timeout=0) is None
    assert master.recv(timeout=0.01) is None
    assert slave.stats.timeouts >= 1 and master.stats.timeouts >= 1


def test_largest_frame_passes_and_longer_is_refused(pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    big = image_frame(5, master.max_frame)
    master.send(big)
    assert slave.recv(timeout=2.0) == big
    with pytest.raises(TransportError) as exc:
        master.send(big + b"x")
    assert "longer than max_frame" in one_line(exc)
    assert master.stats.oversize == 1


def test_round_trip_rate_checks_replies(pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    assert round_trip_rate(master, slave, image_frame(1), 5, responder=invert) > 0


def test_round_trip_rate_detects_a_wrong_reply() -> None:
    master, slave = transport_pair("inproc")
    replies = iter([b"right", b"wrong"])
    with pytest.raises(TransportError) as exc:
        round_trip_rate(master, slave, b"x", 3, responder=lambda _: next(replies, b"right"))
    assert "wrong reply" in one_line(exc)


def test_echo_helper_answers_until_idle() -> None:
    master, slave = transport_pair("inproc")
    for i in range(3):
        master.send(bytes([i + 1]))
    assert echo(slave, invert, idle_timeout=0) == 3
    assert [master.recv(0) for _ in range(3)] == [invert(bytes([i + 1])) for i in range(3)]


@pytest.mark.parametrize("name", ["x", "", "UDP", None])
def test_unknown_backend(name: object) -> None:
    with pytest.raises(TransportError) as exc:
        open_transport(name)  # type: ignore[arg-type]
    assert one_line(exc) == (
        f"unknown transport {name!r}; choose from inproc, udp, serial, can"
    )
    with pytest.raises(TransportError):
        transport_pair(name)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", BACKENDS)
def test_unknown_option_names_the_valid_ones(name: str) -> None:
    with pytest.raises(TransportError) as exc:
        open_transport(name, "master", bogus=1)
    text = one_line(exc)
    assert text.startswith(f"{name}: unknown option 'bogus'; valid options: ")
    assert "max_frame" in text
    with pytest.raises(TransportError) as exc:
        transport_pair(name, bogus=1)
    assert "unknown option 'bogus'" in one_line(exc)


@pytest.mark.parametrize("name", BACKENDS)
def test_bad_role(name: str) -> None:
    with pytest.raises(TransportError) as exc:
        open_transport(name, "client")
    assert one_line(exc) == f"{name}: role must be 'master' or 'slave', not 'client'"


@pytest.mark.parametrize(
    "name, options, message",
    [
        ("inproc", {"max_frame": 0}, "max_frame must be a positive integer"),
        ("inproc", {"channel": ""}, "channel must be a non-empty string"),
        ("udp", {"port": 70000}, "port must be an integer 0..65535"),
        ("udp", {"remote_port": "x"}, "remote_port must be an integer"),
        ("serial", {}, "give exactly one of url="),
        ("serial", {"url": "loop://", "fd": 3}, "got url and fd"),
        ("serial", {"url": "/dev/no-such-tty"}, "cannot open '/dev/no-such-tty'"),
        ("serial", {"url": "loop://", "baudrate": -1}, "baudrate must be a positive integer"),
        ("can", {"base_id": 0x800}, "base_id must be an integer 0..0x7fe"),
        ("can", {"fd": "yes"}, "fd must be True or False"),
        ("can", {"interface": "no-such-interface", "channel": "x"}, "cannot open"),
        ("can", {"interface": "pcan"}, "needs channel="),
        ("can", {"fd": False, "max_frame": 7000}, "max_frame must be at most 6138"),
    ],
)
def test_bad_option_values(name: str, options: dict, message: str) -> None:
    with pytest.raises(TransportError) as exc:
        open_transport(name, "master", **options)
    text = one_line(exc)
    assert text.startswith(f"{name}: ")
    assert message in text


@pytest.mark.parametrize("frame, message", [
    (b"", "empty frame"),
    ("text", "a frame must be bytes, not str"),
    (5, "a frame must be bytes, not int"),
])
def test_bad_frames(frame: object, message: str) -> None:
    master, _ = transport_pair("inproc")
    with pytest.raises(TransportError) as exc:
        master.send(frame)  # type: ignore[arg-type]
    assert message in one_line(exc)
    assert master.stats.frames_sent == 0


@pytest.mark.parametrize("timeout", [-1, float("nan"), float("inf"), "1", True])
def test_bad_timeout(timeout: object) -> None:
    _, slave = transport_pair("inproc")
    with pytest.raises(TransportError) as exc:
        slave.recv(timeout)  # type: ignore[arg-type]
    assert "timeout must be None or a finite number" in one_line(exc)


def test_bytes_like_frames_are_accepted() -> None:
    master, slave = transport_pair("inproc")
    master.send(bytearray(b"ab"))
    master.send(memoryview(b"cd"))
    assert slave.recv(0) == b"ab"
    assert slave.recv(0) == b"cd"


def test_close_is_idempotent_and_use_after_close_fails(
        pair: tuple[Transport, Transport]) -> None:
    master, slave = pair
    with master:
        pass
    assert master.closed
    master.close()
    with pytest.raises(TransportError) as exc:
        master.send(b"x")
    assert "closed" in one_line(exc)
    with pytest.raises(TransportError):
        master.recv(0)


def test_stats_reset_and_dict() -> None:
    stats = TransportStats(frames_sent=3, crc_errors=1)
    assert stats.as_dict()["frames_sent"] == 3
    stats.reset()
    assert stats == TransportStats()
