"""The transport interface: move opaque byte frames between a master end and a slave end.

A transport knows nothing about EtherCAT. It carries whole frames (in practice an EtherCAT
frame: 2-byte header + datagrams, up to ~2.1 kB) from one end to the other and back, and
either delivers a frame exactly as it was sent or not at all. Backends are chosen by name,
as in python-can's ``can.Bus(interface=...)``::

    with open_transport("udp", role="slave", port=0) as slave: ...
    master, slave = transport_pair("inproc")

Every backend shares the checks done here (frame type and size, closed state, timeout
value) and the statistics in :class:`TransportStats`, so the fieldbus code on top can treat
them alike. Backends implement :meth:`Transport._send` and :meth:`Transport._recv`.
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
import inspect
import math
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, ClassVar

#: Roles of the two ends. The names follow EtherCAT: the master starts each exchange.
ROLES: tuple[str, ...] = ("master", "slave")

#: Default largest frame [bytes] a transport sends or accepts. An EtherCAT frame inside an
#: Ethernet frame is at most 1498 bytes; the full-robot process image is ~1.6 kB per
#: direction, so 4096 leaves room for the ~2.1 kB frames of this harness.
DEFAULT_MAX_FRAME = 4096

#: Backend name -> "module:Class", imported on first use so that ``import hil.transports``
#: does not pull in pyserial or python-can.
_REGISTRY: dict[str, str] = {
    "inproc": "hil.transports.inproc:InprocTransport",
    "udp": "hil.transports.udp:UdpTransport",
    "serial": "hil.transports.serialport:SerialTransport",
    "can": "hil.transports.canbus:CanTransport",
}

#: The backend names, in the order the error messages list them.
BACKENDS: tuple[str, ...] = tuple(_REGISTRY)

#: The backends ``eha-hil serve`` offers, in :data:`BACKENDS`' order: those whose class says
#: :attr:`Transport.serves_remote_masters`, named here as well so that the command line can
#: list them without importing every backend (python-can's import alone is ~0.1 s of each
#: start of the console script). tests/transports/test_transport_api.py checks they agree.
SERVING_BACKENDS: tuple[str, ...] = ("udp", "serial")


class TransportError(Exception):
    """A transport cannot be opened or used; the message is one line naming the cause."""


@dataclasses.dataclass
class TransportStats:
    """Counters of one transport end, since it was opened (or since :meth:`reset`).

    ``bytes_*`` count frame bytes (what :meth:`Transport.send` is given and
    :meth:`Transport.recv` returns), not the bytes on the wire (framing, CRC and segment
    headers are not included).
    """

    frames_sent: int = 0
    frames_received: int = 0
    bytes_sent: int = 0
    bytes_received: int = 0
    #: frames dropped because their CRC-32 did not match (serial, can)
    crc_errors: int = 0
    #: frames dropped because their bytes did not form a frame: bad COBS structure, a run of
    #: garbage between delimiters, a lost/duplicated/reordered CAN segment (one count per
    #: resynchronisation, not per garbage byte)
    framing_errors: int = 0
    #: frames longer than ``max_frame``: refused by send, or dropped on receive
    oversize: int = 0
    #: recv calls that returned None because the timeout passed
    timeouts: int = 0

    def reset(self) -> None:
        """Set every counter back to zero."""
        for field in dataclasses.fields(self):
            setattr(self, field.name, 0)

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (for JSON and logs)."""
        return dataclasses.asdict(self)


def deadline_of(timeout: float | None) -> float | None:
    """Monotonic time [s] at which a wait of ``timeout`` seconds ends; None = never."""
    return None if timeout is None else time.monotonic() + timeout


def remaining(deadline: float | None) -> float | None:
    """Seconds left until ``deadline`` (never negative); None if there is no deadline."""
    return None if deadline is None else max(0.0, deadline - time.monotonic())


