"""Distributed clocks in the compiled frame path: :class:`firmware_model.esc.dc.DcUnit` as
functions over one slave's memory ``m`` and state row ``s`` (the columns from
:data:`DC_BASE` of ``EscArrays.st``), tested equal to it. Same integer arithmetic, the
same wrapping 64-bit words."""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.esc import registers as r
from firmware_model.esc.dc import (
    DIFF_FILTER_DEFAULT,
    ERR_CYCLE_WHILE_ACTIVE,
    ERR_PDI_OWNS_SYNC,
    ERR_START_IN_PAST,
    ERR_START_WHILE_ACTIVE,
    MAX_AHEAD_NS,
    MAX_DIFF_NS,
    MAX_H_NS,
    MAX_RATE_PPB,
    MIN_H_NS,
    NS,
    SPEED_FILTER_DEFAULT,
    SPEED_START_DEFAULT,
    SYNC_NEVER,
    SYNC_OFF,
    SYNC_RUNNING,
    DcParams,
)

#: First DC column of the per-slave state rows (after the ESC's own words).
DC_BASE = 23   # after the mailbox columns (S_OUT_SM..S_MBX1_LEN = 15..22)
(D_DRIFT, D_PHASE, D_ARRIVE, D_RETURN, D_CORR_U, D_L_UPD, D_SLEW, D_FREQ, D_L_CMP, D_DIFF_F,
 D_COMPARES, D_ERRORS, D_LAST_ERROR, D_SYNC_STATE, D_SYNC_START, D_SYNC_CYCLE, D_NEXT_SYNC0,
 D_SPREAD) = range(DC_BASE, DC_BASE + 18)
#: Columns in all (the state row's length).
DC_END = DC_BASE + 18


def init_row(m: np.ndarray, s: np.ndarray, p: DcParams) -> None:
    """A slave's DC columns and registers at reset."""
    s[D_DRIFT], s[D_PHASE], s[D_ARRIVE], s[D_RETURN] = (p.drift_ppb, p.phase_ns, p.arrive_ns,
                                                        p.return_ns)
    s[D_NEXT_SYNC0] = -1
    m[r.DC_SPEED_START] = SPEED_START_DEFAULT & 0xFF
    m[r.DC_SPEED_START + 1] = SPEED_START_DEFAULT >> 8
    m[r.DC_DIFF_FILTER] = DIFF_FILTER_DEFAULT
    m[r.DC_SPEED_FILTER] = SPEED_FILTER_DEFAULT


def slave_report(m: np.ndarray, s: np.ndarray) -> dict:
    """What a master set on one slave (delay, offset, SYNC0) beside its simulated clock, the
    loop's compares and the out-of-order writes (for a run's report)."""
    from firmware_model.esc.dc import ERROR_NAMES

    return {"drift_ppm": int(s[D_DRIFT]) / 1000, "simulated_delay_ns": int(s[D_ARRIVE]),
            "delay_ns": int(_get32(m, r.DC_SYSTEM_DELAY)),
            "offset_set": bool(m[r.DC_SYSTEM_OFFSET:r.DC_SYSTEM_OFFSET + 8].any()),
            "compares": int(s[D_COMPARES]), "sync0": int(s[D_SYNC_STATE]) == SYNC_RUNNING,
            "sync0_cycle_ns": int(s[D_SYNC_CYCLE]),
            "out_of_order_writes": int(s[D_ERRORS]),
            "last_out_of_order": ERROR_NAMES.get(int(s[D_LAST_ERROR]), "?")}


@njit(cache=True, nogil=True, inline="always")
def _get64(m, o):
    v = np.int64(0)
    for j in range(8):
        v |= np.int64(m[o + j]) << (8 * j)
    return v


@njit(cache=True, nogil=True, inline="always")
def _put64(m, o, v):
    for j in range(8):
        m[o + j] = (v >> (8 * j)) & 0xFF


@njit(cache=True, nogil=True, inline="always")
def _get32(m, o):
    return (np.int64(m[o]) | (np.int64(m[o + 1]) << 8) | (np.int64(m[o + 2]) << 16)
            | (np.int64(m[o + 3]) << 24))


@njit(cache=True, nogil=True, inline="always")
def _put32(m, o, v):
    for j in range(4):
        m[o + j] = (v >> (8 * j)) & 0xFF


@njit(cache=True, nogil=True)
def local_ns(s, t):
    return s[D_PHASE] + t + (t * s[D_DRIFT]) // NS


@njit(cache=True, nogil=True)
def _slewed(s, dt):
    slew = s[D_SLEW]
    if dt <= 0 or slew == 0:
        return np.int64(0)
    step = MAX_RATE_PPB * min(dt, MAX_H_NS)
    return min(slew, step) if slew > 0 else max(slew, -step)


