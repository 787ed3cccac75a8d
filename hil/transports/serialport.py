"""Serial transport: frames over a byte stream (UART, USB-serial, pseudo-terminal, loop).

Wire format (see :mod:`hil.transports.framing`): ``00 | COBS(frame + CRC-32 LE) | 00``.
The port is opened with pyserial's ``serial_for_url``, so a device path
(``/dev/ttyUSB0``, ``/dev/pts/7``) and pyserial URLs (``loop://``, ``socket://host:port``,
``rfc2217://``) all work; ``fd=`` takes an already open file descriptor, such as the
controlling side of a pseudo-terminal from :func:`pty_pair`, which pyserial cannot open by
path.

Reads never block longer than asked: ``recv(timeout)`` waits (``select`` on the port's
file descriptor, or the port's own timeout for URL ports without one) until *some* bytes
arrive, takes all that are waiting, feeds them to the frame decoder and repeats until a
frame is complete or the time is up. Frames completed by the same read are kept for the
next ``recv``.

Speed: a UART carries 10 bits per byte, so at the default 3 Mbaud a 1.6 kB frame takes
~5.4 ms on the wire; a 1 kHz cycle with full process images in both directions needs
~33 Mbaud, more than any UART. Serial suits a few joints, a bench, or a log replay.
"""

from __future__ import annotations

import dataclasses
import errno
import os
import select
import tty
from collections import deque
from typing import Any

import serial

from hil.transports.base import (
    DEFAULT_MAX_FRAME,
    Listening,
    RemotePeer,
    Transport,
    TransportError,
    deadline_of,
    remaining,
)
from hil.transports.framing import FrameDecoder, encode_frame

#: Default line speed [baud]: the highest common rate of USB-serial bridges (FTDI FT232R/H,
#: CP2102N). Ignored by pseudo-terminals and ``loop://``.
DEFAULT_BAUDRATE = 3_000_000

#: Largest single read [bytes]; the decoder takes any amount, this only bounds one call.
_READ_CHUNK = 65536

#: A write that cannot complete in this time [s] fails instead of hanging (a real port
#: stalled by flow control, a loop:// buffer nobody reads).
_WRITE_TIMEOUT = 2.0

#: Capacity [bytes] given to a loop:// port; pyserial's default (4096) would not hold one
#: 4096-byte frame with its framing, and a write to a full loop blocks.
_LOOP_BUFFER = 1 << 16


class _PortIO:
    """Read/write on an open pyserial port, waiting with ``select`` when it has a fd."""

    def __init__(self, port: Any) -> None:
        self.port = port
        try:
            self.fd: int | None = port.fileno()
        except (AttributeError, OSError, serial.SerialException):
            self.fd = None  # loop://, socket:// ... wait with the port's own timeout

    def read(self, timeout: float | None) -> bytes:
        """Bytes that arrive within ``timeout`` seconds (None = wait for ever): all that
        are waiting as soon as there is at least one, or b"" if none came."""
        port = self.port
        waiting = port.in_waiting
        if waiting:
            return bytes(port.read(min(waiting, _READ_CHUNK)))
        if timeout == 0:
            return b""
        if self.fd is not None:
            ready, _, _ = select.select([self.fd], [], [], timeout)
            if not ready:
                return b""
            return bytes(port.read(max(1, min(port.in_waiting, _READ_CHUNK))))
        if port.timeout != timeout:
            port.timeout = timeout
        first = port.read(1)
        if not first:
            return b""
        waiting = port.in_waiting
        return bytes(first + port.read(min(waiting, _READ_CHUNK))) if waiting else bytes(first)

    def write(self, data: bytes) -> None:
        self.port.write(data)

    def close(self) -> None:
        self.port.close()


