"""Distributed clocks of one ESC (the readable model; the compiled frame path mirrors it in
:mod:`firmware_model.esc.dc_compiled`, tested equal).

Time: the frame side gives every event a wall time ``t`` [ns] (the slaves' clock of
:meth:`Esc.tick`, on ``serve`` the monotonic clock). A frame reaches port 0 of slave ``i``
at ``t + arrive_ns`` (``arrive_ns``: the simulated propagation delay from slave 0) and,
coming back from the slaves behind it, its port 1 ``return_ns`` later. Each slave counts
its own **local time** on a crystal that runs ``drift_ppb`` fast::

    local(t) = phase_ns + t + floor(t * drift_ppb / 1e9)

and keeps a **local copy of the system time** (register 0x0910)::

    system(t) = local(t) + offset (0x0920) + correction(t)

``correction`` is what the time control loop has added: it runs ``freq`` ppb faster since
the loop's last update, and slews the phase correction it decided at the last compare
(``slew``) at up to 1000 ppm until it is done. Everything is integer arithmetic on
64-bit words (wrapping), so the compiled path gives the same bits.

Registers (ETG.1000.4 / ESC datasheets), as this model answers them:

* 0x0900: a write latches, for that frame, the local time at port 0 and (if open) port 1
  into 0x0900/0x0904 (32 bit) and the processing unit's into 0x0918 (64 bit).
* 0x0910 read: the system time at which the frame passed the reference clock, i.e. the
  local copy at this slave's start of frame minus the delay 0x0928. A write (at least the
  first byte) is compared with it: ``diff = copy - delay - written`` (64 bit if all 8 bytes
  are written, else the low 32 bits) feeds the time control loop.
* The time control loop (a model of the ESC's, not its gate-level arithmetic): a filtered
  difference (0x0934 filter depth: exponential average with weight 2**-depth, shown in
  0x092C as sign and magnitude) drives a proportional-integral correction. Per compare the
  clock slews ``-diff / Np`` of phase (at up to 1000 ppm, then stops: a master that stalls
  between compares does not make it overshoot) and its frequency correction moves by
  ``-diff / (Nf * h)``, ``h`` the local time since the previous compare (compares closer
  than 100 us correct only the phase), ``Np = start >> 9`` and ``Nf = start >> 4`` from the
  speed counter start 0x0930 (0x1000: Np 8, Nf 256, about critically damped); the
  frequency correction is limited to +-1000 ppm. A write to 0x0930 resets the loop (and
  0x092C, 0x0932).
* SYNC0: with 0x0981 = cyclic operation + SYNC0 (bits 0, 1), pulses at system times
  ``start + k * cycle`` (0x0990, 0x09A0). The box's MCU samples at these pulses.

Writes out of order get the ESC's answer, each counted (:attr:`DcUnit.errors`, the code of
the last in :attr:`DcUnit.last_error`): a start time (0x0990) or SYNC0 cycle (0x09A0) written
while cyclic operation is on is ignored; an activation while 0x0980 gives the sync unit to
the PDI is ignored; an activation whose start time is not in the future never fires (the
64-bit start time is never reached again) unless the start plausibility check (0x0981 bit
5) is on, which starts at the next cycle boundary and sets 0x0984 bit 2.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from firmware_model.esc import registers as r

NS = 1_000_000_000
#: The loop's frequency correction and its phase slew are limited to this [ppb] (1000 ppm).
MAX_RATE_PPB = 1_000_000
#: Compares closer than this [ns, local] to the previous one leave the frequency alone.
MIN_H_NS = 100_000
#: The compared difference is limited to this [ns] (the magnitude 0x092C can show).
MAX_DIFF_NS = 0x7FFFFFFF
#: The local time between two compares the loop divides by is capped at this [ns].
MAX_H_NS = 1 << 40
#: SYNC0 pulses further ahead than this [ns] are not scheduled yet (looked at again later).
MAX_AHEAD_NS = NS
SPEED_START_DEFAULT = 0x1000
DIFF_FILTER_DEFAULT = 0x04
SPEED_FILTER_DEFAULT = 0x0C

# SYNC unit states.
SYNC_OFF, SYNC_RUNNING, SYNC_NEVER = 0, 1, 2
# Out-of-order writes (codes of the last one; each counted).
ERR_START_WHILE_ACTIVE = 1   # 0x0990 written with cyclic operation on: ignored
ERR_CYCLE_WHILE_ACTIVE = 2   # 0x09A0 written with cyclic operation on: ignored
ERR_START_IN_PAST = 3        # activated with a start time not in the future
ERR_PDI_OWNS_SYNC = 4        # 0x0981 written while 0x0980 gives the sync unit to the PDI
ERROR_NAMES = {0: "none", ERR_START_WHILE_ACTIVE: "start time written while active",
               ERR_CYCLE_WHILE_ACTIVE: "SYNC0 cycle written while active",
               ERR_START_IN_PAST: "activated with a start time not in the future",
               ERR_PDI_OWNS_SYNC: "activation while the PDI owns the sync unit"}

_I64 = struct.Struct("<q")
_U32 = struct.Struct("<I")
_U16 = struct.Struct("<H")


def wrap64(x: int) -> int:
    """``x`` as a signed 64-bit word (two's complement wrap, as the compiled path)."""
    return ((x + (1 << 63)) & ((1 << 64) - 1)) - (1 << 63)


@dataclass(frozen=True)
class DcParams:
    """One slave's clock and place on the line (static)."""

    drift_ppb: int = 0       # crystal error [ppb] (+: runs fast)
    phase_ns: int = 0        # local time at t = 0
    arrive_ns: int = 0       # frame at port 0, after it reached slave 0's [ns]
    return_ns: int = 0       # port 1 receive after port 0 receive [ns]; 0: port 1 closed


def dc_line(n: int, drift_ppm: tuple[float, ...] | float = 50.0, hop_ns: int = 500,
            phase_step_ns: int = 1_234_567) -> list[DcParams]:
    """Clocks and delays of a line of ``n`` slaves. ``drift_ppm``: one per slave, or one
    value X for +X, -X, +X, ... along the line. ``hop_ns``: the delay from one slave's port
    0 to the next one's (its forwarding through the ESC plus the cable), the same both
    ways: port 1 of slave ``i`` hears the frame back ``2 * hop_ns`` per slave behind it
    after port 0 did. So a master's estimate from the port times (half the difference of
    the round trips) is exact up to the clocks' drift over the round trip. Slave ``i``
    powered up ``i * phase_step_ns`` after slave 0 (its local time starts behind)."""
    if isinstance(drift_ppm, (int, float)):
        drifts = [drift_ppm * (1 if i % 2 == 0 else -1) for i in range(n)]
    else:
        drifts = list(drift_ppm)
        if len(drifts) != n:
            raise ValueError(f"{len(drifts)} drifts for {n} slaves")
    if any(abs(d) > 500 for d in drifts):
        raise ValueError(f"a drift of more than 500 ppm: {drifts}")
    if hop_ns < 0:
        raise ValueError(f"hop delay {hop_ns} ns is negative")
    out = []
    for i in range(n):
        # round trip from port 0 of slave i back to it: two hops per slave behind it, and
        # the loop-back of the last one; port 1 hears it back after that minus one hop.
        behind = n - 1 - i
        ret = 2 * behind * hop_ns if behind else 0
        out.append(DcParams(round(drifts[i] * 1000), -i * phase_step_ns, i * hop_ns, ret))
    return out


def local_ns(p: DcParams, t: int) -> int:
    return wrap64(p.phase_ns + t + wrap64(t * p.drift_ppb) // NS)


class DcUnit:
    """The DC state of one ESC beside its memory (registers live in ``mem``)."""

    def __init__(self, params: DcParams | None = None) -> None:
        self.p = params or DcParams()
        self.corr_u = 0      # correction [1e-9 ns] up to local time l_upd
        self.l_upd = 0
        self.slew = 0        # phase correction still to apply [1e-9 ns]
        self.freq = 0        # [ppb] integral part
        self.l_cmp = 0       # local time of the last compare
        self.diff_f = 0      # filtered difference [ns]
        self.compares = 0
        self.errors = 0
        self.last_error = 0
        self.sync_state = SYNC_OFF
        self.sync_start = 0
        self.sync_cycle = 0
        self.next_sync0 = -1  # wall time of the next SYNC0 pulse, -1: none

    @staticmethod
    def reset(mem: bytearray) -> None:
        m = mem
        _U16.pack_into(m, r.DC_SPEED_START, SPEED_START_DEFAULT)
        m[r.DC_DIFF_FILTER] = DIFF_FILTER_DEFAULT
        m[r.DC_SPEED_FILTER] = SPEED_FILTER_DEFAULT

    # --- the clock ---------------------------------------------------------------------------
    def _slewed(self, dt: int) -> int:
        """Of the pending slew, what ``dt`` local ns apply [1e-9 ns]."""
        if dt <= 0 or self.slew == 0:
            return 0
        step = MAX_RATE_PPB * min(dt, MAX_H_NS)
        return min(self.slew, step) if self.slew > 0 else max(self.slew, -step)

    def _corr_u(self, loc: int) -> int:
        dt = wrap64(loc - self.l_upd)
        return wrap64(self.corr_u + self.freq * dt + self._slewed(dt))

    def system_ns(self, mem: bytearray, t: int) -> int:
        loc = local_ns(self.p, t)
        off = _I64.unpack_from(mem, r.DC_SYSTEM_OFFSET)[0]
        return wrap64(loc + off + self._corr_u(loc) // NS)

    def _settle(self, loc: int) -> None:
        """The correction accumulated up to local time ``loc`` (before the loop changes)."""
        dt = wrap64(loc - self.l_upd)
        self.corr_u = self._corr_u(loc)
        self.slew -= self._slewed(dt)
        self.l_upd = loc

    # --- frame events --------------------------------------------------------------------------
    def before_read(self, mem: bytearray, ado: int, end: int, now: int) -> None:
        """Refresh the registers a read of [ado, end) sees at this frame."""
        t = now + self.p.arrive_ns
        if ado < r.DC_SYSTEM_TIME + 8 and end > r.DC_SYSTEM_TIME:
            delay = _U32.unpack_from(mem, r.DC_SYSTEM_DELAY)[0]
            _I64.pack_into(mem, r.DC_SYSTEM_TIME, wrap64(self.system_ns(mem, t) - delay))
        if ado < r.DC_START_TIME + 8 and end > r.DC_START_TIME and \
                self.sync_state == SYNC_RUNNING:
            _I64.pack_into(mem, r.DC_START_TIME, self._next_pulse(self.system_ns(mem, t)))

    def _next_pulse(self, sys_now: int) -> int:
        """System time of the first pulse at or after ``sys_now``."""
        start, cyc = self.sync_start, self.sync_cycle
        d = wrap64(sys_now - start)
        if d <= 0 or cyc <= 0:
            return start
        k = d // cyc + (1 if d % cyc else 0)
        return wrap64(start + k * cyc)

    def written(self, mem: bytearray, ado: int, end: int, data: bytes, now: int) -> None:
        """The master wrote ``data`` at [ado, end) (DC registers the write mask let through
        are already in ``mem``)."""
        t = now + self.p.arrive_ns

        def has(a: int) -> bool:
            return ado <= a < end

        if has(r.DC_RECV_TIME_P0):
            loc = local_ns(self.p, t)
            _U32.pack_into(mem, r.DC_RECV_TIME_P0, loc & 0xFFFFFFFF)
            if self.p.return_ns:
                _U32.pack_into(mem, r.DC_RECV_TIME_P1,
                               local_ns(self.p, t + self.p.return_ns) & 0xFFFFFFFF)
            _I64.pack_into(mem, r.DC_RECV_TIME_PU, loc)
        if has(r.DC_SYSTEM_TIME):
            self._compare(mem, ado, end, data, t)
        if ado < r.DC_SPEED_START + 2 and end > r.DC_SPEED_START:
            self._settle(local_ns(self.p, t))
            self.slew = self.freq = self.diff_f = 0
            _U32.pack_into(mem, r.DC_SYSTEM_DIFF, 0)
            _U16.pack_into(mem, r.DC_SPEED_DIFF, 0)
        if has(r.DC_ACTIVATION):
            self._activate(mem, data[r.DC_ACTIVATION - ado], t)
        active = mem[r.DC_ACTIVATION] & 1
        if ado < r.DC_START_TIME + 8 and end > r.DC_START_TIME:
            if active:
                self._error(ERR_START_WHILE_ACTIVE)
            else:
                for a in range(max(ado, r.DC_START_TIME), min(end, r.DC_START_TIME + 8)):
                    mem[a] = data[a - ado]
        if ado < r.DC_SYNC0_CYCLE + 4 and end > r.DC_SYNC0_CYCLE:
            if active:
                self._error(ERR_CYCLE_WHILE_ACTIVE)
            else:
                for a in range(max(ado, r.DC_SYNC0_CYCLE), min(end, r.DC_SYNC0_CYCLE + 4)):
                    mem[a] = data[a - ado]

    def _error(self, code: int) -> None:
        self.errors += 1
        self.last_error = code

    def _compare(self, mem: bytearray, ado: int, end: int, data: bytes, t: int) -> None:
        sys_t = self.system_ns(mem, t)
        delay = _U32.unpack_from(mem, r.DC_SYSTEM_DELAY)[0]
        copy = wrap64(sys_t - delay)
        got = bytearray(_I64.pack(copy))
        for a in range(r.DC_SYSTEM_TIME, min(end, r.DC_SYSTEM_TIME + 8)):
            got[a - r.DC_SYSTEM_TIME] = data[a - ado]
        if end >= r.DC_SYSTEM_TIME + 8:
            diff = wrap64(copy - _I64.unpack(got)[0])
        else:  # 32-bit compare
            d = (copy - _I64.unpack(got)[0]) & 0xFFFFFFFF
            diff = d - (1 << 32) if d & 0x80000000 else d
        diff = max(-MAX_DIFF_NS, min(MAX_DIFF_NS, diff))
        depth = mem[r.DC_DIFF_FILTER] & 0x0F
        self.diff_f += (diff - self.diff_f) >> depth
        f = self.diff_f
        _U32.pack_into(mem, r.DC_SYSTEM_DIFF, (0x80000000 | -f) if f < 0 else f)
        loc = local_ns(self.p, t)
        h = min(max(wrap64(loc - self.l_cmp), 1), MAX_H_NS)
        self.l_cmp = loc
        self._settle(loc)
        start = _U16.unpack_from(mem, r.DC_SPEED_START)[0] & 0x7FFF
        n_p, n_f = max(start >> 9, 1), max(start >> 4, 8)
        lim = MAX_RATE_PPB
        if h >= MIN_H_NS:
            self.freq = max(-lim, min(lim, self.freq - (f * NS) // (n_f * h)))
        self.slew = -(f * NS) // n_p
        _U16.pack_into(mem, r.DC_SPEED_DIFF, max(-32768, min(32767, self.freq // 100)) & 0xFFFF)
        self.compares += 1

    def _activate(self, mem: bytearray, value: int, t: int) -> None:
        if mem[r.DC_CYCLIC_CONTROL] & 1:
            self._error(ERR_PDI_OWNS_SYNC)
            return
        mem[r.DC_ACTIVATION] = value
        self.sync_state, status = SYNC_OFF, 0
        if value & 0x03 == 0x03:
            start = _I64.unpack_from(mem, r.DC_START_TIME)[0]
            cyc = _U32.unpack_from(mem, r.DC_SYNC0_CYCLE)[0]
            sys_t = self.system_ns(mem, t)
            self.sync_start, self.sync_cycle = start, cyc
            if start > sys_t:
                self.sync_state, status = SYNC_RUNNING, 1
            elif value & 0x20:   # plausibility check: start at the next cycle boundary
                self.sync_start = self._next_pulse(sys_t) if cyc else sys_t
                if self.sync_start <= sys_t:
                    self.sync_start = wrap64(self.sync_start + max(cyc, 1))
                self.sync_state, status = SYNC_RUNNING, 1 | 4
            else:
                self.sync_state = SYNC_NEVER
                self._error(ERR_START_IN_PAST)
        mem[r.DC_ACTIVATION_STATUS] = status
        self.next_sync0 = self.next_pulse_wall(mem, t)

    # --- SYNC0 for the box ---------------------------------------------------------------------
    def next_pulse_wall(self, mem: bytearray, t: int) -> int:
        """Wall time of the first SYNC0 pulse at or after wall time ``t`` (-1: none; a
        single pulse (cycle 0) counts only before it happened)."""
        if self.sync_state != SYNC_RUNNING:
            return -1
        sys_t = self.system_ns(mem, t)
        ahead = wrap64(self._next_pulse(sys_t) - sys_t)
        if ahead < 0 or ahead > MAX_AHEAD_NS:   # the single pulse passed, or not yet near
            return -1
        # invert system(w) = target: a first guess at the clock's speed, then to the ns
        target = wrap64(sys_t + ahead)
        speed = NS + self.p.drift_ppb + self.freq
        w = t + (ahead * NS) // speed
        for _ in range(3):   # the slew still pending moves it by up to its amount
            w += (wrap64(target - self.system_ns(mem, w)) * NS) // speed
        for _ in range(64):
            if self.system_ns(mem, w) >= target:
                break
            w += 1
        for _ in range(64):
            if w <= t or self.system_ns(mem, w - 1) < target:
                break
            w -= 1
        return w

    def tick(self, mem: bytearray, now: int) -> None:
        """The slave's clock is at ``now``: the next SYNC0 pulse's wall time is refreshed."""
        if self.sync_state == SYNC_RUNNING:
            self.next_sync0 = self.next_pulse_wall(mem, now)
