"""CAN transport: a frame cut into CAN-FD (64-byte) or classic CAN (8-byte) segments.

A CAN frame carries at most 64 data bytes (CAN FD) or 8 (classic), so a ~1.6 kB EtherCAT
frame travels as a *message* of many segments. Each segment starts with a 2-byte header,
and the message ends with a CRC-32, so a message with a lost, duplicated or reordered
segment is dropped and counted, never delivered in part or in the wrong order::

    message  = length (u16 LE) | frame | CRC-32(length | frame) (u32 LE) | zero padding
    segment  = header (u16 LE) | next 62 (FD) or 6 (classic) message bytes
    header   = bits 0..9  segment index (0 = first)
               bits 10..14 message sequence number (mod 32)
               bit 15      LAST (this segment ends the message)

The padding fills the last CAN-FD segment up to a valid CAN-FD length (12, 16, 20, 24,
32, 48 or 64); the length field says where the frame ends. CAN's own 15/17/21-bit CRC
protects each segment on the bus; the CRC-32 protects the reassembly.

The master sends on CAN ID ``base_id``, the slave on ``base_id + 1`` (default 0x100 and
0x101); each end accepts only its peer's ID. Works on any python-can interface:
``virtual`` (default; in-process, for tests), ``socketcan`` (Linux: ``vcan0`` or a real
controller such as ``can0``), and others through ``bus_options``.
"""

from __future__ import annotations

import itertools
import uuid
from typing import Any

import can

from hil.transports.base import (
    DEFAULT_MAX_FRAME,
    Listening,
    Transport,
    TransportError,
    TransportStats,
    deadline_of,
    remaining,
)
from hil.transports.framing import crc32

HEADER_BYTES = 2
LENGTH_BYTES = 2
CRC_BYTES = 4
INDEX_BITS = 10
SEQ_BITS = 5
MAX_SEGMENTS = 1 << INDEX_BITS
SEQ_MOD = 1 << SEQ_BITS
_INDEX_MASK = MAX_SEGMENTS - 1
_SEQ_SHIFT = INDEX_BITS
_LAST = 1 << 15

#: CAN-FD data lengths (DLC 0..15 -> bytes); a frame's data must have one of these sizes.
FD_LENGTHS: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)

#: Default CAN ID of the master's segments; the slave's are this + 1. Standard 11-bit IDs,
#: low enough to win arbitration over slow housekeeping traffic.
DEFAULT_BASE_ID = 0x100

#: Default virtual channel of the ``virtual`` interface, and socketcan's default device.
DEFAULT_CHANNELS = {"virtual": "eha-hil", "socketcan": "vcan0"}


def segment_payload(fd: bool) -> int:
    """Message bytes per segment: the CAN data size minus the 2-byte header."""
    return (64 if fd else 8) - HEADER_BYTES


def max_message_frame(fd: bool) -> int:
    """Largest frame [bytes] that fits the 10-bit segment index."""
    return MAX_SEGMENTS * segment_payload(fd) - LENGTH_BYTES - CRC_BYTES


def _padded(size: int) -> int:
    """Smallest valid CAN-FD data length >= size."""
    for length in FD_LENGTHS:
        if length >= size:
            return length
    raise ValueError(f"{size} bytes do not fit a CAN-FD frame")


