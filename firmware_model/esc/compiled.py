"""The chain of ESCs in compiled code: a whole Ethernet frame through every slave in one call
that holds no interpreter lock (numba, ``nogil``), from the slaves' memories only.

The same slaves as :class:`firmware_model.esc.esc.Esc` (the readable reference, tested equal
byte for byte on random frames: ``tests/fieldbus/test_esc_compiled.py``): register space,
SII EEPROM interface, AL state machine, FMMUs, sync managers, working counters, the
process-data watchdog. State lives in arrays (:class:`EscArrays`), one row per slave.

The application side (the box's MCU behind the ESC) meets the frame side through two
3-buffers per slave, as an ESC's process-data sync managers in 3-buffer mode do: the box
publishes a complete input record, the frame side publishes a complete output record, and
each side takes the newest complete record the other published, never a half-written one,
without a lock and without waiting (:func:`publish`, :func:`take`). The frame side copies
a new input record into the slave's memory before the next datagram reaches the slave;
it publishes the output buffer when a write completes it in OP (the safe, all-zero outputs
on leaving OP or on a watchdog trip).

The mailbox (SM0/SM1, 1-buffer mode, as :class:`~firmware_model.esc.esc.Esc` describes it)
meets the application through two more slots of the output buffers (:data:`MBX_RX`: the
master's request the frame side hands over; :data:`MBX_TX`: the application's answer) and
two state words set with atomic exchanges (``S_MBX_RX``: 1 handed over, 2 taken;
``S_MBX_TX``: 1 posted). Only the frame side writes the slaves' memories: a taken request
frees SM0, a posted answer enters an empty SM1, when the next datagram reaches the slave.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from firmware_model.esc import dc_compiled as dcc
from firmware_model.esc import registers as r
from firmware_model.esc.dc import DcParams, dc_line
from firmware_model.esc.esc import _WRITABLE, ESC_TYPE, Esc
from firmware_model.esc.sii import SlaveDescription

MEM = r.MEMORY_SIZE
#: Capacity of one 3-buffer slot [bytes] (a sync manager may span the whole memory).
BUF = r.MEMORY_SIZE
FRESH = 4  # bit of the shared 3-buffer index: the shared slot holds a record not yet taken

# Per-slave state words (int64 columns of ``EscArrays.st``).
S_STATE, S_ERROR, S_CODE, S_NOW, S_LAST_OUT, S_TRIPS, S_TRIP_DELAY = range(7)
S_ALIAS, S_OUT_BYTES, S_SII0_START, S_SII0_LEN, S_SII1_START, S_SII1_LEN = range(7, 13)
S_SII_LEN, S_IN_START = 13, 14
# Mailbox: sync-manager indices of the process data, the hand-over words, the SII's mailbox
# sync managers (length 0: no mailbox). S_SII0_*/S_SII1_* are the process data's
# (S_SII0_LEN/S_SII1_LEN: the lengths the application expects, changed by a PDO remap).
S_OUT_SM, S_IN_SM, S_MBX_RX, S_MBX_TX = 15, 16, 17, 18
S_MBX0_START, S_MBX0_LEN, S_MBX1_START, S_MBX1_LEN = 19, 20, 21, 22
# Distributed clocks: columns dcc.DC_BASE (23) .. dcc.DC_END (firmware_model.esc.dc_compiled).
# S_TRIP_SEEN: of the last watchdog trip, ns from the last output write to the tick of the
# slave's clock that applied it (S_TRIP_DELAY: to the trip itself).
S_TRIP_SEEN = dcc.DC_END
# Output records published in OP (a master's complete writes of the output buffer): how many
# (S_OUT_WRITES), and the slave's clock [ns] at each of the last OUT_RING of them, in a ring
# indexed by that count. The box side asks whether its cycle's scheduled millisecond had a
# write (:meth:`EscArrays.outputs_written`), whenever it runs that cycle.
OUT_RING = 128
S_OUT_WRITES = S_TRIP_SEEN + 1
S_OUT_AT = S_OUT_WRITES + 1
N_ST = S_OUT_AT + OUT_RING
#: The ring's entries before any write (no interval of the slave's clock holds it).
NEVER = -(1 << 62)
#: Slots of ``obuf``/``olen`` after the output 3-buffer: the mailbox hand-over buffers.
MBX_RX, MBX_TX = 3, 4
N_OSLOTS = 5
# 3-buffer index words (int64 columns of ``EscArrays.oidx`` / ``iidx``).
B_WRITER, B_SHARED, B_READER = 0, 1, 2

# Return codes of :func:`handle_frame` (else: the reply's length).
NOT_ETHERCAT = -1   # not an EtherCAT frame (or not even Ethernet): ignored
DROPPED = -2        # EtherCAT frame that does not decode: dropped, as an ESC drops a bad FCS

_INIT, _PREOP, _BOOT, _SAFEOP, _OP = 1, 2, 3, 4, 8
_AL_ERROR = 0x10


class EscArrays:
    """The memories and state of a chain of slaves (``descs``: (description, SII image) in
    line order), laid out as the compiled frame path reads them. ``dc``: the slaves' clocks
    and delays (:func:`firmware_model.esc.dc.dc_line` by default)."""

    def __init__(self, described: list[tuple[SlaveDescription, bytes]],
                 dc: list[DcParams] | None = None) -> None:
        n = len(described)
        dc = dc if dc is not None else dc_line(n)
        self.n = n
        self.mem = np.zeros((n, MEM), dtype=np.uint8)
        sii_max = max(len(img) for _d, img in described)
        self.sii = np.full((n, sii_max), 0xFF, dtype=np.uint8)
        self.st = np.zeros((n, N_ST), dtype=np.int64)
        self.st[:, S_OUT_AT:S_OUT_AT + OUT_RING] = NEVER
        self.wmask = np.frombuffer(_WRITABLE, dtype=np.uint8).copy()
        self.obuf = np.zeros((n, N_OSLOTS, BUF), dtype=np.uint8)
        self.olen = np.zeros((n, N_OSLOTS), dtype=np.int64)
        self.ibuf = np.zeros((n, 3, BUF), dtype=np.uint8)
        self.ilen = np.zeros((n, 3), dtype=np.int64)
        self.oidx = np.tile(np.array([0, 1, 2], dtype=np.int64), (n, 1))
        self.iidx = self.oidx.copy()
        self.scratch = np.zeros(2048, dtype=np.uint8)
        for i, (d, img) in enumerate(described):
            ref = Esc(d, img, last=i == n - 1, dc=dc[i])  # the reference's reset state
            self.mem[i] = np.frombuffer(bytes(ref.mem), dtype=np.uint8)
            self.sii[i, :len(img)] = np.frombuffer(img, dtype=np.uint8)
            st = self.st[i]
            st[S_STATE], st[S_CODE] = int(ref.state), int(ref.code)
            st[S_ALIAS], st[S_OUT_BYTES] = d.alias, d.out_bytes
            out_sm, in_sm = d.sms[d.out_sm], d.sms[d.in_sm]
            st[S_SII0_START], st[S_SII0_LEN] = out_sm.start, out_sm.length
            st[S_SII1_START], st[S_SII1_LEN] = in_sm.start, in_sm.length
            st[S_SII_LEN], st[S_IN_START] = len(img), in_sm.start
            st[S_OUT_SM], st[S_IN_SM] = d.out_sm, d.in_sm
            if d.coe:
                st[S_MBX0_START], st[S_MBX0_LEN] = d.sms[0].start, d.sms[0].length
                st[S_MBX1_START], st[S_MBX1_LEN] = d.sms[1].start, d.sms[1].length
            dcc.init_row(self.mem[i], st, dc[i])
        assert self.mem[0, r.TYPE] == ESC_TYPE

    def frame_args(self) -> tuple:
        """The arrays :func:`handle_frame` takes after the frame, in order."""
        return (self.mem, self.sii, self.st, self.wmask, self.obuf, self.olen, self.oidx,
                self.ibuf, self.ilen, self.iidx, self.scratch)

    # --- the application side, from Python ---------------------------------------------------
    def set_inputs(self, i: int, data: bytes) -> None:
        """Box ``i`` publishes its input record."""
        rec = np.frombuffer(data, dtype=np.uint8)
        publish(self.ibuf[i], self.ilen[i], self.iidx[i], rec, len(rec))

    def pending_outputs(self, i: int) -> bytes | None:
        """The newest output record for box ``i`` since the last call, or None."""
        slot = take(self.oidx[i])
        if slot < 0:
            return None
        return self.obuf[i, slot, :self.olen[i, slot]].tobytes()

    def outputs_written(self, after_ns: int, until_ns: int) -> np.ndarray:
        """Per slave: whether the master completed an output record in OP in ``(after_ns,
        until_ns]`` of the slaves' clock, among its last :data:`OUT_RING` records (read
        while the frame side writes: a slot is one aligned word, whole either way)."""
        return written_in(self.st[:, S_OUT_AT:S_OUT_AT + OUT_RING], after_ns, until_ns)

    def take_mailbox(self, i: int) -> bytes | None:
        """Box ``i``'s application takes the master's mailbox request, if one is there."""
        st = self.st[i]
        if st[S_MBX_RX] != 1:
            return None
        data = self.obuf[i, MBX_RX, :self.olen[i, MBX_RX]].tobytes()
        st[S_MBX_RX] = 2  # (only the frame side writes it otherwise, and not while it is 1)
        return data

    def mailbox_requests(self) -> list[int]:
        """The slaves whose application has a mailbox request to take."""
        return np.flatnonzero(self.st[:, S_MBX_RX] == 1).tolist()

    def in_init(self) -> list[int]:
        """The slaves in INIT (their mailboxes off)."""
        return np.flatnonzero(self.st[:, S_STATE] == _INIT).tolist()

    def post_mailbox(self, i: int, data: bytes) -> bool:
        """Box ``i``'s answer for its SM1; False if the previous one has not gone in yet."""
        st = self.st[i]
        if st[S_MBX_TX]:
            return False
        n = len(data)
        self.obuf[i, MBX_TX, :n] = np.frombuffer(data, dtype=np.uint8)
        self.olen[i, MBX_TX] = n
        st[S_MBX_TX] = 1  # after the data: the frame side copies it once it sees the 1
        return True

    def set_pd_lengths(self, i: int, out_bytes: int, in_bytes: int) -> None:
        """The process-data lengths box ``i`` expects from now on (a PDO remap in PREOP)."""
        st = self.st[i]
        st[S_SII0_LEN] = st[S_OUT_BYTES] = out_bytes
        st[S_SII1_LEN] = in_bytes

    def state(self, i: int) -> tuple[int, bool, int]:
        """(AL state, error, AL status code) of slave ``i``."""
        st = self.st[i]
        return int(st[S_STATE]), bool(st[S_ERROR]), int(st[S_CODE])


