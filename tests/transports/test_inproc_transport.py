"""The in-process transport: named channels, no copies, threads."""

from __future__ import annotations

import threading

import pytest

from hil.transports import TransportError, open_transport, transport_pair
from hil.transports.echo import echo, image_frame, invert, round_trip_rate


def test_default_backend_is_inproc() -> None:
    master, slave = transport_pair()
    assert master.name == slave.name == "inproc"
    assert (master.role, slave.role) == ("master", "slave")


def test_frames_are_not_copied() -> None:
    master, slave = transport_pair("inproc")
    frame = image_frame(0)
    master.send(frame)
    assert slave.recv(0) is frame


def test_ends_meet_on_a_named_channel() -> None:
    with open_transport("inproc", "master", channel="t1") as master:
        with open_transport("inproc", "slave", channel="t1") as slave:
            with open_transport("inproc", "slave", channel="t2") as other:
                master.send(b"ping")
                assert other.recv(0) is None
                assert slave.recv(0) == b"ping"
                slave.send(b"pong")
                assert master.recv(0) == b"pong"
    # both ends closed: the channel name is free again
    with open_transport("inproc", "master", channel="t1") as master:
        assert master.recv(0) is None


def test_second_master_on_a_channel_is_refused() -> None:
    with open_transport("inproc", "master", channel="t3"):
        with pytest.raises(TransportError) as exc:
            open_transport("inproc", "master", channel="t3")
    assert str(exc.value) == ("inproc: channel 't3' already has a master; close it first or "
                              "use another channel name")


def test_frames_to_a_closed_end_are_dropped() -> None:
    master, slave = transport_pair("inproc")
    slave.close()
    master.send(b"lost")
    assert master.pending() == 0  # type: ignore[attr-defined]
    assert slave._in.frames == type(slave._in.frames)()  # type: ignore[attr-defined]


def test_slave_served_by_another_thread() -> None:
    master, slave = transport_pair("inproc")
    server = threading.Thread(target=echo, args=(slave, invert, 200))
    server.start()
    try:
        assert round_trip_rate(master, None, image_frame(2), 200, responder=invert) > 0
    finally:
        server.join(10)
    assert not server.is_alive()
    assert slave.stats.frames_received == slave.stats.frames_sent == 200


def test_blocking_recv_wakes_on_send() -> None:
    master, slave = transport_pair("inproc")
    got: list[bytes | None] = []
    waiter = threading.Thread(target=lambda: got.append(slave.recv(timeout=30.0)))
    waiter.start()
    master.send(b"wake up")
    waiter.join(30.0)
    assert got == [b"wake up"]
