"""The UDP transport: loopback by default, EtherCAT's port, two processes."""

from __future__ import annotations

import socket

import pytest

from hil.transports import TransportError, open_transport, transport_pair
from hil.transports.echo import image_frame, invert, remote_echo
from hil.transports.udp import ETHERCAT_UDP_PORT, UdpTransport


def test_binds_loopback_by_default() -> None:
    with open_transport("udp", "master") as master:
        assert master.address[0] == "127.0.0.1"
        assert master.port != 0
        assert master.peer == ("127.0.0.1", ETHERCAT_UDP_PORT)
    with open_transport("udp", "slave", port=0) as slave:
        assert slave.address[0] == "127.0.0.1"
        assert slave.peer is None


def test_slave_default_port_is_ethercat() -> None:
    assert ETHERCAT_UDP_PORT == 34980 == 0x88A4
    try:
        slave = open_transport("udp", "slave")
    except TransportError as exc:  # something on this machine already holds 34980
        assert "already in use" in str(exc)
        return
    with slave:
        assert slave.port == 34980


def test_port_in_use_is_a_clear_error() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(TransportError) as exc:
            open_transport("udp", "slave", port=port)
    text = str(exc.value)
    assert "\n" not in text
    assert text.startswith(f"udp: cannot bind 127.0.0.1:{port}: address already in use")
    assert "port=0" in text


def test_slave_replies_to_the_latest_master() -> None:
    slave = UdpTransport("slave", port=0)
    first = UdpTransport("master", remote_port=slave.port)
    second = UdpTransport("master", remote_port=slave.port)
    try:
        with pytest.raises(TransportError) as exc:
            slave.send(b"nobody yet")
        assert "has not heard from a master" in str(exc.value)
        first.send(b"1")
        assert slave.recv(1.0) == b"1"
        assert slave.peer == first.address
        second.send(b"2")  # e.g. the master restarted on a new ephemeral port
        assert slave.recv(1.0) == b"2"
        slave.send(b"reply")
        assert second.recv(1.0) == b"reply"
        assert first.recv(0) is None
    finally:
        for t in (slave, first, second):
            t.close()


def test_master_ignores_strangers() -> None:
    master, slave = transport_pair("udp")
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.sendto(b"spoof", master.address)  # type: ignore[attr-defined]
        master.send(b"hello")
        assert slave.recv(1.0) == b"hello"
        slave.send(b"answer")
        assert master.recv(1.0) == b"answer"  # not b"spoof": connect() filters it
    finally:
        master.close()
        slave.close()


def test_oversize_datagram_is_dropped_and_counted() -> None:
    master, slave = transport_pair("udp", max_frame=2000)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.sendto(bytes(2001), slave.address)  # type: ignore[attr-defined]
            raw.sendto(bytes(2000), slave.address)  # type: ignore[attr-defined]
        assert slave.recv(1.0) == bytes(2000)
        assert slave.stats.oversize == 1
    finally:
        master.close()
        slave.close()


def test_master_before_slave_loses_frames_quietly() -> None:
    """No slave listening: the ICMP 'port unreachable' does not break the master."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        free = probe.getsockname()[1]
    with open_transport("udp", "master", remote_port=free) as master:
        master.send(b"into the void")
        assert master.recv(timeout=0.05) is None
        master.send(b"again")


def test_two_processes_round_trip_300_image_frames() -> None:
    """The slave runs in a child process (`python -m hil.transports echo udp`) and answers
    each frame with its bits inverted; the master checks every reply."""
    with remote_echo("udp", port=0) as connect:
        assert connect["remote_host"] == "127.0.0.1"
        with open_transport("udp", "master", **connect) as master:
            for i in range(300):
                frame = image_frame(i)
                master.send(frame)
                assert master.recv(timeout=5.0) == invert(frame)
            assert master.stats.frames_received == 300
            assert master.stats.bytes_received == 300 * 1600


def test_echo_process_reports_a_bad_option() -> None:
    with pytest.raises(TransportError) as exc:
        with remote_echo("udp", prot=1):
            pass
    assert "unknown option 'prot'" in str(exc.value)
