"""UDP transport: one frame per UDP datagram, on loopback unless told otherwise.

This is EtherCAT's own UDP encapsulation (ETG.1000.4: UDP port 34980 = 0x88A4, the
payload starts with the 2-byte EtherCAT header), so a capture of the slave's port decodes
as EtherCAT in Wireshark/tshark without any setting. The datagram *is* the frame: no extra
header, no CRC of our own (the UDP checksum covers the payload, and the kernel drops a
datagram whose checksum fails).

The slave end binds ``host:port`` (default ``127.0.0.1:34980``); the master end binds
``host`` with an ephemeral port (or ``port`` if given) and sends to
``remote_host:remote_port``. The master's socket is ``connect()``-ed to the slave, so the
kernel discards datagrams from anyone else. The slave learns where to reply from the
datagrams it receives: it replies to the sender of the latest one, so a master restarted
on a new ephemeral port is followed at once.
"""

from __future__ import annotations

import errno
import socket
from typing import Any

from hil.transports.base import (
    DEFAULT_MAX_FRAME,
    Listening,
    RemotePeer,
    Transport,
    TransportError,
    deadline_of,
    remaining,
)

#: EtherCAT's UDP port (0x88A4, the EtherCAT Ethernet type).
ETHERCAT_UDP_PORT = 34980

#: Receive buffer asked of the kernel [bytes]: room for a burst of a few hundred frames of
#: ~2 kB, so a slave that falls a few cycles behind does not lose frames. The kernel caps it
#: at net.core.rmem_max.
_RCVBUF = 1 << 20