def written_in(at: np.ndarray, after_ns: int, until_ns: int) -> np.ndarray:
    """Per row of write times ``at`` [ns] (a ring, :data:`NEVER` where unused): whether one
    lies in ``(after_ns, until_ns]``."""
    return ((at > after_ns) & (at <= until_ns)).any(axis=1)


# --- lock-free 3-buffer -------------------------------------------------------------------------
@intrinsic
def _xchg(typingctx, arr, i, value):
    """``old = arr[i]; arr[i] = value`` as one atomic operation; returns ``old``."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]])
        return builder.atomic_rmw("xchg", ptr, args[2], "seq_cst")

    return types.int64(arr, types.intp, types.int64), codegen


@njit(cache=True, nogil=True)
def publish(bufs, lens, idx, data, n):
    """Writer side: ``data[:n]`` into the writer's slot, then that slot becomes the shared
    one (marked fresh) and the previously shared slot the writer's."""
    w = idx[B_WRITER]
    bufs[w, :n] = data[:n]
    lens[w] = n
    idx[B_WRITER] = _xchg(idx, B_SHARED, w | FRESH) & 3


@njit(cache=True, nogil=True)
def take(idx):
    """Reader side: the slot of the newest complete record if one arrived since the last
    take (it becomes the reader's), else -1."""
    if not idx[B_SHARED] & FRESH:
        return -1
    idx[B_READER] = _xchg(idx, B_SHARED, idx[B_READER]) & 3
    return idx[B_READER]