@njit(cache=True, nogil=True)
def _corr_u(s, loc):
    dt = loc - s[D_L_UPD]
    return s[D_CORR_U] + s[D_FREQ] * dt + _slewed(s, dt)


@njit(cache=True, nogil=True)
def system_ns(m, s, t):
    loc = local_ns(s, t)
    return loc + _get64(m, r.DC_SYSTEM_OFFSET) + _corr_u(s, loc) // NS


@njit(cache=True, nogil=True)
def _settle(s, loc):
    dt = loc - s[D_L_UPD]
    c = _corr_u(s, loc)
    s[D_SLEW] = s[D_SLEW] - _slewed(s, dt)
    s[D_CORR_U] = c
    s[D_L_UPD] = loc


@njit(cache=True, nogil=True)
def _next_pulse(s, sys_now):
    start, cyc = s[D_SYNC_START], s[D_SYNC_CYCLE]
    d = sys_now - start
    if d <= 0 or cyc <= 0:
        return start
    k = d // cyc + (1 if d % cyc else 0)
    return start + k * cyc


@njit(cache=True, nogil=True)
def before_read(m, s, ado, end, now):
    t = now + s[D_ARRIVE]
    if ado < r.DC_SYSTEM_TIME + 8 and end > r.DC_SYSTEM_TIME:
        _put64(m, r.DC_SYSTEM_TIME, system_ns(m, s, t) - _get32(m, r.DC_SYSTEM_DELAY))
    if ado < r.DC_START_TIME + 8 and end > r.DC_START_TIME and s[D_SYNC_STATE] == SYNC_RUNNING:
        _put64(m, r.DC_START_TIME, _next_pulse(s, system_ns(m, s, t)))


@njit(cache=True, nogil=True)
def _error(s, code):
    s[D_ERRORS] += 1
    s[D_LAST_ERROR] = code


