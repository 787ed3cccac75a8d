"""Frame transports between the fieldbus master and its slaves, chosen by name.

One interface (:class:`Transport`: ``send``, ``recv``, ``close``, ``stats``), four
backends (:data:`BACKENDS`):

========  ===========================================================================
inproc    two deques in this process; deterministic, fastest, no loss (the default)
udp       one frame per UDP datagram, EtherCAT's port 34980, loopback by default
serial    COBS + CRC-32 framing over any pyserial port, pty or ``loop://``
can       frames cut into CAN-FD (64 B) or classic (8 B) segments, CRC-32, python-can
========  ===========================================================================

::

    from hil.transports import open_transport, transport_pair

    master, slave = transport_pair("udp")
    master.send(frame); request = slave.recv(timeout=0.01)

See docs/transports.md for the wire formats, options and limits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hil.transports.base import (
    BACKENDS,
    DEFAULT_MAX_FRAME,
    ROLES,
    SERVING_BACKENDS,
    Listening,
    RemotePeer,
    Transport,
    TransportError,
    TransportStats,
    backend,
    open_transport,
    prefixed_options,
    transport_pair,
)
from hil.transports.echo import round_trip_rate

if TYPE_CHECKING:
    from hil.transports.serialport import PtyPair

__all__ = [
    "BACKENDS",
    "DEFAULT_MAX_FRAME",
    "ROLES",
    "SERVING_BACKENDS",
    "Listening",
    "RemotePeer",
    "Transport",
    "TransportError",
    "TransportStats",
    "backend",
    "open_transport",
    "prefixed_options",
    "pty_pair",
    "round_trip_rate",
    "transport_pair",
]


def pty_pair() -> PtyPair:
    """A raw-mode pseudo-terminal; see :func:`hil.transports.serialport.pty_pair`.

    Defined here as a thin wrapper so that importing the package does not import pyserial.
    """
    from hil.transports.serialport import pty_pair as _pty_pair

    return _pty_pair()