# --- little-endian helpers ----------------------------------------------------------------------
@njit(cache=True, nogil=True, inline="always")
def _u16(a, o):
    return np.int64(a[o]) | (np.int64(a[o + 1]) << 8)


@njit(cache=True, nogil=True, inline="always")
def _u32(a, o):
    return _u16(a, o) | (_u16(a, o + 2) << 16)


@njit(cache=True, nogil=True, inline="always")
def _put16(a, o, v):
    a[o] = v & 0xFF
    a[o + 1] = (v >> 8) & 0xFF


# --- one slave ----------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _set_al_status(m, st):
    _put16(m, r.AL_STATUS, st[S_STATE] | (_AL_ERROR if st[S_ERROR] else 0))
    _put16(m, r.AL_STATUS_CODE, st[S_CODE])


@njit(cache=True, nogil=True)
def _refuse(m, st, code):
    st[S_ERROR] = 1
    st[S_CODE] = code
    _set_al_status(m, st)


@njit(cache=True, nogil=True)
def _publish_out(obuf, olen, oidx, src, lo, n):
    w = oidx[B_WRITER]
    obuf[w, :n] = src[lo:lo + n]
    olen[w] = n
    oidx[B_WRITER] = _xchg(oidx, B_SHARED, w | FRESH) & 3