@njit(cache=True, nogil=True)
def _compare(m, s, ado, end, src, s0, t):
    copy = system_ns(m, s, t) - _get32(m, r.DC_SYSTEM_DELAY)
    got = copy
    for a in range(r.DC_SYSTEM_TIME, min(end, r.DC_SYSTEM_TIME + 8)):
        sh = 8 * (a - r.DC_SYSTEM_TIME)
        got = (got & ~(np.int64(0xFF) << sh)) | (np.int64(src[s0 + a - ado]) << sh)
    if end >= r.DC_SYSTEM_TIME + 8:
        diff = copy - got
    else:
        d = (copy - got) & 0xFFFFFFFF
        diff = d - (np.int64(1) << 32) if d & 0x80000000 else d
    diff = max(-MAX_DIFF_NS, min(MAX_DIFF_NS, diff))
    depth = m[r.DC_DIFF_FILTER] & 0x0F
    s[D_DIFF_F] += (diff - s[D_DIFF_F]) >> depth
    f = s[D_DIFF_F]
    _put32(m, r.DC_SYSTEM_DIFF, (0x80000000 | -f) if f < 0 else f)
    loc = local_ns(s, t)
    h = min(max(loc - s[D_L_CMP], 1), MAX_H_NS)
    s[D_L_CMP] = loc
    _settle(s, loc)
    start = (np.int64(m[r.DC_SPEED_START]) | (np.int64(m[r.DC_SPEED_START + 1]) << 8)) & 0x7FFF
    n_p, n_f = max(start >> 9, 1), max(start >> 4, 8)
    lim = MAX_RATE_PPB
    if h >= MIN_H_NS:
        s[D_FREQ] = max(-lim, min(lim, s[D_FREQ] - (f * NS) // (n_f * h)))
    s[D_SLEW] = -(f * NS) // n_p
    sd = max(-32768, min(32767, s[D_FREQ] // 100)) & 0xFFFF
    m[r.DC_SPEED_DIFF] = sd & 0xFF
    m[r.DC_SPEED_DIFF + 1] = sd >> 8
    s[D_COMPARES] += 1


@njit(cache=True, nogil=True)
def next_pulse_wall(m, s, t):
    """Wall time of the first SYNC0 pulse at or after ``t`` (-1: none)."""
    if s[D_SYNC_STATE] != SYNC_RUNNING:
        return -1
    sys_t = system_ns(m, s, t)
    ahead = _next_pulse(s, sys_t) - sys_t
    if ahead < 0 or ahead > MAX_AHEAD_NS:
        return -1
    target = sys_t + ahead
    speed = NS + s[D_DRIFT] + s[D_FREQ]
    w = t + (ahead * NS) // speed
    for _ in range(3):
        w += ((target - system_ns(m, s, w)) * NS) // speed
    for _ in range(64):
        if system_ns(m, s, w) >= target:
            break
        w += 1
    for _ in range(64):
        if w <= t or system_ns(m, s, w - 1) < target:
            break
        w -= 1
    return w


@njit(cache=True, nogil=True)
def _activate(m, s, value, t):
    if m[r.DC_CYCLIC_CONTROL] & 1:
        _error(s, ERR_PDI_OWNS_SYNC)
        return
    m[r.DC_ACTIVATION] = value
    s[D_SYNC_STATE] = SYNC_OFF
    status = 0
    if value & 0x03 == 0x03:
        start = _get64(m, r.DC_START_TIME)
        cyc = _get32(m, r.DC_SYNC0_CYCLE)
        sys_t = system_ns(m, s, t)
        s[D_SYNC_START] = start
        s[D_SYNC_CYCLE] = cyc
        if start > sys_t:
            s[D_SYNC_STATE] = SYNC_RUNNING
            status = 1
        elif value & 0x20:
            s[D_SYNC_START] = _next_pulse(s, sys_t) if cyc else sys_t
            if s[D_SYNC_START] <= sys_t:
                s[D_SYNC_START] = s[D_SYNC_START] + max(cyc, 1)
            s[D_SYNC_STATE] = SYNC_RUNNING
            status = 1 | 4
        else:
            s[D_SYNC_STATE] = SYNC_NEVER
            _error(s, ERR_START_IN_PAST)
    m[r.DC_ACTIVATION_STATUS] = status
    s[D_NEXT_SYNC0] = next_pulse_wall(m, s, t)


@njit(cache=True, nogil=True)
def written(m, s, ado, end, src, s0, now):
    """The master wrote ``src[s0:s0 + end - ado]`` at [ado, end); mirrors
    :meth:`DcUnit.written`."""
    t = now + s[D_ARRIVE]
    if ado <= r.DC_RECV_TIME_P0 < end:
        loc = local_ns(s, t)
        _put32(m, r.DC_RECV_TIME_P0, loc & 0xFFFFFFFF)
        if s[D_RETURN]:
            _put32(m, r.DC_RECV_TIME_P1, local_ns(s, t + s[D_RETURN]) & 0xFFFFFFFF)
        _put64(m, r.DC_RECV_TIME_PU, loc)
    if ado <= r.DC_SYSTEM_TIME < end:
        _compare(m, s, ado, end, src, s0, t)
    if ado < r.DC_SPEED_START + 2 and end > r.DC_SPEED_START:
        _settle(s, local_ns(s, t))
        s[D_SLEW] = 0
        s[D_FREQ] = 0
        s[D_DIFF_F] = 0
        _put32(m, r.DC_SYSTEM_DIFF, 0)
        m[r.DC_SPEED_DIFF] = 0
        m[r.DC_SPEED_DIFF + 1] = 0
    if ado <= r.DC_ACTIVATION < end:
        _activate(m, s, np.int64(src[s0 + r.DC_ACTIVATION - ado]), t)
    active = m[r.DC_ACTIVATION] & 1
    if ado < r.DC_START_TIME + 8 and end > r.DC_START_TIME:
        if active:
            _error(s, ERR_START_WHILE_ACTIVE)
        else:
            for a in range(max(ado, r.DC_START_TIME), min(end, r.DC_START_TIME + 8)):
                m[a] = src[s0 + a - ado]
    if ado < r.DC_SYNC0_CYCLE + 4 and end > r.DC_SYNC0_CYCLE:
        if active:
            _error(s, ERR_CYCLE_WHILE_ACTIVE)
        else:
            for a in range(max(ado, r.DC_SYNC0_CYCLE), min(end, r.DC_SYNC0_CYCLE + 4)):
                m[a] = src[s0 + a - ado]


@njit(cache=True, nogil=True)
def tick(mem, st, now):
    """Every slave's next SYNC0 pulse refreshed at wall time ``now``; row 0's
    :data:`D_SPREAD`: the largest difference [ns] between the system time of a slave the
    master gave an offset (or the reference, slave 0) and slave 0's, at ``now`` (the truth
    the model knows, what drift compensation must keep small)."""
    ref = system_ns(mem[0], st[0], now)
    spread = 0
    for i in range(mem.shape[0]):
        m, s = mem[i], st[i]
        if s[D_SYNC_STATE] == SYNC_RUNNING:
            s[D_NEXT_SYNC0] = next_pulse_wall(m, s, now)
        if i and _get64(m, r.DC_SYSTEM_OFFSET) != 0:
            spread = max(spread, abs(system_ns(m, s, now) - ref))
    st[0, D_SPREAD] = spread
