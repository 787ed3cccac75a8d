"""With distributed clocks active the boxes' MCU cycles run at the SYNC0 pulses of their
ESC (``serve --transport ethercat``): :meth:`ServedChain.sync0_release` names the pulse,
the box clock releases each cycle there. The slaves' clock runs on the monotonic clock here
as the frame thread runs it (:func:`firmware_model.esc.compiled.tick`)."""

from __future__ import annotations

import time

import numpy as np

from firmware_model.esc import compiled as cc
from firmware_model.esc import dc_compiled as dcc
from hil.fieldbus.esc.master import EscMaster
from hil.fieldbus.esc.serve import PERIOD_NS, BoxClock, ServedChain
from tests.fieldbus.dc_master import config_dc, dcsync0, frmw
from tests.fieldbus.test_esc import THREE


class _Frames:
    """The compiled frame path of a served chain, as the frame thread drives it."""

    def __init__(self, chain: ServedChain) -> None:
        self.a = chain.arrays
        self.buf = np.zeros(2048, dtype=np.uint8)

    def handle(self, frame: bytes) -> bytes | None:
        self.buf[:len(frame)] = np.frombuffer(frame, dtype=np.uint8)
        n = cc.handle_frame(self.buf, len(frame), *self.a.frame_args())
        return None if n < 0 else self.buf[:n].tobytes()

    def tick(self, dt: int) -> None:
        a = self.a
        cc.tick(a.mem, a.st, a.obuf, a.olen, a.oidx, dt)

    def now(self) -> int:
        return int(self.a.st[0, cc.S_NOW])


def _with_sync0(cfg, cycle_ns: int = PERIOD_NS):  # noqa: ANN001, ANN202
    chain = ServedChain(THREE, cfg, "echo")
    frames = _Frames(chain)
    master = EscMaster(frames)
    master.bring_up(to_op=False)
    frames.tick(2_000_000)
    config_dc(master, chain.arrays.n)
    for _ in range(300):
        frames.tick(1_000_000)
        frmw(master)
    for i in range(chain.arrays.n):
        dcsync0(master, i, cycle_ns)
    return chain, frames


def _pulse_at(chain: ServedChain, i: int, wall: int) -> bool:
    """Is a SYNC0 pulse of slave ``i`` due exactly at slaves' time ``wall``?"""
    m, s = chain.arrays.mem[i], chain.arrays.st[i]
    at, before = dcc.system_ns(m, s, wall), dcc.system_ns(m, s, wall - 1)
    start, cyc = int(s[dcc.D_SYNC_START]), int(s[dcc.D_SYNC_CYCLE])
    k = -((start - at) // cyc)    # the first pulse at or after `before`
    return at >= start + k * cyc > before and at >= start


def _off_pulse_ns(chain: ServedChain, i: int, wall: int) -> int:
    """How far [ns of system time] slaves' time ``wall`` is from slave ``i``'s nearest
    SYNC0 pulse."""
    m, s = chain.arrays.mem[i], chain.arrays.st[i]
    at = dcc.system_ns(m, s, wall)
    start, cyc = int(s[dcc.D_SYNC_START]), int(s[dcc.D_SYNC_CYCLE])
    d = (at - start) % cyc
    return min(d, cyc - d)


def test_without_dc_the_box_clock_keeps_its_own_grid(cfg):
    chain = ServedChain(THREE, cfg, "echo")
    assert chain.sync0_release(0) is None


def test_sync0_release_is_the_next_pulse_of_the_esc(cfg):
    chain, frames = _with_sync0(cfg)
    chain.t0 = 5_000_000_000
    frames.tick(150_000_000)   # past SOEM's 100 ms start delay
    rel = chain.sync0_release(chain.t0 + frames.now())
    assert rel is not None and rel > chain.t0 + frames.now()
    assert _pulse_at(chain, 0, rel - chain.t0)
    # the other slaves' pulses within 100 ns (their clocks are synchronised)
    nxt = [int(chain.arrays.st[i, dcc.D_NEXT_SYNC0]) for i in range(chain.arrays.n)]
    assert max(nxt) - min(nxt) < 100
    # asked after that pulse: the one a cycle later
    rel2 = chain.sync0_release(rel)
    assert abs(rel2 - rel - PERIOD_NS) < 1_000


def test_sync0_of_another_cycle_leaves_the_box_on_its_grid(cfg):
    chain, frames = _with_sync0(cfg, cycle_ns=2 * PERIOD_NS)
    frames.tick(150_000_000)
    assert int(chain.arrays.st[0, dcc.D_SYNC_CYCLE]) == 2 * PERIOD_NS
    assert chain.sync0_release(frames.now()) is None


def test_box_clock_runs_the_box_cycles_at_sync0(cfg):
    chain, frames = _with_sync0(cfg)
    frames.tick(150_000_000)
    releases, begins = [], []
    t0 = time.monotonic_ns() - frames.now()   # the slaves' zero on the monotonic clock
    chain.t0 = t0

    def sync0(after: int) -> int | None:
        frames.tick(max(time.monotonic_ns() - t0 - frames.now(), 0))  # the frame thread
        rel = chain.sync0_release(after)
        releases.append(rel)
        return rel

    def cycle(since: int, at: int) -> None:
        assert at == releases[-1] and since < at  # the pulse is the cycle's release
        begins.append((time.monotonic_ns(), releases[-1]))
        chain.cycle(since, at)

    clock = BoxClock(cycle, sync0=sync0)
    clock.begin(t0)
    while clock.stats.cycles < 20:
        time.sleep(0.005)
    clock.stop()
    assert clock.error is None
    st = clock.stats
    assert st.sync0_cycles == st.cycles >= 20
    for begin, rel in begins:
        assert begin >= rel                            # not before its pulse
        # at a pulse of the ESC (stepped on from the frame thread's last look at it by
        # whole cycles of the wall clock: the crystal's 50 ppm make < 100 ns)
        assert _off_pulse_ns(chain, 0, rel - t0) < 100
    gaps = np.diff([rel for _b, rel in begins])
    pulses = (gaps + PERIOD_NS // 2) // PERIOD_NS
    assert pulses.min() == 1          # one cycle per pulse, never two at one pulse
    if st.slipped_cycles == 0:        # (a stall of this process > 50 ms skips pulses)
        assert set(pulses) == {1}
