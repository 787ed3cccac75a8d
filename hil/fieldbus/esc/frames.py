"""The frame path of ``serve --transport ethercat``: one thread that receives each EtherCAT
frame from the raw socket, passes it through every slave
(:func:`firmware_model.esc.compiled.handle_frame`) and sends it back, all in compiled code
that never takes the interpreter lock: no Python runs per frame, and no box model, however
slow, can hold a frame up.

The loop calls the C library directly (``poll``, ``recv``, ``send``, ``clock_gettime``,
``ioctl(SIOCGSTAMPNS)``); it wakes when a frame arrives, or every :data:`POLL_MS` to run the
slaves' clock (their process-data watchdogs, on the wall clock as an ESC's) and to look at
its stop word. Per answered frame it measures the reply time: from the kernel's receive
time stamp of the frame to the return of ``send`` (so the wake-up of this thread counts),
into a 1 us histogram.

It also keeps the distributed clocks' truth on the slaves' clock: at every wake-up the
slaves' system-time spread (:func:`firmware_model.esc.dc_compiled.tick`), its largest per
:data:`SPREAD_WINDOW_NS` of the slaves' clock, in a ring (:meth:`FrameThread.dc_spread`).
Kept here, not by the box thread: the boxes' cycles fall behind wall time on a loaded
machine, so a record per so many box cycles drifts off the times it claims to cover.
"""

from __future__ import annotations

import socket
import threading

import numpy as np
from numba import njit, types

from firmware_model.esc.compiled import (
    DROPPED,
    NOT_ETHERCAT,
    S_NOW,
    EscArrays,
    handle_frame,
    tick,
)
from firmware_model.esc.dc_compiled import D_SPREAD
from hil.fieldbus.reply_times import HIST_US
from hil.sim.cpu_account import run_delay_ns

POLL_MS = 1
SIOCGSTAMPNS = 0x8907
SOL_PACKET, PACKET_IGNORE_OUTGOING = 263, 23
CLOCK_REALTIME, CLOCK_MONOTONIC = 0, 1
MSG_DONTWAIT = 0x40

# Words of the control / statistics arrays shared with Python.
C_STOP, C_T0, C_LATE_NS = 0, 1, 2
N_CTL = 3
(F_RECEIVED, F_ANSWERED, F_OTHER, F_DROPPED, F_LATE, F_SEND_ERRORS, F_MAX_NS,
 F_RECV_ERRORS, F_NO_STAMP, F_ERRNO, F_MAX_GAP_NS, F_MAX_WORK_NS, F_SPREAD_WINDOWS) = range(13)
N_STATS = 13
#: Windows of the slaves' clock [ns] the DC spread record keeps its largest value per.
SPREAD_WINDOW_NS = 100_000_000
#: Windows the ring holds (about 55 min); a window the thread never woke in holds -1.
SPREAD_RING = 1 << 15
#: Late replies logged (the first ones), each (L_AT, L_REPLY, L_WAKE, L_WORK) in ns.
LATE_LOG = 256
L_AT, L_REPLY, L_WAKE, L_WORK = range(4)

# The C library's functions, linked by name (cacheable, unlike ctypes pointers); pointers
# pass as intp (arrays hand their address).
_poll = types.ExternalFunction("poll", types.int32(types.intp, types.uint64, types.int32))
_recv = types.ExternalFunction("recv", types.intp(types.int32, types.intp, types.uintp,
                                                  types.int32))
_send = types.ExternalFunction("send", types.intp(types.int32, types.intp, types.uintp,
                                                  types.int32))
_clock_gettime = types.ExternalFunction("clock_gettime", types.int32(types.int32, types.intp))
_ioctl = types.ExternalFunction("ioctl", types.int32(types.int32, types.uint64, types.intp))


@njit(cache=True, nogil=True)
def _now(ts, clock):
    _clock_gettime(clock, ts.ctypes.data)
    return ts[0] * 1_000_000_000 + ts[1]


@njit(cache=True, nogil=True)
def record_spread(ring, stats, now, spread):
    """``spread`` [ns] seen at ``now`` of the slaves' clock into the largest-per-window ring
    (``stats[F_SPREAD_WINDOWS]``: windows begun so far); windows passed without a call
    hold -1 (unknown)."""
    n = ring.shape[0]
    w = now // SPREAD_WINDOW_NS
    begun = stats[F_SPREAD_WINDOWS]
    if w < begun - 1:
        return
    for j in range(max(begun, w + 1 - n), w + 1):
        ring[j % n] = -1
    if w + 1 > begun:
        stats[F_SPREAD_WINDOWS] = w + 1
    if spread > ring[w % n]:
        ring[w % n] = spread


