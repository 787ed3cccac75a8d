"""One EtherCAT slave controller: register space, datagram processing, AL state machine,
FMMUs, sync managers, SII EEPROM interface and process-data watchdog.

The chain (:mod:`hil.fieldbus.esc.chain`) hands every datagram of a frame to the slaves in
line order (:meth:`Esc.process`); each slave updates the datagram in place as the frame
passes, as an ESC does on the fly:

* position addressing (APxx, ARMW): the slave whose arriving ADP is 0 is addressed; every
  slave increments ADP. Broadcast (Bxx): every slave, ADP incremented. Configured (FPxx,
  FRMW): ADP equals the station address (0x0010) or, with DL control bit 24 set, the alias;
* working counter: read +1, write +1, read-write +3 (read 1 + write 2); BRD/BRW OR the
  read data into the frame; ARMW/FRMW: the addressed slave reads (+1), every other one
  writes (+1); LRD/LWR/LRW through the active FMMUs: +1 if any read FMMU hit, +2 (LRW) or
  +1 (LWR) if any write FMMU hit. A logical access into a sync-manager area counts only if
  that sync manager is enabled, points the right way and the slave is in SAFEOP or OP.

The application side (the PDI: the MCU board behind the ESC) is :meth:`set_inputs`,
:meth:`pending_outputs` and :meth:`tick` (time for the watchdog). Outputs reach the box only
in OP; leaving OP, or the watchdog expiring, hands the box its safe outputs (all zero:
mode off, drives disabled). Time is what :meth:`tick` is given (the box's 1 ms cycles).

Mailbox (a description with ``coe``): SM0 and SM1 in 1-buffer mode. A master's write that
completes SM0's buffer sets its full bit and hands the buffer to the application
(:meth:`take_mailbox`); further writes are refused (working counter not incremented) until
the application has taken it. The application's answer (:meth:`post_mailbox`) enters SM1's
buffer when that is empty; the master's read of its last byte empties it; reading an empty
one is refused. A toggled repeat request (SM1 activate bit 1) offers the last answer again
and is acknowledged in SM1's PDI control bit 1. The application's side of these (the PDI)
runs when the next datagram reaches the slave, as the compiled path does it.
"""

from __future__ import annotations

import struct

from firmware_model.esc import registers as r
from firmware_model.esc.dc import DcParams, DcUnit
from firmware_model.esc.registers import AL_ERROR, AlState, AlStatusCode
from firmware_model.esc.sii import SlaveDescription
from protocols.ethercat import Command

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_FMMU = struct.Struct("<IHBBHBBB3x")   # logical start, length, start/end bit, physical, bit,
#                                        type, activate

_AUTO = frozenset({Command.APRD, Command.APWR, Command.APRW, Command.ARMW})
_FIXED = frozenset({Command.FPRD, Command.FPWR, Command.FPRW, Command.FRMW})
_BCAST = frozenset({Command.BRD, Command.BWR, Command.BRW})
_READS = frozenset({Command.APRD, Command.FPRD, Command.BRD})
_WRITES = frozenset({Command.APWR, Command.FPWR, Command.BWR})
_RWS = frozenset({Command.APRW, Command.FPRW, Command.BRW})

_ALLOWED = {
    (AlState.INIT, AlState.PREOP), (AlState.PREOP, AlState.SAFEOP),
    (AlState.SAFEOP, AlState.OP), (AlState.OP, AlState.SAFEOP),
    (AlState.OP, AlState.PREOP), (AlState.SAFEOP, AlState.PREOP),
}

#: ESC type code of this model (0x0000); not a vendor's silicon.
ESC_TYPE = 0xE5