class Transport(abc.ABC):
    """One end (master or slave) of a frame transport.

    Frames are ``bytes`` of 1 to ``max_frame`` bytes. Empty frames are refused: every
    EtherCAT frame has at least its 2-byte header, and refusing them keeps an idle serial
    line (a run of zero bytes) from ever decoding to a valid empty frame.

    :meth:`recv` returns a frame exactly as the other end sent it, or None when the timeout
    passes; damaged frames are dropped and counted in :attr:`stats`, never returned.
    Frames may be lost (udp, a noisy serial line, a CAN bus); the caller handles that with
    its own timeouts, as an EtherCAT master does with the working counter.
    """

    #: backend name, as given to :func:`open_transport`
    name: ClassVar[str] = "?"
    #: A sent frame is at the other end when ``send`` returns (memory in this process): the
    #: bus need not wait for it, and a run over it is deterministic enough to log.
    in_memory: ClassVar[bool] = False
    #: The bus system puts the chain of boxes in another process by default on this backend.
    remote_by_default: ClassVar[bool] = False
    #: ``eha-hil serve`` offers it: a master in another process or on another machine can
    #: reach an end that :meth:`listen` opened.
    serves_remote_masters: ClassVar[bool] = False
    #: The fieldbus appends its CRC-32 trailer to every frame on this backend unless told
    #: otherwise (``hil.fieldbus.wire``). Off where the carrier's own format has no room
    #: for one (udp: EtherCAT over UDP is the bare PDU, the UDP checksum guards it).
    crc_trailer_by_default: ClassVar[bool] = True
    #: What :meth:`listen` listens on when the user names nothing (None: they must).
    default_listen_address: ClassVar[str | None] = None

    def __init__(self, role: str, max_frame: int = DEFAULT_MAX_FRAME) -> None:
        if role not in ROLES:
            raise TransportError(f"{self.name}: role must be 'master' or 'slave', not {role!r}")
        if isinstance(max_frame, bool) or not isinstance(max_frame, int) or max_frame < 1:
            raise TransportError(
                f"{self.name}: max_frame must be a positive integer (bytes), got {max_frame!r}"
            )
        self.role: str = role
        self.max_frame: int = max_frame
        self.stats: TransportStats = TransportStats()
        self._closed = False

    # -- the interface -------------------------------------------------------------------

    def send(self, frame: bytes | bytearray | memoryview) -> None:
        """Send one frame to the other end.

        Raises :class:`TransportError` if the transport is closed, the frame is not
        bytes-like, empty, or longer than ``max_frame`` (then also counted in
        ``stats.oversize``), or the underlying device fails.
        """
        if self._closed:
            raise TransportError(f"{self.name}: send on a closed transport")
        if not isinstance(frame, bytes | bytearray | memoryview):
            raise TransportError(
                f"{self.name}: a frame must be bytes, not {type(frame).__name__}"
            )
        data = bytes(frame)  # no copy when it already is bytes
        size = len(data)
        if size == 0:
            raise TransportError(
                f"{self.name}: empty frame (a frame has 1..{self.max_frame} bytes)"
            )
        if size > self.max_frame:
            self.stats.oversize += 1
            raise TransportError(
                f"{self.name}: frame of {size} bytes is longer than max_frame={self.max_frame}"
            )
        self._send(data)
        self.stats.frames_sent += 1
        self.stats.bytes_sent += size

    def recv(self, timeout: float | None = None) -> bytes | None:
        """Return the next frame from the other end, or None after ``timeout`` seconds.

        ``timeout=None`` waits for ever, ``0`` only looks at what has already arrived.
        Never returns a damaged frame.
        """
        if self._closed:
            raise TransportError(f"{self.name}: recv on a closed transport")
        if timeout is not None:
            if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not (
                timeout >= 0 and math.isfinite(timeout)
            ):
                raise TransportError(
                    f"{self.name}: timeout must be None or a finite number of seconds >= 0, "
                    f"got {timeout!r}"
                )
        frame = self._recv(timeout)
        if frame is None:
            self.stats.timeouts += 1
            return None
        self.stats.frames_received += 1
        self.stats.bytes_received += len(frame)
        return frame

    def close(self) -> None:
        """Release the socket, port or bus. Safe to call more than once."""
        if not self._closed:
            self._closed = True
            self._close()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has been called."""
        return self._closed

    def __enter__(self) -> Transport:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"<{type(self).__name__} {self.name} {self.role} {state}>"

    # -- what a backend implements -------------------------------------------------------

    @abc.abstractmethod
    def _send(self, frame: bytes) -> None:
        """Put one checked, non-empty frame of at most ``max_frame`` bytes on the wire."""

    @abc.abstractmethod
    def _recv(self, timeout: float | None) -> bytes | None:
        """Return the next good frame, or None when ``timeout`` (None = never) has passed."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the resources; called once."""

    @classmethod
    def _pair(cls, **options: Any) -> tuple[Transport, Transport]:
        """Two connected ends (master, slave); backends override when they can."""
        raise TransportError(f"{cls.name}: transport_pair is not supported by this backend")

    # -- peers in another process: each backend knows how its ends find each other --------

    @classmethod
    def can_listen(cls) -> bool:
        """Whether the backend implements :meth:`listen`."""
        return cls.listen.__func__ is not Transport.listen.__func__

    @classmethod
    def listen(cls, address: str, **options: Any) -> Listening:
        """A slave end for a master in another process or on another machine. ``address``
        is the backend's own address text (a UDP port, a serial device or ``pty``, a CAN
        channel); TransportError (one line) if it is not one."""
        raise TransportError(f"{cls.name}: cannot serve a peer in another process")

    @classmethod
    def remote_master(cls, **options: Any) -> RemotePeer:
        """How a master reaches a slave this process starts: the address the child listens
        on, and how to connect once the child has said where it listens."""
        raise TransportError(f"{cls.name}: cannot reach a chain in another process")

    @classmethod
    def private_options(cls) -> dict[str, Any]:
        """Options for a bus run that must not meet another one on this machine (a
        benchmark, a test): none needed where pairs are private anyway."""
        return {}

    def record_to(self, path: str) -> Any:
        """Start writing the traffic of this end's bus to ``path`` in the bus's own log
        format; returns the recorder (``.close()`` ends it). TransportError if this
        backend has none (only ``can`` does: BLF, ASC, candump)."""
        raise TransportError(f"{self.name}: no traffic log of its own (CAN logs need the "
                             "can transport)")

    def capture_endpoints(self) -> tuple[tuple[str, int], tuple[str, int]] | None:
        """For a capture file: (this end's, the peer's) IPv4 address and port when the
        frames travel as UDP datagrams, so the capture shows them as such; None when the
        carrier is not IP (the capture then shows raw EtherCAT over Ethernet)."""
        return None


