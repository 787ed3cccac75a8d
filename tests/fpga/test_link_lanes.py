"""The LVDS link's sweeps in vector lanes (firmware_model.lvds.lanes) against the scalar
sweeps (firmware_model.lvds.link): over random batches of links that differ (pointers, bit
accumulators, ticks, stopped directions, delays, word faults that send a lane through the
scalar sweep, stale word-log slots), every tick's receiver memories, board link fields and
word logs, and the whole link state at the end, bit for bit."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.lvds import lanes as LL
from firmware_model.lvds import link as LK
from plant.lanes import LANES, LW

_BITS_REAL = 10_000_000 * 50_000  # 10 Mbit/s, 50 us ticks: 11.1 words per tick


@st.composite
def link(draw):
    """One link's state: counters anywhere valid, random rings and word logs (stale slots
    included), each direction healthy, stopped, delayed or with a word fault."""
    lk = np.random.default_rng(draw(st.integers(0, 2**32))).integers(
        -(1 << 40), 1 << 40, LK.N_LINK_STATE)
    lk[:LK.N_LINK] = 0
    lk[LK.LK_BITS_NUM] = draw(st.sampled_from([_BITS_REAL, LK._WORD_DEN * 3 + 7,
                                               LK._WORD_DEN * 40 + 1]))
    for acc, ptr, size, t, stop, cor, drop, dup, delay, words in (
            (LK.LK_DOWN_ACC, LK.LK_DOWN_PTR, B.DOWN_WORDS, LK.LK_DOWN_T, LK.LK_DOWN_STOPPED,
             LK.LK_DOWN_CORRUPT, LK.LK_DOWN_DROP, LK.LK_DOWN_DUP, LK.LK_DOWN_DELAY,
             LK.LK_DOWN_WORDS),
            (LK.LK_UP_ACC, LK.LK_UP_PTR, B.UP_WORDS, LK.LK_UP_T, LK.LK_UP_STOPPED,
             LK.LK_UP_CORRUPT, LK.LK_UP_DROP, LK.LK_UP_DUP, LK.LK_UP_DELAY, LK.LK_UP_WORDS)):
        lk[acc] = draw(st.one_of(st.integers(0, LK._WORD_DEN - 1),
                                 st.sampled_from([0, LK._WORD_DEN - 1])))
        lk[ptr] = draw(st.integers(0, size - 1))
        lk[t] = draw(st.one_of(st.integers(0, 2 * LK.HIST_TICKS), st.integers(0, 1 << 40)))
        lk[words] = draw(st.integers(0, 1 << 40))
        lk[stop] = draw(st.sampled_from([0, 0, 0, 1]))
        lk[delay] = draw(st.sampled_from([0, 0, 1, 5, LK.HIST_TICKS - 1]))
        fault = draw(st.sampled_from([None, None, cor, drop, dup]))
        if fault is not None:
            lk[fault] = draw(st.integers(1, 4))
    return lk


@settings(max_examples=25, deadline=None)
@given(links=st.lists(link(), min_size=1, max_size=LW), extra=st.integers(0, 3),
       ticks=st.integers(1, 6), seed=st.integers(0, 2**32))
def test_the_sweeps_in_lanes_are_the_scalar_sweeps_bit_for_bit(links, extra, ticks, seed):
    """Up to LW links in one batch (rows of a larger array, out of order), ``ticks``
    ticks with new sender memories each tick: receiver memories, the board's link-watchdog
    and CRC-error fields and both word logs after every tick, and every link's whole state
    after the batch is stored back, equal to the scalar sweeps of each link alone."""
    rng = np.random.default_rng(seed)
    n = len(links) + extra
    lk = rng.integers(-(1 << 30), 1 << 30, (n, LK.N_LINK_STATE))
    rows = rng.permutation(n)[:len(links)]
    m = len(rows)
    for j, r in enumerate(rows):
        lk[r] = links[j]
    mdown = rng.integers(0, 1 << 17, (n, B.DOWN_WORDS))
    mup = rng.integers(-(1 << 33), 1 << 33, (n, B.UP_WORDS))
    st_ = rng.integers(0, 1 << 16, (n, B.N_STATE))
    down = rng.integers(0, 1 << 16, (n, B.DOWN_WORDS))
    up = rng.integers(-(1 << 33), 1 << 33, (n, B.UP_WORDS))
    ref = [a.copy() for a in (lk, mdown, mup, st_, down, up)]
    lb = LL.link_lane_buffer()
    block = np.zeros(LW, dtype=np.int64)
    block[:m] = rows
    LL.load_link(lb, lk, block, m)
    # the boards' downstream memories and link counts in the board lanes, as in the engine
    fb = fpl.board_buffer()
    raw = np.zeros((n, B.N_RAW), dtype=np.int64)
    fpl.load_board(fb, np.zeros((n, B.N_PARAMS), dtype=np.int64), st_, raw, down, block, m)
    trace = np.zeros((1, 2 * LK.WORDS_W), dtype=np.int64)
    for _ in range(ticks):
        new_down = rng.integers(0, 1 << 17, (n, B.DOWN_WORDS))
        new_up = rng.integers(-(1 << 33), 1 << 33, (n, B.UP_WORDS))
        mdown[:], ref[1][:] = new_down, new_down
        up[:], ref[5][:] = new_up, new_up
        LL.sweep_down_lanes(lb, lk, mdown, fb, st_, down, block, m)
        LL.sweep_up_lanes(lb, lk, up, mup, block, m)
        fpl.store_board(fb, st_, raw, down, block, m)
        r_lk, r_mdown, r_mup, r_st, r_down, r_up = ref
        for j, r in enumerate(rows):
            LK.sweep_down(r_lk[r], r_mdown[r], r_st[r], r_down[r])
            LK.sweep_up(r_lk[r], r_up[r], r_mup[r])
            LL.word_log(trace, 0, 0, lb, j)
            np.testing.assert_array_equal(trace[0], r_lk[r, LK.LK_DOWN_WORDLOG:])
        np.testing.assert_array_equal(down, r_down)
        np.testing.assert_array_equal(mup, r_mup)
        np.testing.assert_array_equal(st_, r_st)
    LL.store_link(lb, lk, block, m)
    np.testing.assert_array_equal(lk, ref[0])


@pytest.mark.slow
def test_link_and_sensor_lanes_compile_to_vector_instructions():
    """The machine code of the lane loops (compiled afresh, ~10 s): the link's bookkeeping
    and the chips' codes run on full vector registers (zmm with AVX-512, ymm with AVX2),
    their 64-bit multiplies packed (``vpmullq`` with AVX-512DQ, ``vpmuludq`` halves with
    AVX2), no int64 <-> float64 conversion left scalar (AVX2 has no packed form: the lanes
    convert with the 1.5 * 2**52 trick), the integer divisions the scalar code makes are
    gone, no multiply-add is fused."""
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features().flatten()
    if "+avx512dq" in features:
        reg, mul = "zmm", "vpmullq"
    elif "+avx2" in features:
        reg, mul = "ymm", "vpmuludq"
    else:
        pytest.skip("no AVX2 on this CPU")
    from plant.sensors import lanes as SL

    opts = {k: v for k, v in LANES.items() if k != "cache"}

    @njit(**opts)
    def book(lb):
        LL._book(lb, LL.U, B.UP_WORDS, LK.LK_UP_HIST)

    @njit(**opts)
    def codes(sb, tick):
        SL._codes(sb, tick, True)

    book(LL.link_lane_buffer())
    codes(SL.sensor_lane_buffer(), 7)
    for f, ops in ((book, (mul, "vpaddq", "vmulpd")),
                   (codes, ("vdivpd", "vpsrlvq", mul))):
        asm = next(iter(f.inspect_asm().values()))
        for op in ops:
            assert re.search(rf"\b{op}\s+[^\n]*%{reg}", asm), op
        assert not re.search(r"\bvcvtt?s[di]2s[id]", asm)
        assert not re.search(r"\bidiv", asm)
        assert not re.search(r"vfn?m(?:add|sub)", asm)