@njit(cache=True, nogil=True)
def _publish_safe(obuf, olen, oidx, n):
    w = oidx[B_WRITER]
    obuf[w, :n] = 0
    olen[w] = n
    oidx[B_WRITER] = _xchg(oidx, B_SHARED, w | FRESH) & 3


@njit(cache=True, nogil=True)
def _enter(m, st, obuf, olen, oidx, state):
    was_op = st[S_STATE] == _OP
    st[S_STATE] = state
    if state == _OP and not was_op:
        st[S_LAST_OUT] = st[S_NOW]
        _put16(m, r.WD_STATUS_PD, 1)
    if was_op and state != _OP and st[S_OUT_BYTES]:
        _publish_safe(obuf, olen, oidx, st[S_OUT_BYTES])
    if state == _INIT:  # the PDI turns the mailboxes off: both empty
        m[r.SM0 + r.SM_STATUS] &= ~r.SM_STATUS_FULL & 0xFF
        m[r.SM0 + r.SM_SIZE + r.SM_STATUS] &= ~r.SM_STATUS_FULL & 0xFF
    _set_al_status(m, st)


@njit(cache=True, nogil=True)
def _sm(m, k):
    b = r.SM0 + k * r.SM_SIZE
    return _u16(m, b), _u16(m, b + 2), np.int64(m[b + 4]), np.int64(m[b + 6])


@njit(cache=True, nogil=True)
def _fmmu(m, k):
    b = r.FMMU0 + k * r.FMMU_SIZE
    return (_u32(m, b), _u16(m, b + 4), _u16(m, b + 8), np.int64(m[b + 11]),
            np.int64(m[b + 12]))


@njit(cache=True, nogil=True)
def _sm_allows(m, st, lo, hi, direction):
    for k in range(r.N_SM):
        start, length, control, act = _sm(m, k)
        if not length or hi <= start or lo >= start + length:
            continue
        return bool(act & r.SM_ENABLE and (control & r.SM_DIR_MASK) == direction
                    and (control & r.SM_MODE_MASK) != r.SM_MODE_MAILBOX
                    and (st[S_STATE] == _SAFEOP or st[S_STATE] == _OP))
    return True


# --- mailbox (mirrors Esc._mailbox_at .. Esc._pdi) -----------------------------------------
@njit(cache=True, nogil=True)
def _mailbox_at(m, lo, hi):
    for k in range(r.N_SM):
        start, length, control, _act = _sm(m, k)
        if not length or hi <= start or lo >= start + length:
            continue
        return k if (control & r.SM_MODE_MASK) == r.SM_MODE_MAILBOX else -1
    return -1


@njit(cache=True, nogil=True)
def _mbx_open(m, st, k, lo, hi, direction):
    start, length, control, act = _sm(m, k)
    return ((act & r.SM_ENABLE) != 0 and (control & r.SM_DIR_MASK) == direction
            and st[S_STATE] != _INIT and start <= lo and hi <= start + length)


@njit(cache=True, nogil=True)
def _mbx_write(m, st, obuf, olen, k, lo, hi, src, s0):
    status = r.SM0 + k * r.SM_SIZE + r.SM_STATUS
    if not _mbx_open(m, st, k, lo, hi, r.SM_DIR_WRITE) or m[status] & r.SM_STATUS_FULL:
        return 0
    m[lo:hi] = src[s0:s0 + hi - lo]
    start, length, _c, _a = _sm(m, k)
    if hi == start + length:
        m[status] |= r.SM_STATUS_FULL
        obuf[MBX_RX, :length] = m[start:start + length]
        olen[MBX_RX] = length
        _xchg(st, S_MBX_RX, 1)
    return 1


@njit(cache=True, nogil=True)
def _mbx_read(m, st, ado, n):
    """1 if a read of [ado, ado + n) counts (0: a refused mailbox read); a read of a full
    mailbox's last byte empties it."""
    end = min(ado + n, MEM)
    if ado < r.RAM_START or ado >= end:
        return 1
    k = _mailbox_at(m, ado, end)
    if k < 0:
        return 1
    status = r.SM0 + k * r.SM_SIZE + r.SM_STATUS
    if not _mbx_open(m, st, k, ado, end, r.SM_DIR_READ) or not m[status] & r.SM_STATUS_FULL:
        return 0
    start, length, _c, _a = _sm(m, k)
    if end == start + length:
        m[status] &= ~r.SM_STATUS_FULL & 0xFF
    return 1


