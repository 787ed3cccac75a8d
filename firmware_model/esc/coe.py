"""The box's mailbox application: the mailbox header (ETG.1000.4), CoE's SDO server
(ETG.1000.6: upload and download, expedited, normal and segmented, complete access) over a
:class:`~firmware_model.esc.objects.Dictionary`, and emergencies.

It runs on the box's side (the MCU's program, on the box's clock), never in the frame path:
:meth:`CoeServer.receive` takes one request as the ESC's SM0 held it, :meth:`outgoing` gives
the next message for SM1 (answers and emergencies in the order they arose).

Mailbox header (6 bytes): length of the data after it (u16), address (u16), channel (bits
0..5) and priority (6..7), type (bits 0..3: 0 error, 3 CoE) and counter (4..6). A request
whose counter (1..7) equals the previous one is a repeat the master sent again and is not
served twice. A header that does not hold is answered with a mailbox error (type 0:
service 1, detail code), counted. CoE header (u16): number (bits 0..8), service (12..15: 1
emergency, 2 SDO request, 3 SDO response). Every request, answer, abort (per code), mailbox
error (per code) and emergency is counted in :attr:`CoeServer.stats`.
"""

from __future__ import annotations

import struct
from collections import Counter, deque
from collections.abc import Callable

from firmware_model.esc.objects import Abort, Dictionary, SdoAbort

MBX_HEADER = 6
TYPE_ERROR, TYPE_COE = 0x00, 0x03
COE_EMERGENCY, COE_SDO_REQUEST, COE_SDO_RESPONSE = 1, 2, 3


class MailboxError:
    """Mailbox error detail codes (ETG.1000.4, mailbox type 0)."""

    SYNTAX = 0x01
    UNSUPPORTED_PROTOCOL = 0x02
    INVALID_CHANNEL = 0x03
    SERVICE_NOT_SUPPORTED = 0x04
    INVALID_HEADER = 0x05
    SIZE_TOO_SHORT = 0x06
    NO_MEMORY = 0x07
    INVALID_SIZE = 0x08


#: Emergency error codes (CiA 301 classes; the first data byte names the actuator slot).
EMCY_MCU_WATCHDOG = 0x8130     # monitoring, communication: no fresh command (life guard)
EMCY_LINK = 0x7500             # additional modules, communication: the LVDS link failed
EMCY_DRIVER_TRIP = 0x5400      # device hardware, power section: the driver board tripped
#: Error register bits (0x1001): generic, current, voltage, temperature, communication.
ERR_GENERIC, ERR_COMMUNICATION = 0x01, 0x10
EMERGENCY_QUEUE = 8


def mailbox(kind: int, data: bytes, counter: int) -> bytes:
    return struct.pack("<HHBB", len(data), 0, 0, kind | (counter & 7) << 4) + data