@njit(cache=True, nogil=True)
def frame_loop(fd, ctl, stats, hist, late_log, spread_ring, buf, mem, sii, st, wmask, obuf,
               olen, oidx, ibuf, ilen, iidx, scratch):
    """Serve frames on socket ``fd`` until ``ctl[C_STOP]`` is set (by another thread).

    Besides the reply times: the longest gap between two returns of ``poll`` beyond its
    timeout (``F_MAX_GAP_NS``: the thread did not run), the longest work on one wake-up
    (``F_MAX_WORK_NS``), and per late reply (the first ``late_log.shape[0]``) when its
    frame arrived (CLOCK_MONOTONIC), its reply time, how long after its arrival the thread
    woke, and how long that wake-up's work took up to its send."""
    pfd = np.zeros(2, dtype=np.int32)
    pfd[0] = fd
    pfd[1] = 1  # events: POLLIN
    ts = np.zeros(2, dtype=np.int64)
    stamp = np.zeros(2, dtype=np.int64)
    last = ctl[C_T0]
    nbins = hist.shape[0]
    nlog = late_log.shape[0]
    while ctl[C_STOP] == 0:
        ready = _poll(pfd.ctypes.data, 1, POLL_MS)
        now = _now(ts, CLOCK_MONOTONIC)
        if now - last - POLL_MS * 1_000_000 > stats[F_MAX_GAP_NS]:
            stats[F_MAX_GAP_NS] = now - last - POLL_MS * 1_000_000
        if now > last:
            tick(mem, st, obuf, olen, oidx, now - last)
            last = now
            if mem.shape[0]:
                record_spread(spread_ring, stats, st[0, S_NOW], st[0, D_SPREAD])
        if ready <= 0:
            continue
        # CLOCK_REALTIME (the kernel's receive stamps) minus CLOCK_MONOTONIC, this wake-up
        mono_off = _now(ts, CLOCK_REALTIME) - now
        while True:
            n = _recv(fd, buf.ctypes.data, 2048, MSG_DONTWAIT)
            if n < 0:
                break
            stats[F_RECEIVED] += 1
            if _ioctl(fd, SIOCGSTAMPNS, stamp.ctypes.data) == 0 and stamp[0] > 0:
                t_rx = stamp[0] * 1_000_000_000 + stamp[1]
            else:
                stats[F_NO_STAMP] += 1
                t_rx = _now(ts, CLOCK_REALTIME)
            out = handle_frame(buf, n, mem, sii, st, wmask, obuf, olen, oidx, ibuf, ilen,
                               iidx, scratch)
            if out == NOT_ETHERCAT:
                stats[F_OTHER] += 1
                continue
            if out == DROPPED:
                stats[F_DROPPED] += 1
                continue
            if _send(fd, buf.ctypes.data, out, 0) != out:
                stats[F_SEND_ERRORS] += 1
                continue
            sent = _now(ts, CLOCK_REALTIME)
            lat = sent - t_rx
            stats[F_ANSWERED] += 1
            if lat > stats[F_MAX_NS]:
                stats[F_MAX_NS] = lat
            work = sent - mono_off - now
            if work > stats[F_MAX_WORK_NS]:
                stats[F_MAX_WORK_NS] = work
            if lat > ctl[C_LATE_NS]:
                k = stats[F_LATE]
                if k < nlog:
                    late_log[k, L_AT] = t_rx - mono_off
                    late_log[k, L_REPLY] = lat
                    late_log[k, L_WAKE] = now + mono_off - t_rx
                    late_log[k, L_WORK] = work
                stats[F_LATE] += 1
            b = max(lat, 0) // 1000
            hist[min(b, nbins - 1)] += 1
    return 0