@njit(cache=True, nogil=True)
def _pdi_mailbox(m, st, obuf, olen):
    if st[S_MBX_RX] == 2:
        m[r.SM0 + r.SM_STATUS] &= ~r.SM_STATUS_FULL & 0xFF
        _xchg(st, S_MBX_RX, 0)
    b1 = r.SM0 + r.SM_SIZE
    if (m[b1 + 4] & r.SM_MODE_MASK) != r.SM_MODE_MAILBOX or st[S_STATE] == _INIT:
        return
    if (m[b1 + 6] ^ m[b1 + r.SM_PDI_CONTROL]) & r.SM_REPEAT:
        m[b1 + r.SM_PDI_CONTROL] ^= r.SM_REPEAT
        m[b1 + r.SM_STATUS] |= r.SM_STATUS_FULL
    start, length, _c, act = _sm(m, 1)
    if (st[S_MBX_TX] == 1 and act & r.SM_ENABLE and length
            and not m[b1 + r.SM_STATUS] & r.SM_STATUS_FULL):
        length = min(length, MEM - start)
        n = min(olen[MBX_TX], length)
        m[start:start + n] = obuf[MBX_TX, :n]
        m[start + n:start + length] = 0
        m[b1 + r.SM_STATUS] |= r.SM_STATUS_FULL
        _xchg(st, S_MBX_TX, 0)


@njit(cache=True, nogil=True)
def _mailbox_config_ok(m, st):
    if not st[S_MBX0_LEN]:
        return True
    for k in range(2):
        want = r.SM_DIR_WRITE if k == 0 else r.SM_DIR_READ
        s_start = st[S_MBX0_START] if k == 0 else st[S_MBX1_START]
        s_len = st[S_MBX0_LEN] if k == 0 else st[S_MBX1_LEN]
        start, length, control, act = _sm(m, k)
        if (start != s_start or length != s_len or not act & r.SM_ENABLE
                or (control & (r.SM_DIR_MASK | r.SM_MODE_MASK)) != (want | r.SM_MODE_MAILBOX)):
            return False
    return True


@njit(cache=True, nogil=True)
def _check_pd_config(m, st):
    for k in range(2):
        if k == 0:
            want, code, ftype = r.SM_DIR_WRITE, 0x001D, r.FMMU_WRITE
            s_start, s_len, sm = st[S_SII0_START], st[S_SII0_LEN], st[S_OUT_SM]
        else:
            want, code, ftype = r.SM_DIR_READ, 0x001E, r.FMMU_READ
            s_start, s_len, sm = st[S_SII1_START], st[S_SII1_LEN], st[S_IN_SM]
        if not s_len:
            continue
        start, length, control, act = _sm(m, sm)
        if (start != s_start or length != s_len or not act & r.SM_ENABLE
                or (control & r.SM_DIR_MASK) != want):
            return code
        covered = 0
        for f in range(r.N_FMMU):
            _ls, ll, ps, typ, fact = _fmmu(m, f)
            if fact & 1 and ll and typ and typ & ftype:
                covered += max(0, min(ps + ll, start + length) - max(ps, start))
        if covered < length:
            return code
    return 0


@njit(cache=True, nogil=True)
def _al_control(m, st, obuf, olen, oidx, value):
    req, ack = value & 0x0F, (value & _AL_ERROR) != 0
    if st[S_ERROR]:
        if ack:
            st[S_ERROR] = 0
            st[S_CODE] = 0
        elif req >= st[S_STATE]:
            return
    if not (req == _INIT or req == _PREOP or req == _BOOT or req == _SAFEOP or req == _OP):
        _refuse(m, st, 0x0012)
        return
    if req == _BOOT:
        _refuse(m, st, 0x0013)
        return
    cur = st[S_STATE]
    if req != cur and req != _INIT and not (
            (cur == _INIT and req == _PREOP) or (cur == _PREOP and req == _SAFEOP)
            or (cur == _SAFEOP and req == _OP) or (cur == _OP and req == _SAFEOP)
            or (cur == _OP and req == _PREOP) or (cur == _SAFEOP and req == _PREOP)):
        _refuse(m, st, 0x0011)
        return
    if cur == _INIT and req == _PREOP and not _mailbox_config_ok(m, st):
        _refuse(m, st, 0x0016)
        return
    if cur == _PREOP and req == _SAFEOP:
        code = _check_pd_config(m, st)
        if code:
            _refuse(m, st, code)
            return
    _enter(m, st, obuf, olen, oidx, req)