def _writable_mask() -> bytearray:
    m = bytearray(r.MEMORY_SIZE)

    def allow(lo: int, hi: int) -> None:
        m[lo:hi] = b"\x01" * (hi - lo)

    allow(r.STATION_ADDRESS, r.STATION_ADDRESS + 4)
    allow(r.DL_CONTROL, r.DL_CONTROL + 4)
    allow(r.AL_CONTROL, r.AL_CONTROL + 2)
    allow(r.IRQ_MASK, r.IRQ_MASK + 4)
    allow(r.WD_DIVIDER, r.WD_DIVIDER + 2)
    allow(r.WD_TIME_PDI, r.WD_TIME_PDI + 2)
    allow(r.WD_TIME_PD, r.WD_TIME_PD + 2)
    allow(r.EEP_CONFIG, r.EEP_CONFIG + 1)
    allow(r.EEP_CONTROL, r.EEP_END)
    allow(r.FMMU0, r.FMMU0 + r.N_FMMU * r.FMMU_SIZE)
    for k in range(r.N_SM):
        base = r.SM0 + k * r.SM_SIZE
        allow(base, base + 5)
        allow(base + 6, base + 7)       # status (5) and PDI control (7) are the PDI's
    # distributed clocks: the registers the master sets as written; 0x0900 (latch), 0x0910
    # (compare), 0x0981, 0x0990 and 0x09A0 (checked first) go through the DC unit
    allow(r.DC_SYSTEM_OFFSET, r.DC_SYSTEM_DELAY + 4)
    allow(r.DC_SPEED_START, r.DC_SPEED_START + 2)
    allow(r.DC_DIFF_FILTER, r.DC_SPEED_FILTER + 1)
    allow(r.DC_CYCLIC_CONTROL, r.DC_CYCLIC_CONTROL + 1)
    allow(r.DC_SYNC1_CYCLE, r.DC_SYNC1_CYCLE + 4)
    allow(r.RAM_START, r.MEMORY_SIZE)
    return m


_WRITABLE = bytes(_writable_mask())