def segment(frame: bytes, seq: int, fd: bool = True) -> list[bytes]:
    """The data fields of the CAN frames carrying ``frame`` as message number ``seq``.

    Pure function (no bus), used by :class:`CanTransport` and by the tests.
    """
    body = len(frame).to_bytes(LENGTH_BYTES, "little") + frame
    body += crc32(body).to_bytes(CRC_BYTES, "little")
    per = segment_payload(fd)
    count = -(-len(body) // per)
    if count > MAX_SEGMENTS:
        raise ValueError(f"frame of {len(frame)} bytes needs {count} segments (max "
                         f"{MAX_SEGMENTS})")
    seq_bits = (seq % SEQ_MOD) << _SEQ_SHIFT
    out = []
    for index in range(count):
        header = seq_bits | index | (_LAST if index == count - 1 else 0)
        data = header.to_bytes(HEADER_BYTES, "little") + body[index * per:(index + 1) * per]
        if fd and len(data) not in FD_LENGTHS:
            data += bytes(_padded(len(data)) - len(data))
        out.append(data)
    return out


class Reassembler:
    """Rebuild messages from segment data fields; drop any message that is not whole.

    A message is delivered only when its segments 0..n arrive consecutively, in order,
    with one sequence number, ending with the LAST flag, and its length and CRC-32 check.
    Anything else abandons the message in progress: a segment out of place counts one
    ``framing_error`` per broken message (the other segments of a message already known to
    be broken are dropped silently), a CRC mismatch one ``crc_error``, a length beyond
    ``max_frame`` one ``oversize``. A message broken by the loss of its last segments is
    counted when the next message starts.

    A completed message with the same sequence number as the one delivered just before is
    a repeat (e.g. a one-segment message seen twice) and is dropped as a framing error; so,
    after exactly 32*k lost messages in a row, one good message would be dropped too.
    Whole messages are delivered in the order they complete: on one CAN bus the frames of
    one ID never overtake each other, so only a gateway that reorders whole messages could
    make an older frame arrive after a newer one (the EtherCAT datagram index catches it).
    """

    def __init__(self, fd: bool = True, max_frame: int = DEFAULT_MAX_FRAME,
                 stats: TransportStats | None = None) -> None:
        self.fd = fd
        self.max_frame = max_frame
        self.stats = stats if stats is not None else TransportStats()
        per = segment_payload(fd)
        self._max_index = min(MAX_SEGMENTS, -(-(max_frame + LENGTH_BYTES + CRC_BYTES) // per)) - 1
        self._parts: list[bytes] = []
        self._seq = -1  # sequence number of the message in progress
        self._dead_seq = -1  # sequence number of the last broken message (not recounted)
        self._last_delivered = -1

    def _abandon(self) -> None:
        if self._parts:
            self.stats.framing_errors += 1
            self._dead_seq = self._seq
            self._parts = []

    def feed(self, data: bytes | bytearray) -> bytes | None:
        """Add one segment's data field; return a frame when it completes one."""
        if len(data) < HEADER_BYTES:
            self._abandon()
            self.stats.framing_errors += 1
            return None
        header = data[0] | (data[1] << 8)
        index = header & _INDEX_MASK
        seq = (header >> _SEQ_SHIFT) & (SEQ_MOD - 1)
        if index > self._max_index:
            # Longer than any message we accept: drop it all, one count per message.
            if self._parts and seq == self._seq:
                self._parts = []
            elif seq == self._dead_seq:
                return None
            else:
                self._abandon()
            self._dead_seq = seq
            self.stats.oversize += 1
            return None
        if index == 0:
            self._abandon()
            self._parts = [data[HEADER_BYTES:]]
            self._seq = seq
            self._dead_seq = -1
        elif self._parts and seq == self._seq and index == len(self._parts):
            self._parts.append(data[HEADER_BYTES:])
        else:
            # Out of place: the message in progress is broken (counted by _abandon, which
            # marks its sequence number dead); a segment of a message whose start we never
            # saw is counted once per message.
            self._abandon()
            if seq != self._dead_seq:
                self.stats.framing_errors += 1
                self._dead_seq = seq
            return None
        if not header & _LAST:
            return None
        body = b"".join(self._parts)
        self._parts = []
        return self._check(body, seq)

    def _check(self, body: bytes, seq: int) -> bytes | None:
        size = int.from_bytes(body[:LENGTH_BYTES], "little") if len(body) >= 2 else -1
        end = LENGTH_BYTES + size
        if size < 1 or end + CRC_BYTES > len(body):
            self.stats.framing_errors += 1
            return None
        if crc32(body[:end]) != int.from_bytes(body[end:end + CRC_BYTES], "little"):
            self.stats.crc_errors += 1
            return None
        if size > self.max_frame:
            self.stats.oversize += 1
            return None
        if seq == self._last_delivered:
            self.stats.framing_errors += 1
            return None
        self._last_delivered = seq
        return body[LENGTH_BYTES:end]


class CanTransport(Transport):
    """One end of a segmented CAN link.

    Options:
        interface: python-can interface name (default ``"virtual"``; ``"socketcan"`` on
            Linux with a real or ``vcan`` device).
        channel: bus channel (default ``"eha-hil"`` for virtual, ``"vcan0"`` for
            socketcan; required for other interfaces).
        fd: True (default) for CAN-FD, 64-byte segments; False for classic CAN, 8 bytes.
        base_id: CAN ID of master->slave segments; slave->master use ``base_id + 1``
            (default 0x100).
        extended: use 29-bit IDs (default False: 11-bit).
        bus: an open ``can.BusABC`` to use instead of opening one (left open on close).
        bus_options: extra keyword arguments for ``can.Bus`` (e.g. bitrate for a USB
            adapter).
        send_timeout: seconds one segment may wait for room in the transmit queue
            (default 1.0).
        max_frame: largest frame [bytes] (default 4096; at most 63 482 FD / 6 138
            classic, what the 10-bit segment index can number).
    """

    name = "can"

    def __init__(
        self,
        role: str,
        interface: str = "virtual",
        channel: str | int | None = None,
        fd: bool = True,
        base_id: int = DEFAULT_BASE_ID,
        extended: bool = False,
        bus: can.BusABC | None = None,
        bus_options: dict[str, Any] | None = None,
        send_timeout: float = 1.0,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        super().__init__(role, max_frame)
        if not isinstance(fd, bool):
            raise TransportError(f"can: fd must be True or False, got {fd!r}")
        if not isinstance(extended, bool):
            raise TransportError(f"can: extended must be True or False, got {extended!r}")
        top = (1 << 29) - 1 if extended else (1 << 11) - 1
        if isinstance(base_id, bool) or not isinstance(base_id, int) or not 0 <= base_id < top:
            raise TransportError(
                f"can: base_id must be an integer 0..{top - 1:#x} ({'29' if extended else '11'}"
                f"-bit IDs, the slave uses base_id + 1), got {base_id!r}"
            )
        if max_frame > max_message_frame(fd):
            raise TransportError(f"can: max_frame must be at most {max_message_frame(fd)} "
                                 f"with fd={fd}, got {max_frame}")
        if not isinstance(send_timeout, int | float) or not send_timeout > 0:
            raise TransportError(f"can: send_timeout must be seconds > 0, got {send_timeout!r}")
        if bus_options is not None and not isinstance(bus_options, dict):
            raise TransportError(f"can: bus_options must be a dict, got {bus_options!r}")
        self.fd = fd
        self.extended = extended
        self.base_id = base_id
        self.interface: str | None = None if bus is not None else interface
        self.channel = channel
        self._bus_options = bus_options
        self.tx_id = base_id if role == "master" else base_id + 1
        self.rx_id = base_id + 1 if role == "master" else base_id
        self.send_timeout = float(send_timeout)
        if bus is not None:
            if not isinstance(bus, can.BusABC):
                raise TransportError(f"can: bus must be a can.BusABC, got {type(bus).__name__}")
            self.bus = bus
            self._owns_bus = False
        else:
            if channel is None:
                if interface not in DEFAULT_CHANNELS:
                    raise TransportError(f"can: interface {interface!r} needs channel=")
                channel = DEFAULT_CHANNELS[interface]
                self.channel = channel
            try:
                self.bus = can.Bus(interface=interface, channel=channel, fd=fd,
                                   **(bus_options or {}))
            except (can.CanError, ImportError, OSError, ValueError, TypeError) as exc:
                raise TransportError(
                    f"can: cannot open {interface} channel {channel!r}: {_one_line(exc)}"
                ) from None
            self._owns_bus = True
        mask = (1 << 29) - 1 if extended else (1 << 11) - 1
        try:
            # Hardware/kernel filtering where the interface has it; python-can filters in
            # software otherwise. _recv checks the ID again regardless.
            self.bus.set_filters([{"can_id": self.rx_id, "can_mask": mask,
                                   "extended": extended}])
        except (can.CanError, NotImplementedError):
            pass
        self._seq = itertools.count()
        self._reassembler = Reassembler(fd, max_frame, self.stats)

    def _send(self, frame: bytes) -> None:
        seq = next(self._seq) % SEQ_MOD
        for data in segment(frame, seq, self.fd):
            msg = can.Message(arbitration_id=self.tx_id, is_extended_id=self.extended,
                              data=data, is_fd=self.fd, bitrate_switch=self.fd, check=False)
            try:
                self.bus.send(msg, timeout=self.send_timeout)
            except can.CanError as exc:
                raise TransportError(f"can: send failed: {_one_line(exc)}") from None

    def _recv(self, timeout: float | None) -> bytes | None:
        deadline = deadline_of(timeout)
        feed = self._reassembler.feed
        while True:
            try:
                msg = self.bus.recv(remaining(deadline))
            except can.CanError as exc:
                raise TransportError(f"can: receive failed: {_one_line(exc)}") from None
            if msg is None:
                return None
            if (msg.arbitration_id != self.rx_id or msg.is_error_frame or msg.is_remote_frame
                    or msg.is_extended_id != self.extended):
                continue
            frame = feed(msg.data)
            if frame is not None:
                return frame
            if deadline is not None and remaining(deadline) == 0.0:
                return None

    def record_to(self, path: str) -> Any:
        """A :class:`~hil.transports.canlog.CanLogRecorder` on this end's channel: every
        segment on the bus, both directions, to a BLF / ASC / candump file."""
        from hil.transports.canlog import CanLogRecorder

        if self.interface is None:
            raise TransportError("can: a log needs the interface and channel (this end was "
                                 "given an open bus)")
        return CanLogRecorder(path, self.interface, self.channel, self.fd, self._bus_options)

    def _close(self) -> None:
        if self._owns_bus:
            self.bus.shutdown()

    @classmethod
    def listen(cls, address: str, **options: Any) -> Listening:
        """A slave on CAN channel ``address``."""
        end = cls("slave", channel=address, **options)
        return Listening(end, address, f"can {address}")

    @classmethod
    def _pair(cls, interface: str = "virtual", channel: str | int | None = None,
              fd: bool = True, base_id: int = DEFAULT_BASE_ID, extended: bool = False,
              bus_options: dict[str, Any] | None = None,
              max_frame: int = DEFAULT_MAX_FRAME) -> tuple[Transport, Transport]:
        """Two ends on one bus; on ``virtual`` a fresh private channel unless given."""
        if channel is None and interface == "virtual":
            channel = f"eha-hil-{uuid.uuid4().hex[:12]}"
        kw: dict[str, Any] = dict(interface=interface, channel=channel, fd=fd, base_id=base_id,
                                  extended=extended, bus_options=bus_options,
                                  max_frame=max_frame)
        master = cls("master", **kw)
        try:
            slave = cls("slave", **kw)
        except BaseException:
            master.close()
            raise
        return master, slave


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