@njit(cache=True, nogil=True)
def _eeprom_command(m, st, sii):
    cmd = _u16(m, r.EEP_CONTROL) & r.EEP_CMD_MASK
    status = r.EEP_STAT_READ8
    if cmd == r.EEP_CMD_READ:
        a = 2 * _u32(m, r.EEP_ADDRESS)
        n = st[S_SII_LEN]
        for j in range(8):
            m[r.EEP_DATA + j] = sii[a + j] if a + j < n else 0xFF
    elif cmd == r.EEP_CMD_WRITE:
        status |= r.EEP_STAT_CMD_ERROR
    elif cmd == r.EEP_CMD_RELOAD:
        _put16(m, r.STATION_ALIAS, st[S_ALIAS])
    _put16(m, r.EEP_CONTROL, status)


@njit(cache=True, nogil=True)
def _ram_written(m, st, obuf, olen, oidx, lo, hi):
    if not st[S_OUT_BYTES]:
        return
    start, length, control, _act = _sm(m, st[S_OUT_SM])
    if length and lo < start + length <= hi:
        if control & r.SM_WATCHDOG:
            st[S_LAST_OUT] = st[S_NOW]
            _put16(m, r.WD_STATUS_PD, 1)
        if st[S_STATE] == _OP:
            _publish_out(obuf, olen, oidx, m, start, min(length, MEM - start))
            k = st[S_OUT_WRITES]
            st[S_OUT_AT + k % OUT_RING] = st[S_NOW]
            st[S_OUT_WRITES] = k + 1


@njit(cache=True, nogil=True)
def _write(m, st, sii, wmask, obuf, olen, oidx, ado, src, s0, n):
    """The master writes ``src[s0:s0 + n]`` at ``ado``; 1 if the write counts (0: refused
    by a mailbox)."""
    end = min(ado + n, MEM)
    if ado >= end:
        return 1
    if ado >= r.RAM_START:
        k = _mailbox_at(m, ado, end)
        if k >= 0:
            return _mbx_write(m, st, obuf, olen, k, ado, end, src, s0)
        if _sm_allows(m, st, ado, end, r.SM_DIR_WRITE):
            m[ado:end] = src[s0:s0 + end - ado]
            _ram_written(m, st, obuf, olen, oidx, ado, end)
        return 1
    for a in range(ado, end):
        if wmask[a]:
            m[a] = src[s0 + a - ado]
    if ado < r.AL_CONTROL + 2 and end > r.AL_CONTROL:
        _al_control(m, st, obuf, olen, oidx, _u16(m, r.AL_CONTROL))
    if ado < r.EEP_CONTROL + 2 and end > r.EEP_CONTROL:
        _eeprom_command(m, st, sii)
    if ado < r.ERROR_COUNTERS_END and end > r.RX_ERROR:
        m[r.RX_ERROR:r.ERROR_COUNTERS_END] = 0
    if ado <= r.WD_COUNTER_PDI and end > r.WD_COUNTER_PD:
        m[r.WD_COUNTER_PD] = 0
        m[r.WD_COUNTER_PDI] = 0
    if ado < r.DC_END and end > r.DC_START:
        dcc.written(m, st, ado, end, src, s0, st[S_NOW])
    return 1


@njit(cache=True, nogil=True)
def _read_into(m, ado, dst, d0, n, orr):
    """Memory at ``ado`` (zeros past its end) into ``dst[d0:d0 + n]``; ``orr``: OR it in."""
    for j in range(n):
        a = ado + j
        v = m[a] if a < MEM else 0
        if orr:
            dst[d0 + j] |= v
        else:
            dst[d0 + j] = v


@njit(cache=True, nogil=True)
def _logical(m, st, obuf, olen, oidx, cmd, lad, buf, d0, n, scratch, wkc):
    if cmd == 12:  # LRW: the FMMUs that write take the data as it arrived here
        scratch[:n] = buf[d0:d0 + n]
    read_hit = write_hit = False
    for k in range(r.N_FMMU):
        ls, ll, ps, typ, act = _fmmu(m, k)
        if not (act & 1 and ll and typ):
            continue
        lo, hi = max(lad, ls), min(lad + n, ls + ll)
        if lo >= hi:
            continue
        plo, phi = ps + lo - ls, ps + hi - ls
        if phi > MEM:  # the part past the slave's memory maps to nothing
            hi -= phi - MEM
            phi = MEM
            if lo >= hi:
                continue
        if typ & r.FMMU_WRITE and cmd != 10 and _sm_allows(m, st, plo, phi, r.SM_DIR_WRITE):
            if cmd == 12:
                m[plo:phi] = scratch[lo - lad:hi - lad]
            else:
                m[plo:phi] = buf[d0 + lo - lad:d0 + hi - lad]
            _ram_written(m, st, obuf, olen, oidx, plo, phi)
            write_hit = True
        if typ & r.FMMU_READ and cmd != 11 and _sm_allows(m, st, plo, phi, r.SM_DIR_READ):
            buf[d0 + lo - lad:d0 + hi - lad] = m[plo:phi]
            read_hit = True
    if cmd == 12:
        return wkc + read_hit + 2 * write_hit
    return wkc + (read_hit if cmd == 10 else write_hit)