class _FdIO:
    """Read/write on a raw file descriptor (the controlling side of a pty)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def read(self, timeout: float | None) -> bytes:
        ready, _, _ = select.select([self.fd], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self.fd, _READ_CHUNK)
        except OSError as exc:
            if exc.errno == errno.EIO:
                # Linux reports EIO on a pty whose other side has been closed.
                raise TransportError("serial: the other side of the pseudo-terminal is "
                                     "closed") from None
            raise

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            written = os.write(self.fd, view)
            view = view[written:]

    def close(self) -> None:
        pass  # the fd belongs to whoever passed it in


@dataclasses.dataclass
class PtyPair:
    """A raw-mode pseudo-terminal: ``master_fd`` is the controlling side (use it with
    ``fd=``), ``slave_path`` the device any program can open like a serial port
    (``/dev/pts/N``). ``slave_fd`` is held open so the controlling side never sees the
    terminal hang up while the device is between users."""

    master_fd: int
    slave_fd: int
    slave_path: str

    def close(self) -> None:
        """Close both fds (idempotent)."""
        for name in ("master_fd", "slave_fd"):
            fd = getattr(self, name)
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
                setattr(self, name, -1)

    def __enter__(self) -> PtyPair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def pty_pair() -> PtyPair:
    """Open a pseudo-terminal in raw mode (no echo, no line editing, no CR/LF mapping, all
    8 bits pass), for tests and for serving a serial end to another program."""
    master_fd, slave_fd = os.openpty()
    try:
        tty.setraw(slave_fd)  # the line discipline lives on the slave side; raw = transparent
        path = os.ttyname(slave_fd)
    except BaseException:
        os.close(master_fd)
        os.close(slave_fd)
        raise
    return PtyPair(master_fd, slave_fd, path)


class SerialTransport(Transport):
    """One end of a serial link (give exactly one of ``url``, ``fd``, ``port``).

    Options:
        url: a device path or pyserial URL (``"/dev/ttyUSB0"``, ``"/dev/pts/3"``,
            ``"loop://"``); the transport opens and closes the port.
        fd: an open file descriptor (e.g. :attr:`PtyPair.master_fd`); left open on close.
        port: an open pyserial ``Serial``-like object; left open on close.
        baudrate: line speed [baud] for ``url`` (default 3 000 000).
        max_frame: largest frame [bytes] (default 4096).

    ``loop://`` echoes every byte back to the same port, so one transport on it receives
    its own frames: a send then a recv is a full encode/wire/decode round trip.
    """

    name = "serial"
    serves_remote_masters = True

    def __init__(
        self,
        role: str,
        url: str | None = None,
        fd: int | None = None,
        port: Any = None,
        baudrate: int = DEFAULT_BAUDRATE,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        super().__init__(role, max_frame)
        given = [k for k, v in (("url", url), ("fd", fd), ("port", port)) if v is not None]
        if len(given) != 1:
            what = "none" if not given else " and ".join(given)
            raise TransportError(
                "serial: give exactly one of url= (e.g. 'loop://', '/dev/ttyUSB0'), fd= or "
                f"port=; got {what}"
            )
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise TransportError(f"serial: baudrate must be a positive integer, got {baudrate!r}")
        self.url = url
        self._io: _PortIO | _FdIO
        if url is not None:
            if not isinstance(url, str) or not url:
                raise TransportError(f"serial: url must be a non-empty string, got {url!r}")
            try:
                # timeout=0: reads return what is waiting; waiting is done by _PortIO.read.
                opened = serial.serial_for_url(url, baudrate=baudrate, timeout=0,
                                               write_timeout=_WRITE_TIMEOUT, do_not_open=True)
                if hasattr(opened, "buffer_size"):  # loop://: size its byte queue
                    opened.buffer_size = _LOOP_BUFFER
                opened.open()
            except (serial.SerialException, ValueError, OSError) as exc:
                raise TransportError(f"serial: cannot open {url!r}: {_one_line(exc)}") from None
            self._io = _PortIO(opened)
            self._owns_io = True
        elif fd is not None:
            if isinstance(fd, bool) or not isinstance(fd, int) or fd < 0:
                raise TransportError(f"serial: fd must be an open file descriptor, got {fd!r}")
            self._io = _FdIO(fd)
            self._owns_io = False
        else:
            if not all(hasattr(port, a) for a in ("read", "write", "in_waiting")):
                raise TransportError("serial: port must be an open pyserial Serial-like object "
                                     f"(read, write, in_waiting), got {type(port).__name__}")
            self._io = _PortIO(port)
            self._owns_io = False
        self._decoder = FrameDecoder(max_frame, self.stats)
        self._ready: deque[bytes] = deque()
        self._on_close: list[Any] = []

    def _send(self, frame: bytes) -> None:
        try:
            self._io.write(encode_frame(frame))
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"serial: write failed: {_one_line(exc)}") from None

    def _recv(self, timeout: float | None) -> bytes | None:
        ready = self._ready
        if ready:
            return ready.popleft()
        deadline = deadline_of(timeout)
        while True:
            try:
                data = self._io.read(remaining(deadline))
            except (serial.SerialException, OSError) as exc:
                raise TransportError(f"serial: read failed: {_one_line(exc)}") from None
            if data:
                ready.extend(self._decoder.feed(data))
                if ready:
                    return ready.popleft()
            elif deadline is not None and remaining(deadline) == 0.0:
                return None

    def _close(self) -> None:
        try:
            if self._owns_io:
                self._io.close()
        finally:
            for callback in self._on_close:
                callback()

    @classmethod
    def listen(cls, address: str, baudrate: int = DEFAULT_BAUDRATE,
               **options: Any) -> Listening:
        """A slave on the device or pyserial URL ``address``, or on a new pseudo-terminal
        for ``"pty"`` (its path is what the peer opens)."""
        if address != "pty":
            end = cls("slave", url=address, baudrate=baudrate, **options)
            return Listening(end, address, f"serial {address} at {baudrate} baud")
        try:
            pty_ = pty_pair()
        except OSError as exc:
            raise TransportError(f"cannot open a pseudo-terminal: {exc}") from None
        try:
            end = cls("slave", fd=pty_.master_fd, **options)
        except BaseException:
            pty_.close()
            raise
        return Listening(end, pty_.slave_path, f"serial {pty_.slave_path} (new "
                         "pseudo-terminal: open this path from the master program)", pty_.close)

    @classmethod
    def remote_master(cls, **options: Any) -> RemotePeer:
        """A new pseudo-terminal: the child opens its device path, the master its
        controlling side."""
        pty_ = pty_pair()
        return RemotePeer(pty_.slave_path,
                          lambda _address: cls("master", fd=pty_.master_fd, **options),
                          pty_.close)

    @classmethod
    def _pair(cls, url: str | None = None, baudrate: int = DEFAULT_BAUDRATE,
              max_frame: int = DEFAULT_MAX_FRAME) -> tuple[Transport, Transport]:
        """Without ``url``: a fresh pty, the master on its controlling side, the slave on
        its device path through pyserial. With ``url="loop://"`` (or any URL that echoes):
        one transport returned as both ends, which works for strict request/response."""
        if url is not None:
            end = cls("master", url=url, baudrate=baudrate, max_frame=max_frame)
            return end, end
        pty_ = pty_pair()
        try:
            slave = cls("slave", url=pty_.slave_path, baudrate=baudrate, max_frame=max_frame)
            master = cls("master", fd=pty_.master_fd, max_frame=max_frame)
        except BaseException:
            pty_.close()
            raise
        master.pty = pty_  # type: ignore[attr-defined]
        # Close the pty after the pyserial end, whichever end is closed last.
        closed: list[str] = []

        def release(role: str) -> None:
            closed.append(role)
            if len(closed) == 2:
                pty_.close()

        master._on_close.append(lambda: release("master"))
        slave._on_close.append(lambda: release("slave"))
        return master, slave


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line (pyserial's sometimes span several)."""
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
