"""The serial transport on pyserial's loop:// and on a pseudo-terminal."""

from __future__ import annotations

import os

import pytest
import serial

from hil.transports import TransportError, open_transport, pty_pair, transport_pair
from hil.transports.echo import image_frame, invert, remote_echo, round_trip_rate
from hil.transports.framing import encode_frame
from hil.transports.serialport import SerialTransport


def test_loop_returns_own_frames() -> None:
    with open_transport("serial", url="loop://") as end:
        frames = [image_frame(i) for i in range(3)]
        for f in frames:
            end.send(f)
        assert [end.recv(timeout=2.0) for _ in frames] == frames
        assert end.recv(timeout=0) is None
        assert end.stats.frames_sent == end.stats.frames_received == 3


def test_loop_with_a_caller_owned_port() -> None:
    port = serial.serial_for_url("loop://", timeout=0)
    with open_transport("serial", port=port) as end:
        end.send(b"\x00\x01\x02")
        assert end.recv(timeout=1.0) == b"\x00\x01\x02"
    assert port.is_open  # the caller's port is left open
    port.close()


def test_pty_pair_is_raw_and_transparent() -> None:
    """Every byte value crosses the pty unchanged (no echo, no CR/LF mapping, no XON/XOFF,
    no line buffering)."""
    with pty_pair() as pty_:
        port = serial.serial_for_url(pty_.slave_path, timeout=1.0)
        try:
            data = bytes(range(256)) * 4
            os.write(pty_.master_fd, data)
            assert port.read(len(data)) == data
            port.write(data[::-1])
            got = b""
            while len(got) < len(data):
                got += os.read(pty_.master_fd, 4096)
            assert got == data[::-1]
        finally:
            port.close()


def test_pty_pair_transports_use_device_path_and_fd() -> None:
    master, slave = transport_pair("serial")
    try:
        assert isinstance(slave, SerialTransport) and slave.url.startswith("/dev/")
        assert round_trip_rate(master, slave, image_frame(3), 20, responder=invert) > 0
    finally:
        master.close()
        slave.close()
    assert master.pty.master_fd == -1  # type: ignore[attr-defined]  # released


def test_frame_split_across_reads_is_assembled() -> None:
    master, slave = transport_pair("serial")
    try:
        fd = master.pty.master_fd  # type: ignore[attr-defined]
        wire = encode_frame(image_frame(7))
        os.write(fd, wire[:700])
        assert slave.recv(timeout=0.05) is None  # half a frame is not a frame
        os.write(fd, wire[700:])
        assert slave.recv(timeout=2.0) == image_frame(7)
    finally:
        master.close()
        slave.close()


def test_garbage_on_the_line_is_skipped_and_counted() -> None:
    master, slave = transport_pair("serial")
    try:
        fd = master.pty.master_fd  # type: ignore[attr-defined]
        os.write(fd, b"\x13\x37garbage\xff\x00\x00\x05noise")
        master.send(b"good frame")
        wire = bytearray(encode_frame(b"bad crc!"))
        wire[3] ^= 0x40  # a data byte, not a COBS code byte
        os.write(fd, bytes(wire))
        master.send(b"after")
        assert slave.recv(timeout=2.0) == b"good frame"
        assert slave.recv(timeout=2.0) == b"after"
        assert slave.stats.framing_errors == 2  # the two garbage runs
        assert slave.stats.crc_errors == 1
        assert slave.stats.frames_received == 2
    finally:
        master.close()
        slave.close()


def test_serial_echo_in_another_process_over_a_pty() -> None:
    """A child process opens the pty's device path by name, as an external program
    (firmware bridge, terminal) would."""
    with pty_pair() as pty_:
        with remote_echo("serial", url=pty_.slave_path):
            with SerialTransport("master", fd=pty_.master_fd) as master:
                for i in range(50):
                    frame = image_frame(i)
                    master.send(frame)
                    assert master.recv(timeout=5.0) == invert(frame)


def test_closed_peer_is_reported() -> None:
    pty_ = pty_pair()
    master = SerialTransport("master", fd=pty_.master_fd)
    os.close(pty_.slave_fd)
    pty_.slave_fd = -1
    try:
        with pytest.raises(TransportError) as exc:
            master.recv(timeout=1.0)
        assert "closed" in str(exc.value)
    finally:
        master.close()
        pty_.close()