class FrameThread:
    """The frame path on ``sock`` (an AF_PACKET socket bound to the interface) over the
    slaves ``arrays``. :meth:`start`, then :meth:`stop`; ``stats``/``hist`` while it runs.
    ``on_start``: run first inside the thread (its priority, its CPU)."""

    def __init__(self, sock: socket.socket, arrays: EscArrays, late_us: float,
                 on_start=None) -> None:  # noqa: ANN001
        try:  # our own replies are never received; frames other hosts send are
            sock.setsockopt(SOL_PACKET, PACKET_IGNORE_OUTGOING, 1)
        except OSError:
            pass  # kernels before 4.20: the compiled path answers only EtherCAT requests
        self.sock = sock
        self.arrays = arrays
        self.ctl = np.zeros(N_CTL, dtype=np.int64)
        self.ctl[C_LATE_NS] = int(late_us * 1e3)
        self.stats = np.zeros(N_STATS, dtype=np.int64)
        self.hist = np.zeros(HIST_US + 1, dtype=np.int64)
        self.late_log = np.zeros((LATE_LOG, 4), dtype=np.int64)
        self.spread_ring = np.full(SPREAD_RING, -1, dtype=np.int64)
        self.buf = np.zeros(2048, dtype=np.uint8)
        self.on_start = on_start
        self.error: BaseException | None = None
        #: Time the thread was runnable but waited for its CPU while serving [ns].
        self.run_delay_ns: int | None = None
        self._thread = threading.Thread(target=self._run, name="esc-frames", daemon=True)
        self._set_up = threading.Event()

    def start(self, t0_ns: int) -> None:
        """Start serving (returns once the thread set itself up); ``t0_ns``:
        CLOCK_MONOTONIC origin of the slaves' clock."""
        self.ctl[C_T0] = t0_ns
        self._thread.start()
        self._set_up.wait()

    def _run(self) -> None:
        try:
            try:
                if self.on_start is not None:
                    self.on_start()
            finally:
                self._set_up.set()
            d0 = run_delay_ns()
            frame_loop(self.sock.fileno(), self.ctl, self.stats, self.hist, self.late_log,
                       self.spread_ring, self.buf, *self.arrays.frame_args())
            d1 = run_delay_ns()
            if d0 is not None and d1 is not None:
                self.run_delay_ns = d1 - d0
        except BaseException as exc:  # reported by the owner
            self.error = exc

    def stop(self) -> None:
        self.ctl[C_STOP] = 1
        self._thread.join()

    def late_replies(self, t0_ns: int) -> list[dict]:
        """The logged late replies: when [s after ``t0_ns``], reply time, how long the
        thread took to wake after the frame arrived, and its work up to the send [us]."""
        n = min(int(self.stats[F_LATE]), self.late_log.shape[0])
        return [{"at_s": round((int(r[L_AT]) - t0_ns) * 1e-9, 4),
                 "reply_us": round(int(r[L_REPLY]) / 1e3, 1),
                 "wake_us": round(int(r[L_WAKE]) / 1e3, 1),
                 "work_us": round(int(r[L_WORK]) / 1e3, 1)} for r in self.late_log[:n]]

    def dc_spread(self) -> tuple[int, list[int]]:
        """(index of the first window held, the largest spread [ns] per window of
        :data:`SPREAD_WINDOW_NS` of the slaves' clock from it on; -1: no wake-up in it)."""
        begun = int(self.stats[F_SPREAD_WINDOWS])
        n = self.spread_ring.shape[0]
        first = max(begun - n, 0)
        return first, [int(self.spread_ring[j % n]) for j in range(first, begun)]

    def alive(self) -> bool:
        return self._thread.is_alive()


def warm_up() -> None:
    """Compile (or load) the frame loop before a master is waiting on it."""
    from firmware_model.esc.esc import Esc  # noqa: F401  (the reference's tables)

    a, b = socket.socketpair()
    try:
        arrays = _tiny_chain()
        ctl = np.zeros(N_CTL, dtype=np.int64)
        ctl[C_STOP] = 1
        frame_loop(a.fileno(), ctl, np.zeros(N_STATS, dtype=np.int64),
                   np.zeros(2, dtype=np.int64), np.zeros((1, 4), dtype=np.int64),
                   np.full(1, -1, dtype=np.int64), np.zeros(2048, dtype=np.uint8),
                   *arrays.frame_args())
    finally:
        a.close()
        b.close()


def _tiny_chain() -> EscArrays:
    from firmware_model.esc.sii import SlaveDescription, SyncManager, build_image

    d = SlaveDescription(0, 0, 0, 0, "warm-up", "warm-up", (), (),
                         (SyncManager(0x1000, 0, 0x64, False),
                          SyncManager(0x1100, 0, 0x20, False)))
    return EscArrays([(d, build_image(d))])
