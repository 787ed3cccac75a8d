"""The LVDS link's value-level sweeps (:func:`firmware_model.lvds.link.sweep_down` and
:func:`~firmware_model.lvds.link.sweep_up`) over a batch of up to ``LW`` actuators at once.

The per-actuator link state (``lk``, :data:`~firmware_model.lvds.link.N_LINK_STATE` int64)
is mostly the two sender-memory rings of the ``delay`` fault (2 x 64 x 32 words); the rest is
a few counters per direction (bit accumulator, pointer, tick, words sent) and the word log
of the latest tick. Here, for the whole kernel call:

* the counters and the word logs live in one flat int64 **lane buffer** (structure of
  arrays: row ``r`` of lane ``j`` at ``r * LW + j``), loaded when a thread claims the batch
  (:func:`load_link`) and stored back into each actuator's ``lk`` at its end
  (:func:`store_link`); the trace and frame-log reads of the word log
  (:func:`word_log`) read the lanes;
* the rings stay in each actuator's ``lk`` row (16 KiB each: moving them would cost more
  than the sweep), and so do the MCU's memories (rows, moved once per MCU period) and the
  board's upstream memory (its row: the upstream ring copy is one contiguous move);
* the downstream sweep writes the board's downstream memory and restarts its link watchdog
  in the board lanes (:mod:`firmware_model.fpga.lanes`: ``DO``, ``F_SINCE_VALID``), where
  the board reads them.

Per tick and direction: the bookkeeping of all lanes (words of the tick from the bit
accumulator, ring slots, pointer, word count, which addresses the word log names) is one
pass over the lanes, branch-free (LLVM vectorises it); then per actuator the ring copy of
the sender's memory and the tick's words into the receiver's memory and the word log's
data, as at most two runs of consecutive addresses (no per-word wrap-around test).

Words sent, stored values, counters and word log are those of the scalar sweep, bit for bit
(``tests/firmware/test_lvds_lanes.py``), for any valid state (pointer within the memory,
bit accumulator below one word, tick >= 0). A direction with a **word fault** set (every
N-th word corrupted, dropped or sent twice: the ``corrupt_every`` bit flips, the
value-level ``drop_every``/``dup_every``) runs the scalar sweep for that actuator and that
direction, in place in its ``lk`` row (downstream: on the board's rows, its exchange words
moved out of the board lanes and back), and its word log is copied into the lanes; the other
lanes and the other direction stay in the lane path. Fault settings change only between
kernel calls (cycle boundaries), so which lanes fall back is decided at :func:`load_link`.
A stopped direction (a dead cable) and a ``delay`` stay in the lane path.

The value-level link computes no CRC (a word's CRC verdict is the fault setting's); the
LVDS CRC (:mod:`protocols.lvds`) runs only on the bit-level path and in the log export.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.fpga.lanes import LANES, LW
from firmware_model.lane_int import int_to_float, trunc_to_int
from firmware_model.lvds import link as LK

#: Rows of the lane buffer per direction (offset ``D`` for downstream, ``U`` upstream).
(_ACC, _PTR, _T, _WORDS, _STOP, _DELAY, _SCALAR, _P0, _N, _SRC, _WROW) = range(11)
_PER_DIR = 11
BITS = 0                                #: bits per tick x 1e9 (LK_BITS_NUM)
D = 1                                   #: downstream counters
U = D + _PER_DIR                        #: upstream counters
WL = U + _PER_DIR                       #: word logs: down's WORDS_W rows, then up's
SIZE = (WL + 2 * LK.WORDS_W) * LW       #: int64 entries of a link lane buffer
#: (lk index of the counters, lane-buffer row) per direction, for load and store.
_FIELDS_DOWN = ((LK.LK_DOWN_ACC, _ACC), (LK.LK_DOWN_PTR, _PTR), (LK.LK_DOWN_T, _T),
                (LK.LK_DOWN_WORDS, _WORDS), (LK.LK_DOWN_STOPPED, _STOP),
                (LK.LK_DOWN_DELAY, _DELAY))
_FIELDS_UP = ((LK.LK_UP_ACC, _ACC), (LK.LK_UP_PTR, _PTR), (LK.LK_UP_T, _T),
              (LK.LK_UP_WORDS, _WORDS), (LK.LK_UP_STOPPED, _STOP),
              (LK.LK_UP_DELAY, _DELAY))
_DEN = LK._WORD_DEN
_INV_DEN = 1.0 / _DEN


@njit(cache=True, inline="always")
def _ix(row, j):
    """Row ``row`` of lane ``j``, as an unsigned index (no wrap-around select)."""
    return np.uint64(row * LW + j)


@njit(cache=True, inline="always")
def _floordiv_den(acc):
    """``acc // _WORD_DEN`` (floor) without an integer division, which has no vector form
    for 64-bit lanes: a float64 estimate (a product with 1 / ``_WORD_DEN``, off by at most
    one for any int64 ``acc``: the quotient is below 2^28) corrected by one compare each
    way. ``acc`` to float64 and the estimate back without the packed conversions AVX2
    lacks (:mod:`firmware_model.lane_int`: exact for any ``acc``, and the estimate is well
    inside the 1.5 * 2**52 trick's range)."""
    q = trunc_to_int(int_to_float(acc) * _INV_DEN)
    r = acc - q * _DEN
    q = q - 1 if r < 0 else q
    r = r + _DEN if r < 0 else r
    return q + 1 if r >= _DEN else q


@njit(cache=True, inline="always", error_model="numpy")
def _book(lb, o, size, hist):
    """One tick's bookkeeping of direction ``o`` (:data:`D` or :data:`U`) in every lane (a
    vector loop), then the word log's slots (a loop per lane):
    ``_words_this_tick`` and ``_remember`` (the ring row written, ``_WROW``; the row the
    words are read from, ``_SRC``), the words sent (``_N``: none when stopped) from the
    pointer ``_P0``, the pointer and word count after them, the word log's count,
    addresses and fates (its data: :func:`_sweep_lane`)."""
    wl = WL if o == D else WL + LK.WORDS_W
    for j in range(LW):
        acc = lb[_ix(o + _ACC, j)] + lb[_ix(BITS, j)]
        n = _floordiv_den(acc)
        lb[_ix(o + _ACC, j)] = acc - n * _DEN
        t = lb[_ix(o + _T, j)]
        lb[_ix(o + _WROW, j)] = hist + (t % LK.HIST_TICKS) * LK.HIST_W
        lb[_ix(o + _T, j)] = t + 1
        d = lb[_ix(o + _DELAY, j)]
        back = t - d if t >= d else 0
        lb[_ix(o + _SRC, j)] = hist + (back % LK.HIST_TICKS) * LK.HIST_W
        n = 0 if lb[_ix(o + _STOP, j)] != 0 else n
        lb[_ix(o + _N, j)] = n
        p0 = lb[_ix(o + _PTR, j)]
        lb[_ix(o + _P0, j)] = p0
        lb[_ix(o + _PTR, j)] = (p0 + n) % size
        lb[_ix(o + _WORDS, j)] += n
        lb[_ix(wl, j)] = n if n < LK.MAX_WORDS_TICK else LK.MAX_WORDS_TICK
    # The word log's slots below the count, lane by lane. In the loop above, a slot kept
    # where ``k >= n`` is a conditional store: a scatter (AVX-512) or a ``vpmaskmovq``
    # (AVX2; microcoded on AMD: that vector loop ran slower than the scalar one, and LLVM's
    # cost model left it scalar); as a loop of their own, ~11 plain stores of two rows per
    # lane, and the loop above vectorises on both.
    for j in range(LW):
        n = lb[_ix(wl, j)]
        p0 = lb[_ix(o + _P0, j)]
        for k in range(n):
            lb[_ix(wl + 1 + 3 * k, j)] = (p0 + k) % size
            lb[_ix(wl + 3 + 3 * k, j)] = LK.WORD_OK


@njit(cache=True, inline="always", error_model="numpy")
def _copy_words(lb, wl, j, lk, src, dest, d0, ds, a0, a1, k0, mask):
    """Words of addresses ``a0..a1-1`` (the ``k0``-th word of the tick first): from the
    ring row ``src`` into ``dest`` (address ``a`` at ``d0 + a * ds``) as ``data & mask``,
    and the data of the word-log slots below
    :data:`~firmware_model.lvds.link.MAX_WORDS_TICK` into lane ``j``."""
    for a in range(a0, a1):
        v = lk[np.uint64(src + a)]
        dest[np.uint64(d0 + a * ds)] = v & mask
        k = k0 + a - a0
        if k < LK.MAX_WORDS_TICK:
            lb[_ix(wl + 2 + 3 * k, j)] = v


@njit(cache=True, inline="always", error_model="numpy")
def _sweep_lane(lb, o, j, lk, mem, dest, d0, ds, size, mask):
    """Lane ``j``'s memory moves of the tick (direction ``o``, bookkept by :func:`_book`):
    the sender's memory ``mem`` into its ring row; the tick's ``n`` words from the pointer
    ``p0`` into ``dest`` (address ``a`` at ``d0 + a * ds``: a row, or a lane of the board
    lanes; ``data & mask``; both memories are whole link memories of
    ``size`` words, so every address exists), as at most two runs of consecutive
    addresses (up to the memory's end, then from 0), and the word log's data. Returns
    ``n``."""
    wrow = lb[_ix(o + _WROW, j)]
    # A trip count the compiler does not know (the row's length, ``size``): a known one is
    # unrolled into word-by-word moves (the memories may overlap the ring, as far as it
    # can tell); this way it is a vector loop behind one run-time overlap check.
    for w in range(mem.shape[0]):
        lk[np.uint64(wrow + w)] = mem[w]
    src = lb[_ix(o + _SRC, j)]
    p0 = lb[_ix(o + _P0, j)]
    n = lb[_ix(o + _N, j)]
    wl = WL if o == D else WL + LK.WORDS_W
    if n <= size:
        end = p0 + n
        first = end if end < size else size
        if src == wrow:  # no delay: the ring row just written is the memory itself
            _copy_words(lb, wl, j, mem, 0, dest, d0, ds, p0, first, 0, mask)
            _copy_words(lb, wl, j, mem, 0, dest, d0, ds, 0, end - first, first - p0, mask)
        else:
            _copy_words(lb, wl, j, lk, src, dest, d0, ds, p0, first, 0, mask)
            _copy_words(lb, wl, j, lk, src, dest, d0, ds, 0, end - first, first - p0, mask)
    else:  # more words than the memory holds (a bit rate far above the real one)
        a = p0
        for k in range(n):
            v = lk[np.uint64(src + a)]
            dest[np.uint64(d0 + a * ds)] = v & mask
            if k < LK.MAX_WORDS_TICK:
                lb[_ix(wl + 2 + 3 * k, j)] = v
            a = a + 1 if a + 1 < size else 0
    return n


@njit(cache=True, inline="always")
def _log_from(lb, o, j, lk):
    """The word log of direction ``o`` in ``lk`` (a lane that ran the scalar sweep) into
    lane ``j``."""
    wl = WL if o == D else WL + LK.WORDS_W
    base = LK.LK_DOWN_WORDLOG if o == D else LK.LK_UP_WORDLOG
    for w in range(LK.WORDS_W):
        lb[_ix(wl + w, j)] = lk[base + w]


@njit(cache=True, inline="always")
def _scalar_down(lb, lk, mdown, fb, j, st, down):
    """The scalar downstream sweep of lane ``j`` (a word fault) on the board's rows: its
    downstream memory and link counts moved out of the board lanes, the sweep, and back."""
    since = np.uint64(fpl.SO + B.F_SINCE_VALID * LW + j)
    crc = np.uint64(fpl.SO + B.F_ERR_LINK_CRC * LW + j)
    for w in range(B.DOWN_WORDS):
        down[w] = fb[np.uint64(fpl.DO + w * LW + j)]
    st[B.F_SINCE_VALID] = fb[since]
    st[B.F_ERR_LINK_CRC] = fb[crc]
    LK.sweep_down(lk, mdown, st, down)
    for w in range(B.DOWN_WORDS):
        fb[np.uint64(fpl.DO + w * LW + j)] = down[w]
    fb[since] = st[B.F_SINCE_VALID]
    fb[crc] = st[B.F_ERR_LINK_CRC]
    _log_from(lb, D, j, lk)


@njit(**LANES, inline="always")
def sweep_down_lanes(lb, lk, mdown, fb, st, down, rows, m):
    """:func:`~firmware_model.lvds.link.sweep_down` of one tick for the actuators
    ``rows[:m]`` (lanes 0..m-1): MCU memory rows ``mdown`` -> the boards' downstream
    memories in the board lanes ``fb`` (:func:`firmware_model.fpga.lanes.load_board`); a
    good word restarts the board's link watchdog (its ``F_SINCE_VALID`` lane). ``st`` and
    ``down`` (the boards' state and downstream rows) only for a lane on the scalar sweep."""
    _book(lb, D, B.DOWN_WORDS, LK.LK_DOWN_HIST)
    for j in range(m):
        i = rows[j]
        if lb[_ix(D + _SCALAR, j)] != 0:
            _scalar_down(lb, lk[i], mdown[i], fb, j, st[i], down[i])
        elif _sweep_lane(lb, D, j, lk[i], mdown[i], fb, fpl.DO + j, LW, B.DOWN_WORDS,
                         0xFFFF) > 0:
            fb[np.uint64(fpl.SO + B.F_SINCE_VALID * LW + j)] = 0


@njit(**LANES, inline="always")
def sweep_up_lanes(lb, lk, up, mup, rows, m):
    """:func:`~firmware_model.lvds.link.sweep_up` of one tick for the actuators
    ``rows[:m]``: board memory rows ``up`` -> MCU memory rows ``mup``."""
    _book(lb, U, B.UP_WORDS, LK.LK_UP_HIST)
    for j in range(m):
        i = rows[j]
        if lb[_ix(U + _SCALAR, j)] != 0:
            LK.sweep_up(lk[i], up[i], mup[i])
            _log_from(lb, U, j, lk[i])
        else:
            _sweep_lane(lb, U, j, lk[i], up[i], mup[i], 0, 1, B.UP_WORDS, -1)


@njit(cache=True, inline="always")
def word_log(trace, at, col, lb, j):
    """Both directions' word logs of lane ``j`` (what the link's ``lk[LK_DOWN_WORDLOG:]``
    holds after the tick's sweeps) into ``trace[at, col:]``."""
    for w in range(2 * LK.WORDS_W):
        trace[at, col + w] = lb[_ix(WL + w, j)]


@njit(**LANES)
def load_link(lb, lk, rows, m):
    """The counters and word logs of the links ``lk[rows[:m]]`` into lanes 0..m-1 (the last
    one's into the free lanes, computed and never stored), and per direction whether a
    word fault sends the lane through the scalar sweep."""
    for j in range(LW):
        i = rows[min(j, m - 1)]
        lb[_ix(BITS, j)] = lk[i, LK.LK_BITS_NUM]
        for at, row in _FIELDS_DOWN:
            lb[_ix(D + row, j)] = lk[i, at]
        for at, row in _FIELDS_UP:
            lb[_ix(U + row, j)] = lk[i, at]
        word_fault = (lk[i, LK.LK_DOWN_DUP] > 0 or lk[i, LK.LK_DOWN_DROP] > 0
                      or lk[i, LK.LK_DOWN_CORRUPT] > 0)
        lb[_ix(D + _SCALAR, j)] = 1 if word_fault else 0
        word_fault = (lk[i, LK.LK_UP_DUP] > 0 or lk[i, LK.LK_UP_DROP] > 0
                      or lk[i, LK.LK_UP_CORRUPT] > 0)
        lb[_ix(U + _SCALAR, j)] = 1 if word_fault else 0
        for w in range(2 * LK.WORDS_W):
            lb[_ix(WL + w, j)] = lk[i, LK.LK_DOWN_WORDLOG + w]


@njit(**LANES)
def store_link(lb, lk, rows, m):
    """The counters and word logs of lanes 0..m-1 back into ``lk[rows[:m]]`` (a direction
    that ran the scalar sweep is there already)."""
    for j in range(m):
        i = rows[j]
        if lb[_ix(D + _SCALAR, j)] == 0:
            for at, row in _FIELDS_DOWN:
                lk[i, at] = lb[_ix(D + row, j)]
            for w in range(LK.WORDS_W):
                lk[i, LK.LK_DOWN_WORDLOG + w] = lb[_ix(WL + w, j)]
        if lb[_ix(U + _SCALAR, j)] == 0:
            for at, row in _FIELDS_UP:
                lk[i, at] = lb[_ix(U + row, j)]
            for w in range(LK.WORDS_W):
                lk[i, LK.LK_UP_WORDLOG + w] = lb[_ix(WL + LK.WORDS_W + w, j)]


def link_lane_buffer() -> np.ndarray:
    """A zeroed link lane buffer (:data:`SIZE` int64)."""
    return np.zeros(SIZE, dtype=np.int64)


__all__ = ["SIZE", "link_lane_buffer", "load_link", "store_link", "sweep_down_lanes",
           "sweep_up_lanes", "word_log"]