@dataclasses.dataclass
class Listening:
    """A listening slave end: ``address`` is what a peer needs to reach it (a port, a
    path), ``where`` the same for people; ``close`` releases what the end does not own."""

    end: Transport
    address: str
    where: str
    close: Callable[[], None] | None = None


@dataclasses.dataclass
class RemotePeer:
    """A slave in a child process: it listens on ``child_address``; ``connect(address)``,
    given the address the child reports, opens the master end; ``close`` releases the
    resources made for the pair (e.g. a pseudo-terminal)."""

    child_address: str
    connect: Callable[[str], Transport]
    close: Callable[[], None] | None = None


def prefixed_options(name: str, given: dict[str, Any]) -> dict[str, Any]:
    """Backend options from command-line values named ``<backend>_<option>`` (e.g.
    ``udp_port``, ``can_channel``): those of backend ``name`` with the prefix removed;
    None values are left out; a value given for another backend is a TransportError
    naming the flag (``--can-channel: only with --transport can``)."""
    out = {}
    for key, value in given.items():
        owner, _, option = key.partition("_")
        if value is None:
            continue
        if owner not in _REGISTRY or not option:
            raise TransportError(f"{key}: not a <backend>_<option> name")
        if owner != name:
            raise TransportError(f"--{key.replace('_', '-')}: only with --transport {owner}")
        out[option] = value
    return out


def backend(name: str) -> type[Transport]:
    """The backend class registered under ``name`` (its capabilities: ``in_memory``,
    ``remote_by_default``, ``listen``, ``remote_master``); TransportError if none."""
    return _backend(name)


def _backend(name: str) -> type[Transport]:
    """The backend class registered under ``name``; TransportError if there is none."""
    if not isinstance(name, str) or name not in _REGISTRY:
        raise TransportError(f"unknown transport {name!r}; choose from {', '.join(BACKENDS)}")
    module_name, _, class_name = _REGISTRY[name].partition(":")
    cls: type[Transport] = getattr(importlib.import_module(module_name), class_name)
    return cls


def _check_options(name: str, func: Callable[..., Any], options: dict[str, Any],
                   skip: tuple[str, ...] = ("self", "role")) -> None:
    """Raise a one-line TransportError if ``options`` holds a keyword ``func`` lacks."""
    params = [p for p in inspect.signature(func).parameters if p not in skip]
    for key in options:
        if key not in params:
            valid = ", ".join(params) or "(none)"
            raise TransportError(f"{name}: unknown option {key!r}; valid options: {valid}")


def open_transport(name: str = "inproc", role: str = "master", **options: Any) -> Transport:
    """Open one end of the transport called ``name`` (see :data:`BACKENDS`).

    ``role`` is ``"master"`` or ``"slave"``; ``options`` are the backend's keyword options
    (documented on each backend class and in docs/transports.md). A bad name, role or
    option raises :class:`TransportError` with a one-line message.
    """
    cls = _backend(name)
    if role not in ROLES:
        raise TransportError(f"{name}: role must be 'master' or 'slave', not {role!r}")
    _check_options(name, cls.__init__, options)
    return cls(role, **options)


def transport_pair(name: str = "inproc", **options: Any) -> tuple[Transport, Transport]:
    """Return connected ``(master, slave)`` ends of the transport called ``name``.

    For tests and in-process use: both ends live in this process (udp on loopback with a
    free port, serial over a fresh pseudo-terminal, can on a private virtual channel).
    """
    cls = _backend(name)
    _check_options(name, cls._pair, options, skip=("cls",))
    return cls._pair(**options)
