"""Raw Ethernet (Linux AF_PACKET) for EtherCAT frames: EtherType 0x88A4 on one interface.

Real EtherCAT masters (SOEM, IgH, TwinCAT) send Ethernet frames, not UDP: this end receives
every frame of that EtherType arriving on the interface and sends whole frames back. It is
not one of the :data:`hil.transports.BACKENDS` (those carry bare PDUs between the project's
own master and chain); :mod:`hil.fieldbus.esc.serve` uses it. Opening needs CAP_NET_RAW
(root); errors are :class:`~hil.transports.TransportError` with one line naming the
interface.
"""

from __future__ import annotations

import select
import socket

from hil.transports.base import TransportError
from protocols.ethercat import ETHERTYPE_ETHERCAT

PACKET_OUTGOING = 4  # sll_pkttype of a frame this host sent


def _is_up(interface: str) -> bool:
    """IFF_UP of the interface (sysfs; True if it cannot be read: let the bind decide)."""
    try:
        with open(f"/sys/class/net/{interface}/flags") as f:
            return bool(int(f.read(), 16) & 0x1)
    except (OSError, ValueError):
        return True


class RawEthernet:
    """One AF_PACKET socket bound to ``interface`` for EtherType 0x88A4."""

    def __init__(self, interface: str) -> None:
        if not hasattr(socket, "AF_PACKET"):
            raise TransportError("raw Ethernet needs Linux (AF_PACKET)")
        self.interface = interface
        try:
            socket.if_nametoindex(interface)
        except OSError:
            raise TransportError(f"--interface {interface}: no such network interface"
                                 ) from None
        if not _is_up(interface):
            raise TransportError(f"--interface {interface}: the interface is down (ip link "
                                 f"set {interface} up)")
        try:
            self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW,
                                      socket.htons(ETHERTYPE_ETHERCAT))
        except PermissionError:
            raise TransportError(f"--interface {interface}: raw sockets need root or "
                                 "CAP_NET_RAW (e.g. sudo setcap cap_net_raw+ep on python)"
                                 ) from None
        try:
            self.sock.bind((interface, ETHERTYPE_ETHERCAT))
        except OSError as exc:
            self.sock.close()
            raise TransportError(f"--interface {interface}: cannot bind: "
                                 f"{exc.strerror or exc}") from None
        self.sock.setblocking(False)
        self.frames_received = 0
        self.frames_sent = 0

    def recv(self, timeout: float) -> bytes | None:
        """The next frame from another host within ``timeout`` seconds, or None."""
        while True:
            try:
                frame, addr = self.sock.recvfrom(2048)
            except BlockingIOError:
                if timeout <= 0:
                    return None
                ready, _, _ = select.select([self.sock], [], [], timeout)
                if not ready:
                    return None
                timeout = 0.0
                continue
            except OSError as exc:
                raise TransportError(f"{self.interface}: receive failed: {exc}") from None
            if addr[2] == PACKET_OUTGOING:
                continue
            self.frames_received += 1
            return frame

    def send(self, frame: bytes) -> None:
        try:
            self.sock.send(frame)
        except OSError as exc:
            raise TransportError(f"{self.interface}: send failed: {exc}") from None
        self.frames_sent += 1

    def close(self) -> None:
        self.sock.close()