class Esc:
    """One slave's ESC with its SII image; ``last`` if it closes the line (port 1 open)."""

    def __init__(self, desc: SlaveDescription, image: bytes, last: bool = False,
                 dc: DcParams | None = None) -> None:
        self.desc = desc
        self.sii = image
        self.mem = bytearray(r.MEMORY_SIZE)
        self._fmmu_cache: list | None = None
        self._sm_cache: list | None = None
        m = self.mem
        m[r.TYPE] = ESC_TYPE
        m[r.REVISION] = 1
        _U16.pack_into(m, r.BUILD, 1)
        m[r.FMMUS_SUPPORTED] = r.N_FMMU
        m[r.SMS_SUPPORTED] = r.N_SM
        m[r.RAM_SIZE] = (r.MEMORY_SIZE - r.RAM_START) // 1024
        m[r.PORT_DESCRIPTOR] = 0x0F            # ports 0 and 1 MII, 2 and 3 not implemented
        _U16.pack_into(m, r.FEATURES, r.FEATURE_DC | r.FEATURE_DC64)
        self.dc = DcUnit(dc)
        self.dc.reset(m)
        _U16.pack_into(m, r.STATION_ALIAS, desc.alias)
        m[r.PDI_CONTROL] = desc.pdi_control
        # DL status: PDI operational (SII loaded), PDI watchdog fine, port 0 link +
        # communication; port 1 the same unless last in line (then its loop is closed);
        # ports 2 and 3 not implemented (loop closed, no communication).
        dl = 0x0001 | 0x0002 | 0x0010 | 0x0200 | 0x1000 | 0x4000
        dl |= 0x0400 if last else (0x0020 | 0x0800)
        _U16.pack_into(m, r.DL_STATUS, dl)
        _U16.pack_into(m, r.WD_DIVIDER, 2498)   # 100 us per watchdog increment
        _U16.pack_into(m, r.WD_TIME_PDI, 1000)
        _U16.pack_into(m, r.WD_TIME_PD, 1000)   # 100 ms
        _U16.pack_into(m, r.EEP_CONTROL, r.EEP_STAT_READ8)
        self.state = AlState.INIT
        self.error = False
        self.code = AlStatusCode.NO_ERROR
        self._set_al_status()
        #: Simulated time [ns] (from :meth:`tick`) and the last output-buffer write.
        self.now_ns = 0
        self.last_output_ns = 0
        #: Watchdog expirations and, of the last, ns from the last output write to the trip
        #: and to the tick that applied it.
        self.watchdog_trips = 0
        self.last_trip_delay_ns = 0
        self.last_trip_seen_ns = 0
        self._pending: bytes | None = None
        #: Process-data lengths the application expects (the SII's, or as CoE remapped).
        self.out_bytes, self.in_bytes = desc.out_bytes, desc.in_bytes
        #: Mailbox hand-over: 0 idle, 1 a request for the application, 2 taken by it.
        self.mbx_rx_state = 0
        self._mbx_rx = b""
        self._mbx_tx: bytes | None = None

    # --- the frame side ---------------------------------------------------------------------
    def process(self, cmd: int, adp: int, ado: int, data: bytearray, wkc: int
                ) -> tuple[int, int]:
        """Let one datagram pass; ``data`` is changed in place. Returns (ADP, WKC) as the
        datagram leaves this slave."""
        self._pdi()
        if cmd in _AUTO:
            hit = adp == 0
            adp = (adp + 1) & 0xFFFF
        elif cmd in _FIXED:
            m = self.mem
            hit = adp == _U16.unpack_from(m, r.STATION_ADDRESS)[0] or (
                m[r.DL_CONTROL + 3] & 1 and adp == _U16.unpack_from(m, r.STATION_ALIAS)[0])
        elif cmd in _BCAST:
            hit = True
            adp = (adp + 1) & 0xFFFF
        elif cmd in (Command.LRD, Command.LWR, Command.LRW):
            return adp, self._logical(cmd, adp | (ado << 16), data, wkc)
        else:
            return adp, wkc
        if not hit:
            if cmd in (Command.ARMW, Command.FRMW):  # the others write what it read
                return adp, wkc + self._write(ado, bytes(data))
            return adp, wkc
        n = len(data)
        if ado < r.DC_END and ado + n > r.DC_START:
            self.dc.before_read(self.mem, ado, ado + n, self.now_ns)
        if cmd in _READS:
            old, ok = self._read(ado, n)
            if cmd == Command.BRD:
                data[:] = bytes(a | b for a, b in zip(data, old, strict=True))
            else:
                data[:] = old
            return adp, wkc + ok
        if cmd in _WRITES:
            return adp, wkc + self._write(ado, bytes(data))
        if cmd in _RWS:
            old, ok = self._read(ado, n)
            wrote = self._write(ado, bytes(data))
            if cmd == Command.BRW:
                data[:] = bytes(a | b for a, b in zip(data, old, strict=True))
            else:
                data[:] = old
            return adp, wkc + ok + 2 * wrote
        # ARMW / FRMW: the addressed slave reads, the others write.
        data[:], ok = self._read(ado, n)
        return adp, wkc + ok

    # --- memory ---------------------------------------------------------------------------
    def _read(self, ado: int, n: int) -> tuple[bytes, int]:
        """(the bytes, 1 if the read counts: 0 for a refused mailbox read)."""
        out = bytes(self.mem[ado:ado + n])
        ok = 1
        end = min(ado + n, r.MEMORY_SIZE)
        if ado >= r.RAM_START and ado < end:
            k = self._mailbox_at(ado, end)
            if k >= 0:
                ok = self._mbx_read(k, ado, end)
        return out + bytes(n - len(out)), ok

    def _write(self, ado: int, data: bytes) -> int:
        """1 if the write counts (0: refused by a mailbox)."""
        end = min(ado + len(data), r.MEMORY_SIZE)
        if ado >= end:
            return 1
        m = self.mem
        if ado >= r.RAM_START:
            k = self._mailbox_at(ado, end)
            if k >= 0:
                return self._mbx_write(k, ado, end, data)
            if self._sm_allows(ado, end, r.SM_DIR_WRITE):
                m[ado:end] = data[:end - ado]
                self._ram_written(ado, end)
            return 1
        for a in range(ado, end):
            if _WRITABLE[a]:
                m[a] = data[a - ado]
        if ado < r.SM0 + r.N_SM * r.SM_SIZE and end > r.FMMU0:
            self._fmmu_cache = self._sm_cache = None  # mapping changed: decode it again
        if ado < r.AL_CONTROL + 2 and end > r.AL_CONTROL:
            self._al_control(_U16.unpack_from(m, r.AL_CONTROL)[0])
        if ado < r.EEP_CONTROL + 2 and end > r.EEP_CONTROL:
            self._eeprom_command()
        if ado < r.ERROR_COUNTERS_END and end > r.RX_ERROR:
            m[r.RX_ERROR:r.ERROR_COUNTERS_END] = bytes(r.ERROR_COUNTERS_END - r.RX_ERROR)
        if ado <= r.WD_COUNTER_PDI and end > r.WD_COUNTER_PD:
            m[r.WD_COUNTER_PD] = m[r.WD_COUNTER_PDI] = 0
        if ado < r.DC_END and end > r.DC_START:
            self.dc.written(m, ado, end, data, self.now_ns)
        return 1

    # --- mailbox --------------------------------------------------------------------------------
    def _mailbox_at(self, lo: int, hi: int) -> int:
        """The sync manager that decides an access to [lo, hi) if it is a mailbox, else -1."""
        for k in range(r.N_SM):
            start, length, control, _act = self.sm(k)
            if not length or hi <= start or lo >= start + length:
                continue
            return k if control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX else -1
        return -1

    def _mbx_open(self, k: int, lo: int, hi: int, direction: int) -> bool:
        start, length, control, act = self.sm(k)
        return bool(act & r.SM_ENABLE and control & r.SM_DIR_MASK == direction
                    and self.state != AlState.INIT and start <= lo and hi <= start + length)

    def _mbx_write(self, k: int, lo: int, hi: int, data: bytes) -> int:
        m, status = self.mem, r.SM0 + k * r.SM_SIZE + r.SM_STATUS
        if not self._mbx_open(k, lo, hi, r.SM_DIR_WRITE) or m[status] & r.SM_STATUS_FULL:
            return 0
        m[lo:hi] = data[:hi - lo]
        start, length, _c, _a = self.sm(k)
        if hi == start + length:  # the last byte: the mailbox is full, the PDI's to take
            m[status] |= r.SM_STATUS_FULL
            self._mbx_rx = bytes(m[start:start + length])
            self.mbx_rx_state = 1
        return 1

    def _mbx_read(self, k: int, lo: int, hi: int) -> int:
        m, status = self.mem, r.SM0 + k * r.SM_SIZE + r.SM_STATUS
        if not self._mbx_open(k, lo, hi, r.SM_DIR_READ) or not m[status] & r.SM_STATUS_FULL:
            return 0
        start, length, _c, _a = self.sm(k)
        if hi == start + length:  # the last byte read: empty again
            m[status] &= ~r.SM_STATUS_FULL & 0xFF
        return 1

    def _pdi(self) -> None:
        """The application's side of the mailbox, before a datagram reaches the slave: a
        taken request frees SM0; a repeat request re-offers SM1's last answer; a posted
        answer enters an empty SM1."""
        m = self.mem
        if self.mbx_rx_state == 2:
            m[r.SM0 + r.SM_STATUS] &= ~r.SM_STATUS_FULL & 0xFF
            self.mbx_rx_state = 0
        b1 = r.SM0 + r.SM_SIZE
        if m[b1 + 4] & r.SM_MODE_MASK != r.SM_MODE_MAILBOX or self.state == AlState.INIT:
            return
        if (m[b1 + 6] ^ m[b1 + r.SM_PDI_CONTROL]) & r.SM_REPEAT:
            m[b1 + r.SM_PDI_CONTROL] ^= r.SM_REPEAT
            m[b1 + r.SM_STATUS] |= r.SM_STATUS_FULL
        start, length, _c, act = self.sm(1)
        if (self._mbx_tx is not None and act & r.SM_ENABLE and length
                and not m[b1 + r.SM_STATUS] & r.SM_STATUS_FULL):
            length = min(length, r.MEMORY_SIZE - start)
            data = self._mbx_tx[:length]
            m[start:start + length] = data + bytes(length - len(data))
            m[b1 + r.SM_STATUS] |= r.SM_STATUS_FULL
            self._mbx_tx = None

    def take_mailbox(self) -> bytes | None:
        """The application takes the master's request (SM0's buffer), if one is there."""
        if self.mbx_rx_state != 1:
            return None
        self.mbx_rx_state = 2
        return self._mbx_rx

    def post_mailbox(self, data: bytes) -> bool:
        """The application's answer for SM1; False if the previous one has not gone in yet."""
        if self._mbx_tx is not None:
            return False
        self._mbx_tx = bytes(data)
        return True

    def set_pd_lengths(self, out_bytes: int, in_bytes: int) -> None:
        """The process-data lengths the application expects from now on (a PDO assignment
        changed over CoE in PREOP): what SAFEOP's check compares the sync managers with."""
        self.out_bytes, self.in_bytes = out_bytes, in_bytes

    # --- sync managers and FMMUs -----------------------------------------------------------
    def sm(self, k: int) -> tuple[int, int, int, int]:
        """Sync manager ``k``: (start, length, control, activate)."""
        start, length, control, _st, act = struct.unpack_from("<HHBBB", self.mem,
                                                              r.SM0 + k * r.SM_SIZE)
        return start, length, control, act

    def fmmus(self) -> list[tuple[int, int, int, int]]:
        """Active FMMUs: (logical start, length, physical start, type)."""
        if self._fmmu_cache is not None:
            return self._fmmu_cache
        out = []
        for k in range(r.N_FMMU):
            ls, ll, _sb, _eb, ps, _pb, typ, act = _FMMU.unpack_from(
                self.mem, r.FMMU0 + k * r.FMMU_SIZE)
            if act & 1 and ll and typ:
                out.append((ls, ll, ps, typ))
        self._fmmu_cache = out
        return out

    def _sms(self) -> list[tuple[int, int, int, int]]:
        if self._sm_cache is None:
            self._sm_cache = [s for s in (self.sm(k) for k in range(r.N_SM)) if s[1]]
        return self._sm_cache

    def _sm_allows(self, lo: int, hi: int, direction: int) -> bool:
        """May the master access [lo, hi) of RAM this way? Outside every sync manager: yes;
        inside one: only if it is enabled, points this way and the slave is in SAFEOP/OP
        (never a mailbox's: those are the physical accesses' of :meth:`_mbx_write`)."""
        for start, length, control, act in self._sms():
            if hi <= start or lo >= start + length:
                continue
            return bool(act & r.SM_ENABLE and (control & r.SM_DIR_MASK) == direction
                        and control & r.SM_MODE_MASK != r.SM_MODE_MAILBOX
                        and self.state in (AlState.SAFEOP, AlState.OP))
        return True

    def _ram_written(self, lo: int, hi: int) -> None:
        """A write that reaches the last byte of the output buffer completes it."""
        if not self.out_bytes:
            return
        start, length, control, _act = self.sm(self.desc.out_sm)
        if length and lo < start + length <= hi:
            if control & r.SM_WATCHDOG:
                self.last_output_ns = self.now_ns
                _U16.pack_into(self.mem, r.WD_STATUS_PD, 1)
            if self.state == AlState.OP:
                self._pending = bytes(self.mem[start:start + length])

    def _logical(self, cmd: int, lad: int, data: bytearray, wkc: int) -> int:
        n = len(data)
        incoming = bytes(data) if cmd == Command.LRW else data
        read_hit = write_hit = False
        for ls, ll, ps, typ in self.fmmus():
            lo, hi = max(lad, ls), min(lad + n, ls + ll)
            if lo >= hi:
                continue
            plo, phi = ps + lo - ls, ps + hi - ls
            if phi > r.MEMORY_SIZE:  # the part past the slave's memory maps to nothing
                hi -= phi - r.MEMORY_SIZE
                phi = r.MEMORY_SIZE
                if lo >= hi:
                    continue
            if typ & r.FMMU_WRITE and cmd != Command.LRD and self._sm_allows(
                    plo, phi, r.SM_DIR_WRITE):
                self.mem[plo:phi] = incoming[lo - lad:hi - lad]
                self._ram_written(plo, phi)
                write_hit = True
            if typ & r.FMMU_READ and cmd != Command.LWR and self._sm_allows(
                    plo, phi, r.SM_DIR_READ):
                data[lo - lad:hi - lad] = self.mem[plo:phi]
                read_hit = True
        if cmd == Command.LRW:
            return wkc + read_hit + 2 * write_hit
        return wkc + (read_hit if cmd == Command.LRD else write_hit)

    # --- SII EEPROM interface ----------------------------------------------------------------
    def _eeprom_command(self) -> None:
        m = self.mem
        cmd = _U16.unpack_from(m, r.EEP_CONTROL)[0] & r.EEP_CMD_MASK
        status = r.EEP_STAT_READ8
        if cmd == r.EEP_CMD_READ:
            a = 2 * _U32.unpack_from(m, r.EEP_ADDRESS)[0]
            chunk = self.sii[a:a + 8]
            m[r.EEP_DATA:r.EEP_DATA + 8] = chunk + b"\xff" * (8 - len(chunk))
        elif cmd == r.EEP_CMD_WRITE:
            status |= r.EEP_STAT_CMD_ERROR  # the image is the box's: read only here
        elif cmd == r.EEP_CMD_RELOAD:
            _U16.pack_into(m, r.STATION_ALIAS, self.desc.alias)
        _U16.pack_into(m, r.EEP_CONTROL, status)

    # --- AL state machine --------------------------------------------------------------------
    def _set_al_status(self) -> None:
        _U16.pack_into(self.mem, r.AL_STATUS, int(self.state) | (AL_ERROR if self.error else 0))
        _U16.pack_into(self.mem, r.AL_STATUS_CODE, int(self.code))

    def _refuse(self, code: AlStatusCode) -> None:
        self.error, self.code = True, code
        self._set_al_status()

    def _al_control(self, value: int) -> None:
        req, ack = value & 0x0F, bool(value & AL_ERROR)
        if self.error:
            if ack:
                self.error, self.code = False, AlStatusCode.NO_ERROR
            elif req >= self.state:
                return  # an error must be acknowledged before going up again
        if req not in AlState._value2member_map_:
            return self._refuse(AlStatusCode.UNKNOWN_STATE)
        req = AlState(req)
        if req == AlState.BOOT:
            return self._refuse(AlStatusCode.BOOTSTRAP_NOT_SUPPORTED)
        cur = self.state
        if req != cur and req != AlState.INIT and (cur, req) not in _ALLOWED:
            return self._refuse(AlStatusCode.INVALID_STATE_CHANGE)
        if cur == AlState.INIT and req == AlState.PREOP and not self._mailbox_config_ok():
            return self._refuse(AlStatusCode.INVALID_MAILBOX_CONFIG)
        if cur == AlState.PREOP and req == AlState.SAFEOP:
            code = self._check_pd_config()
            if code is not None:
                return self._refuse(code)
        self._enter(req)

    def _enter(self, state: AlState) -> None:
        was_op = self.state == AlState.OP
        self.state = state
        if state == AlState.OP and not was_op:
            self.last_output_ns = self.now_ns   # the watchdog starts with OP
            _U16.pack_into(self.mem, r.WD_STATUS_PD, 1)
        if was_op and state != AlState.OP and self.out_bytes:
            self._pending = bytes(self.out_bytes)
        if state == AlState.INIT:  # the PDI turns the mailboxes off: both empty
            for k in (0, 1):
                self.mem[r.SM0 + k * r.SM_SIZE + r.SM_STATUS] &= ~r.SM_STATUS_FULL & 0xFF
        self._set_al_status()

    def _mailbox_config_ok(self) -> bool:
        """INIT -> PREOP: are SM0/SM1 the SII's mailboxes (if it has any)?"""
        if not self.desc.coe:
            return True
        for k, want in ((0, r.SM_DIR_WRITE), (1, r.SM_DIR_READ)):
            sii = self.desc.sms[k]
            start, length, control, act = self.sm(k)
            if (start != sii.start or length != sii.length or not act & r.SM_ENABLE
                    or control & (r.SM_DIR_MASK | r.SM_MODE_MASK) != want | r.SM_MODE_MAILBOX):
                return False
        return True

    def _check_pd_config(self) -> AlStatusCode | None:
        """PREOP -> SAFEOP: are the process-data sync managers and FMMUs as the SII says?"""
        fmmus = self.fmmus()
        for k, want_len, (want, code, ftype) in zip(
                (self.desc.out_sm, self.desc.in_sm), (self.out_bytes, self.in_bytes),
                ((r.SM_DIR_WRITE, AlStatusCode.INVALID_OUTPUT_CONFIG, r.FMMU_WRITE),
                 (r.SM_DIR_READ, AlStatusCode.INVALID_INPUT_CONFIG, r.FMMU_READ)), strict=True):
            sii = self.desc.sms[k]
            if not want_len:
                continue
            start, length, control, act = self.sm(k)
            if (start != sii.start or length != want_len or not act & r.SM_ENABLE
                    or (control & r.SM_DIR_MASK) != want):
                return code
            covered = sum(max(0, min(ps + ll, start + length) - max(ps, start))
                          for _ls, ll, ps, typ in fmmus if typ & ftype)
            if covered < length:
                return code
        return None

    # --- the application (PDI) side ------------------------------------------------------------
    def set_inputs(self, data: bytes) -> None:
        """The box's input record into the input sync manager's buffer."""
        start = self.desc.sms[self.desc.in_sm].start
        self.mem[start:start + len(data)] = data

    def pending_outputs(self) -> bytes | None:
        """Outputs for the box since the last call (new ones in OP, safe ones on leaving
        OP or on a watchdog trip), or None."""
        out, self._pending = self._pending, None
        return out

    def watchdog_increment_ns(self) -> int:
        """One watchdog increment [ns] (the divider, register 0x0400)."""
        return 40 * (_U16.unpack_from(self.mem, r.WD_DIVIDER)[0] + 2)

    def watchdog_ns(self) -> int:
        """Process-data watchdog time [ns] (0: disabled)."""
        div = _U16.unpack_from(self.mem, r.WD_DIVIDER)[0]
        return 40 * (div + 2) * _U16.unpack_from(self.mem, r.WD_TIME_PD)[0]

    def tick(self, dt_ns: int) -> None:
        """Advance the slave's time; in OP the watchdog trips if the output buffer was not
        written for the watchdog time (outputs safe, SAFEOP + error, code 0x001B): at the
        first watchdog increment that ends it, as an ESC counts it, applied in the tick
        that passes it."""
        self.now_ns += dt_ns
        self.dc.tick(self.mem, self.now_ns)
        if self.state != AlState.OP or not self.out_bytes:
            return
        wd = self.watchdog_ns()
        if not wd or not self.sm(self.desc.out_sm)[2] & r.SM_WATCHDOG:
            return
        inc = self.watchdog_increment_ns()
        t = self.last_output_ns + wd
        expiry = -(-t // inc) * inc   # the first increment boundary of the slave's clock
        if self.now_ns >= expiry:
            _U16.pack_into(self.mem, r.WD_STATUS_PD, 0)
            self.mem[r.WD_COUNTER_PD] = min(self.mem[r.WD_COUNTER_PD] + 1, 0xFF)
            self.watchdog_trips += 1
            self.last_trip_delay_ns = expiry - self.last_output_ns
            self.last_trip_seen_ns = self.now_ns - self.last_output_ns
            self._enter(AlState.SAFEOP)
            self._refuse(AlStatusCode.SM_WATCHDOG)