@njit(cache=True, nogil=True)
def _take_inputs(m, st, ibuf, ilen, iidx):
    slot = take(iidx)
    if slot >= 0:
        start = st[S_IN_START]
        n = min(ilen[slot], MEM - start)
        m[start:start + n] = ibuf[slot, :n]


@njit(cache=True, nogil=True)
def _process(m, st, sii, wmask, obuf, olen, oidx, cmd, adp, ado, buf, d0, n, wkc, scratch):
    """One datagram (data ``buf[d0:d0 + n]``, changed in place) through one slave; returns
    (ADP, WKC) as it leaves. Mirrors :meth:`Esc.process`."""
    if cmd == 1 or cmd == 2 or cmd == 3 or cmd == 13:
        hit = adp == 0
        adp = (adp + 1) & 0xFFFF
    elif cmd == 4 or cmd == 5 or cmd == 6 or cmd == 14:
        hit = adp == _u16(m, r.STATION_ADDRESS) or (
            (m[r.DL_CONTROL + 3] & 1) != 0 and adp == _u16(m, r.STATION_ALIAS))
    elif cmd == 7 or cmd == 8 or cmd == 9:
        hit = True
        adp = (adp + 1) & 0xFFFF
    elif cmd == 10 or cmd == 11 or cmd == 12:
        return adp, _logical(m, st, obuf, olen, oidx, cmd, adp | (ado << 16), buf, d0, n,
                             scratch, wkc)
    else:
        return adp, wkc
    if not hit:
        if cmd == 13 or cmd == 14:
            return adp, wkc + _write(m, st, sii, wmask, obuf, olen, oidx, ado, buf, d0, n)
        return adp, wkc
    if ado < r.DC_END and ado + n > r.DC_START:
        dcc.before_read(m, st, ado, ado + n, st[S_NOW])
    if cmd == 1 or cmd == 4 or cmd == 7:
        _read_into(m, ado, buf, d0, n, cmd == 7)
        return adp, wkc + _mbx_read(m, st, ado, n)
    if cmd == 2 or cmd == 5 or cmd == 8:
        return adp, wkc + _write(m, st, sii, wmask, obuf, olen, oidx, ado, buf, d0, n)
    if cmd == 3 or cmd == 6 or cmd == 9:
        scratch[:n] = buf[d0:d0 + n]
        _read_into(m, ado, buf, d0, n, cmd == 9)
        ok = _mbx_read(m, st, ado, n)
        wrote = _write(m, st, sii, wmask, obuf, olen, oidx, ado, scratch, 0, n)
        return adp, wkc + ok + 2 * wrote
    _read_into(m, ado, buf, d0, n, False)   # ARMW / FRMW: the addressed slave reads
    return adp, wkc + _mbx_read(m, st, ado, n)


# --- the frame --------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _check_pdu(buf, n):
    """End of the EtherCAT PDU in ``buf[:n]`` (from offset 14), or -1 if it does not
    decode (the rules of :func:`protocols.ethercat.decode_pdu`, trailing bytes allowed)."""
    if n < 16:
        return -1
    word = _u16(buf, 14)
    if word >> 12 != 1 or word & 0x0800:
        return -1
    length = word & 0x07FF
    end = 16 + length
    if length == 0 or end > n:
        return -1
    pos = 16
    while True:
        if pos + 10 > end:
            return -1
        if buf[pos] > 14:
            return -1
        lw = _u16(buf, pos + 6)
        if lw & 0x3800:
            return -1
        nxt = pos + 10 + (lw & 0x07FF) + 2
        if nxt > end:
            return -1
        pos = nxt
        if lw & 0x8000:
            if pos == end:
                return -1
        else:
            return end if pos == end else -1