def _check_port(value: Any, option: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 65535:
        raise TransportError(f"udp: {option} must be an integer 0..65535, got {value!r}")
    return value


class UdpTransport(Transport):
    """One end of a UDP link.

    Options:
        host: local address to bind (default ``"127.0.0.1"``: only this machine can reach
            the end; pass ``"0.0.0.0"`` or an interface address to talk to another host).
        port: local UDP port; default 34980 for the slave, 0 (an ephemeral port chosen by
            the kernel) for the master. ``port=0`` on the slave picks a free port, read it
            back from :attr:`port`.
        remote_host: master only, the slave's address (default: ``host``, or 127.0.0.1 if
            ``host`` is a wildcard).
        remote_port: master only, the slave's port (default 34980).
        max_frame: largest frame [bytes] (default 4096; a larger datagram is dropped and
            counted in ``stats.oversize``).
    """

    name = "udp"
    remote_by_default = True
    serves_remote_masters = True
    crc_trailer_by_default = False
    default_listen_address = str(ETHERCAT_UDP_PORT)

    def __init__(
        self,
        role: str,
        host: str = "127.0.0.1",
        port: int | None = None,
        remote_host: str | None = None,
        remote_port: int = ETHERCAT_UDP_PORT,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        super().__init__(role, max_frame)
        if not isinstance(host, str) or not host:
            raise TransportError(f"udp: host must be an address string, got {host!r}")
        if port is None:
            port = ETHERCAT_UDP_PORT if role == "slave" else 0
        _check_port(port, "port")
        if role == "slave" and remote_host is not None:
            raise TransportError("udp: remote_host is a master option; the slave replies to "
                                 "whoever sent the last frame")
        if role == "master":
            _check_port(remote_port, "remote_port")
            if remote_port == 0:
                raise TransportError("udp: remote_port must be the slave's port (1..65535), got 0")
            if remote_host is None:
                remote_host = "127.0.0.1" if host in ("0.0.0.0", "") else host
            if not isinstance(remote_host, str) or not remote_host:
                raise TransportError(f"udp: remote_host must be an address string, got "
                                     f"{remote_host!r}")
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
            try:
                self._sock.bind((host, port))
            except OSError as exc:
                hint = (" (is another slave running? pass port=0 for a free port)"
                        if exc.errno == errno.EADDRINUSE else "")
                reason = exc.strerror or str(exc)
                raise TransportError(
                    f"udp: cannot bind {host}:{port}: {reason.lower()}{hint}"
                ) from None
            if role == "master":
                try:
                    # connect(): the kernel now drops datagrams not from the slave, and
                    # send() needs no address.
                    self._sock.connect((remote_host, remote_port))
                except OSError as exc:
                    raise TransportError(
                        f"udp: cannot reach {remote_host}:{remote_port}: {exc.strerror or exc}"
                    ) from None
        except BaseException:
            self._sock.close()
            raise
        self._peer: tuple[str, int] | None = (
            (remote_host, remote_port) if role == "master" and remote_host is not None else None
        )
        self._timeout: float | None | str = "unset"  # the socket's current timeout

    @property
    def address(self) -> tuple[str, int]:
        """The local (host, port) this end is bound to."""
        host, port = self._sock.getsockname()[:2]
        return host, port

    @property
    def port(self) -> int:
        """The local UDP port (useful after ``port=0``)."""
        return self.address[1]

    @property
    def peer(self) -> tuple[str, int] | None:
        """Where frames are sent: the slave for a master; for a slave, the sender of the
        last frame received (None before the first)."""
        return self._peer

    def _send(self, frame: bytes) -> None:
        try:
            if self.role == "master":
                self._sock.send(frame)
            else:
                if self._peer is None:
                    raise TransportError("udp: the slave has not heard from a master yet, so "
                                         "it has no address to reply to")
                self._sock.sendto(frame, self._peer)
        except ConnectionRefusedError:
            # An ICMP "port unreachable" from an earlier datagram (no slave listening yet)
            # is reported on the next call; the datagram itself is lost, as UDP may.
            pass
        except OSError as exc:
            raise TransportError(f"udp: send failed: {exc.strerror or exc}") from None

    def _set_timeout(self, timeout: float | None) -> None:
        if timeout != self._timeout:
            self._sock.settimeout(timeout)
            self._timeout = timeout

    def _recv(self, timeout: float | None) -> bytes | None:
        deadline = deadline_of(timeout)
        bufsize = self.max_frame + 1  # one byte more tells an oversize datagram
        while True:
            self._set_timeout(remaining(deadline))
            try:
                data, sender = self._sock.recvfrom(bufsize)
            except (TimeoutError, BlockingIOError):
                return None
            except ConnectionRefusedError:
                # ICMP from a send to a slave that is not (yet) listening; keep waiting.
                if deadline is not None and remaining(deadline) == 0.0:
                    return None
                continue
            except OSError as exc:
                raise TransportError(f"udp: receive failed: {exc.strerror or exc}") from None
            if len(data) > self.max_frame:
                self.stats.oversize += 1
            elif not data:
                self.stats.framing_errors += 1  # an empty datagram is no frame
            else:
                if self.role == "slave":
                    self._peer = sender
                return data
            if deadline is not None and remaining(deadline) == 0.0:
                return None

    def _close(self) -> None:
        self._sock.close()

    @classmethod
    def listen(cls, address: str, host: str = "127.0.0.1", **options: Any) -> Listening:
        """A slave on port ``address`` (``"0"``: any free port) of ``host``."""
        try:
            port = int(address)
        except (TypeError, ValueError):
            raise TransportError(f"port {address!r}: udp needs a port number "
                                 "(0: any free port)") from None
        if not 0 <= port <= 65535:
            raise TransportError(f"port {port}: must be 0..65535")
        end = cls("slave", host=host, port=port, **options)
        h, p = end.address[0], end.address[1]
        return Listening(end, str(p), f"udp {h}:{p}")

    def capture_endpoints(self) -> tuple[tuple[str, int], tuple[str, int]] | None:
        peer = self._peer
        if peer is None:
            return None
        return self.address, (peer[0], peer[1])

    @classmethod
    def private_options(cls) -> dict[str, Any]:
        """A free port for the chain instead of 34980, which another run may hold."""
        return {"port": 0}

    @classmethod
    def remote_master(cls, port: int = ETHERCAT_UDP_PORT, **options: Any) -> RemotePeer:
        """The child listens on ``port`` (default 34980, EtherCAT's, so that a capture
        decodes as EtherCAT without options; 0: any free port) and reports it; the master
        sends there from an ephemeral port."""
        _check_port(port, "port")
        return RemotePeer(str(port), lambda address: cls("master", remote_port=int(address),
                                                         **options))

    @classmethod
    def _pair(cls, host: str = "127.0.0.1",
              max_frame: int = DEFAULT_MAX_FRAME) -> tuple[Transport, Transport]:
        """A slave on a free port of ``host`` and a master sending to it."""
        slave = cls("slave", host=host, port=0, max_frame=max_frame)
        try:
            master = cls("master", host=host, remote_port=slave.port, max_frame=max_frame)
        except BaseException:
            slave.close()
            raise
        return master, slave