class CoeServer:
    """The SDO server and emergency sender of one slave. ``state()``: its AL state now;
    ``size``: the mailbox (SM0 / SM1) size in bytes."""

    def __init__(self, od: Dictionary, size: int, state: Callable[[], int]) -> None:
        self.od = od
        self.size = size
        self.state = state
        self.stats: Counter[str] = Counter()
        self._out: deque[bytes] = deque()
        self._emcy: deque[bytes] = deque()
        self._last_counter = 0
        self._counter = 0
        # Segmented transfer in progress: ("up" | "down", index, sub, complete access, data,
        # expected size, next toggle).
        self._seg: tuple | None = None

    def reset(self) -> None:
        """The mailbox went off (INIT): no counter to repeat, no transfer under way, nothing
        waiting for a master that is gone (emergencies stay queued)."""
        self._last_counter = 0
        self._seg = None
        self._out.clear()

    # --- messages out --------------------------------------------------------------------
    def _send(self, kind: int, data: bytes) -> None:
        self._counter = self._counter % 7 + 1   # 1..7, never 0
        self._out.append(mailbox(kind, data, self._counter))

    def outgoing(self) -> bytes | None:
        """The next message for SM1 (answers first), or None; :meth:`sent` once it went in."""
        if self._out:
            return self._out[0]
        return self._emcy[0] if self._emcy else None

    def sent(self) -> None:
        (self._out if self._out else self._emcy).popleft()

    def emergency(self, code: int, register: int, data: bytes = b"") -> None:
        """Queue an emergency (error code, error register, up to 5 bytes of data); the oldest
        is dropped (counted) if the master does not read them."""
        self._counter = self._counter % 7 + 1
        msg = mailbox(TYPE_COE, struct.pack("<HHB", COE_EMERGENCY << 12, code, register)
                      + data[:5].ljust(5, b"\0"), self._counter)
        if len(self._emcy) >= EMERGENCY_QUEUE:
            self._emcy.popleft()
            self.stats["emergencies_dropped"] += 1
        self._emcy.append(msg)
        self.stats["emergencies"] += 1

    def _mbx_error(self, detail: int) -> None:
        self.stats[f"mailbox_error_{detail:#04x}"] += 1
        self._send(TYPE_ERROR, struct.pack("<HH", 0x0001, detail))

    def _abort(self, index: int, sub: int, code: Abort) -> None:
        self._seg = None
        self.stats[f"abort_{int(code):#010x}"] += 1
        # An abort is an "Abort SDO Transfer Request": CoE service 2, from either side.
        self._send(TYPE_COE, struct.pack("<HBHBI", COE_SDO_REQUEST << 12, 0x80, index, sub,
                                         int(code)))

    def _respond(self, body: bytes) -> None:
        self.stats["sdo_responses"] += 1
        self._send(TYPE_COE, struct.pack("<H", COE_SDO_RESPONSE << 12) + body)

    # --- requests in ---------------------------------------------------------------------
    def receive(self, raw: bytes) -> None:
        """One request as SM0 held it (the whole buffer; the header says how much counts)."""
        self.stats["mailbox_requests"] += 1
        if len(raw) < MBX_HEADER:
            return self._mbx_error(MailboxError.SIZE_TOO_SHORT)
        length, _address, channel, type_counter = struct.unpack_from("<HHBB", raw)
        kind, counter = type_counter & 0x0F, type_counter >> 4 & 7
        if length > len(raw) - MBX_HEADER:
            return self._mbx_error(MailboxError.INVALID_SIZE)
        if counter and counter == self._last_counter:
            self.stats["mailbox_repeats_ignored"] += 1
            return None
        self._last_counter = counter
        if channel & 0x3F:
            return self._mbx_error(MailboxError.INVALID_CHANNEL)
        if kind != TYPE_COE:
            return self._mbx_error(MailboxError.UNSUPPORTED_PROTOCOL)
        if length < 2:
            return self._mbx_error(MailboxError.SIZE_TOO_SHORT)
        body = raw[MBX_HEADER:MBX_HEADER + length]
        service = struct.unpack_from("<H", body)[0] >> 12
        if service != COE_SDO_REQUEST:
            return self._mbx_error(MailboxError.SERVICE_NOT_SUPPORTED)
        if length < 10:
            return self._mbx_error(MailboxError.SIZE_TOO_SHORT)
        self.stats["sdo_requests"] += 1
        where = self._where(body[2:])
        try:
            self._sdo(body[2:])
        except SdoAbort as exc:
            self._abort(*where, exc.code)
        except Exception:  # a box model's failure is the slave's general error, never a crash
            self._abort(*where, Abort.GENERAL)
        return None

    def _where(self, sdo: bytes) -> tuple[int, int]:
        """(index, subindex) an abort of this request names."""
        if sdo[0] >> 5 in (1, 2):
            return struct.unpack_from("<HB", sdo, 1)
        return (self._seg[1], self._seg[2]) if self._seg is not None else (0, 0)

    def _sdo(self, sdo: bytes) -> None:
        cmd = sdo[0]
        ccs = cmd >> 5
        if ccs == 1:
            return self._download_initiate(sdo)
        if ccs == 0:
            return self._download_segment(sdo)
        if ccs == 2:
            return self._upload_initiate(sdo)
        if ccs == 3:
            return self._upload_segment(sdo)
        if ccs == 4:  # the master aborts a transfer: no answer
            self._seg = None
            self.stats["sdo_aborted_by_master"] += 1
            return None
        raise SdoAbort(Abort.COMMAND)

    # --- upload (slave -> master) ----------------------------------------------------------
    def _upload_initiate(self, sdo: bytes) -> None:
        cmd = sdo[0]
        index, sub = struct.unpack_from("<HB", sdo, 1)
        self._seg = None
        ca = bool(cmd & 0x10)
        data = self.od.read_complete(index, sub) if ca else self.od.read(index, sub)
        head = struct.pack("<HB", index, sub)
        if len(data) <= 4 and not ca:
            n = 4 - len(data)
            return self._respond(bytes([0x43 | n << 2]) + head + data.ljust(4, b"\0"))
        room = self.size - MBX_HEADER - 10
        first, rest = data[:room], data[room:]
        self._respond(bytes([0x41 | (cmd & 0x10)]) + head + struct.pack("<I", len(data)) + first)
        if rest:
            self._seg = ("up", index, sub, ca, rest, len(data), 0)
        return None

    def _upload_segment(self, sdo: bytes) -> None:
        toggle = sdo[0] >> 4 & 1
        if self._seg is None or self._seg[0] != "up":
            raise SdoAbort(Abort.COMMAND)
        kind, index, sub, ca, rest, total, want = self._seg
        if toggle != want:
            raise SdoAbort(Abort.TOGGLE)
        room = self.size - MBX_HEADER - 3
        chunk, rest = rest[:room], rest[room:]
        last = not rest
        n = 7 - len(chunk) if len(chunk) < 7 else 0
        self._respond(bytes([toggle << 4 | n << 1 | int(last)]) + chunk.ljust(7, b"\0"))
        self._seg = None if last else (kind, index, sub, ca, rest, total, want ^ 1)

    # --- download (master -> slave) --------------------------------------------------------
    def _download_initiate(self, sdo: bytes) -> None:
        cmd = sdo[0]
        index, sub = struct.unpack_from("<HB", sdo, 1)
        self._seg = None
        ca = bool(cmd & 0x10)
        if cmd & 0x02:  # expedited: the data in the 4 bytes, n of them unused if s
            data = sdo[4:8][:4 - (cmd >> 2 & 3)] if cmd & 0x01 else sdo[4:8]
            return self._store(index, sub, ca, data)
        if not cmd & 0x01:
            raise SdoAbort(Abort.COMMAND)  # normal transfer without its size
        total = struct.unpack_from("<I", sdo, 4)[0]
        data = sdo[8:]
        if len(data) > total:
            raise SdoAbort(Abort.LENGTH_MISMATCH)
        if total > 0xFFFF:
            raise SdoAbort(Abort.LENGTH_HIGH)
        if len(data) == total:
            return self._store(index, sub, ca, data)
        self._seg = ("down", index, sub, ca, data, total, 0)
        self._respond(struct.pack("<BHBI", 0x60, index, sub, 0))
        return None

    def _download_segment(self, sdo: bytes) -> None:
        cmd = sdo[0]
        if self._seg is None or self._seg[0] != "down":
            raise SdoAbort(Abort.COMMAND)
        kind, index, sub, ca, got, total, want = self._seg
        toggle = cmd >> 4 & 1
        if toggle != want:
            raise SdoAbort(Abort.TOGGLE)
        chunk = sdo[1:]
        if len(chunk) == 7:
            chunk = chunk[:7 - (cmd >> 1 & 7)]
        got += chunk
        if len(got) > total:
            raise SdoAbort(Abort.LENGTH_HIGH)   # an oversize segment: more than announced
        last = bool(cmd & 1)
        if last:
            if len(got) != total:
                raise SdoAbort(Abort.LENGTH_LOW)
            self._seg = (kind, index, sub, ca, got, total, want)
            self.od.write_complete(index, sub, got, self.state()) if ca else self.od.write(
                index, sub, got, self.state())
            self._seg = None
        else:
            self._seg = (kind, index, sub, ca, got, total, want ^ 1)
        self._respond(bytes([0x20 | toggle << 4]) + bytes(7))

    def _store(self, index: int, sub: int, ca: bool, data: bytes) -> None:
        if ca:
            self.od.write_complete(index, sub, data, self.state())
        else:
            self.od.write(index, sub, data, self.state())
        self._respond(struct.pack("<BHBI", 0x60, index, sub, 0))