@njit(cache=True, nogil=True)
def handle_frame(buf, n, mem, sii, st, wmask, obuf, olen, oidx, ibuf, ilen, iidx, scratch):
    """The Ethernet frame ``buf[:n]`` through every slave, in place; returns the reply's
    length (``buf[:length]``, padded to 60 bytes), :data:`NOT_ETHERCAT` or
    :data:`DROPPED`. ``buf`` must have room for 60 bytes."""
    if n < 14:
        return NOT_ETHERCAT
    ethertype = (np.int64(buf[12]) << 8) | buf[13]
    if ethertype < 0x0600 or ethertype != 0x88A4:
        return NOT_ETHERCAT
    end = _check_pdu(buf, n)
    if end < 0 or end - 14 > 1500:
        return DROPPED
    n_slaves = mem.shape[0]
    pos = 16
    while pos < end:
        cmd = np.int64(buf[pos])
        adp = _u16(buf, pos + 2)
        ado = _u16(buf, pos + 4)
        dlen = _u16(buf, pos + 6) & 0x07FF
        d0 = pos + 10
        wkc = _u16(buf, d0 + dlen)
        for i in range(n_slaves):
            m, s = mem[i], st[i]
            _take_inputs(m, s, ibuf[i], ilen[i], iidx[i])
            _pdi_mailbox(m, s, obuf[i], olen[i])
            adp, wkc = _process(m, s, sii[i], wmask, obuf[i], olen[i], oidx[i], cmd, adp,
                                ado, buf, d0, dlen, wkc, scratch)
        _put16(buf, pos + 2, adp)
        _put16(buf, d0 + dlen, wkc & 0xFFFF)
        pos = d0 + dlen + 2
    buf[6] |= 0x02   # the source MAC handed back with the locally-administered bit set
    if end < 60:
        buf[end:60] = 0
        end = 60
    return end


@njit(cache=True, nogil=True)
def tick(mem, st, obuf, olen, oidx, dt_ns):
    """Every slave's clock ``dt_ns`` on; in OP a slave whose output buffer was not written
    for its watchdog time trips (outputs safe, SAFEOP + error, code 0x001B), at the first
    watchdog increment of its clock that ends it (:func:`watchdog_expiry`), applied in the
    tick that passes it. Mirrors :meth:`Esc.tick`."""
    for i in range(mem.shape[0]):
        m, s = mem[i], st[i]
        s[S_NOW] += dt_ns
        if s[S_STATE] != _OP or not s[S_OUT_BYTES]:
            continue
        inc = 40 * (_u16(m, r.WD_DIVIDER) + 2)
        wd = inc * _u16(m, r.WD_TIME_PD)
        if not wd or not _sm(m, s[S_OUT_SM])[2] & r.SM_WATCHDOG:
            continue
        expiry = watchdog_expiry(s[S_LAST_OUT], inc, wd)
        if s[S_NOW] >= expiry:
            _put16(m, r.WD_STATUS_PD, 0)
            m[r.WD_COUNTER_PD] = min(np.int64(m[r.WD_COUNTER_PD]) + 1, 0xFF)
            s[S_TRIPS] += 1
            s[S_TRIP_DELAY] = expiry - s[S_LAST_OUT]
            s[S_TRIP_SEEN] = s[S_NOW] - s[S_LAST_OUT]
            _enter(m, s, obuf[i], olen[i], oidx[i], _SAFEOP)
            _refuse(m, s, 0x001B)
    if mem.shape[0]:
        dcc.tick(mem, st, st[0, S_NOW])


@njit(cache=True, nogil=True)
def watchdog_expiry(last_write_ns, increment_ns, watchdog_ns):
    """When [ns of the slave's clock] the process-data watchdog runs out after an output
    write at ``last_write_ns``: an ESC counts it in increments of its divider (40 ns *
    (0x0400 + 2)), which runs free on its clock, so it expires at the first increment
    boundary at least the watchdog time after the write: within [t, t + one increment]
    (ESC datasheet, Section I, "Watchdogs"), whenever the emulator looks."""
    t = last_write_ns + watchdog_ns
    return -(-t // increment_ns) * increment_ns


def watchdog_increment_ns(mem_row: np.ndarray) -> int:
    """One watchdog increment [ns] of a slave (its divider, register 0x0400)."""
    return 40 * ((int(mem_row[r.WD_DIVIDER]) | int(mem_row[r.WD_DIVIDER + 1]) << 8) + 2)


def watchdog_ns(mem_row: np.ndarray) -> int:
    """Process-data watchdog time [ns] of one slave (0: disabled)."""
    div = int(mem_row[r.WD_DIVIDER]) | int(mem_row[r.WD_DIVIDER + 1]) << 8
    t = int(mem_row[r.WD_TIME_PD]) | int(mem_row[r.WD_TIME_PD + 1]) << 8
    return 40 * (div + 2) * t
