"""The LVDS link: sweep timing and latency, CRC discards, value level vs bit level."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import DriverBoard, LinkMemory
from firmware_model.fpga.tick import control_tick
from firmware_model.lvds import link as LK
from hil.sim.actuator import FpgaStack
from plant.config import load_config
from plant.model import Plant
from plant.sensors.chips import chip_params
from plant.sensors.harness import digitise


@pytest.fixture(scope="module")
def cfg():
    return load_config(None, ["load.kind=fixed"])


def test_words_per_tick_follow_the_bit_rate_exactly(cfg):
    stack = FpgaStack(cfg)
    stack.advance(900)
    bits = cfg.get("fpga.lvds_bit_rate_hz") * 900 * cfg.get("sim.tick_ns") * 1e-9
    assert stack.link[LK.LK_DOWN_WORDS] == int(bits // LK.WORD_BITS)
    assert stack.link[LK.LK_UP_WORDS] == int(bits // LK.WORD_BITS)


@pytest.mark.parametrize("rate", [2_000_000, 10_000_000])
def test_round_trip_latency_is_bounded_by_the_two_sweeps(cfg, rate):
    cfg = cfg.with_overrides({"fpga.lvds_bit_rate_hz": rate})
    stack = FpgaStack(cfg)
    stack.advance(50)
    tick_s = stack.tick_s
    worst = 0
    for seq in range(1, 30):
        stack.mcu_link.write("sequence", seq)
        k = 0
        while stack.mcu_link.read("sequence_echo") != seq:
            stack.advance(1)
            k += 1
            assert k < 1000
        worst = max(worst, k)
    bound = (LK.sweep_time_s(cfg, B.DOWN_WORDS) + LK.sweep_time_s(cfg, B.UP_WORDS)) / tick_s
    assert worst <= int(np.ceil(bound)) + 2
    # At the slow rate the sweeps take many ticks: the latency really comes from the link.
    if rate == 2_000_000:
        assert worst >= bound / 2


def test_bit_level_link_gives_the_same_memories_and_counts(cfg):
    """Same board, same sensors: value-level words vs words through protocols.lvds."""
    plant = Plant(cfg)
    k = chip_params(cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    boards = [DriverBoard(cfg), DriverBoard(cfg)]
    mems = [LinkMemory(cfg), LinkMemory(cfg)]
    links = [LK.link_state(cfg), LK.link_state(cfg)]
    bit = LK.BitLevelLink()
    for m in mems:
        m.write("mode", B.BoardMode.VOLTAGE)
        m.write("control", B.CTRL_ENABLE)
        m.write("vq_ref", 1500)
    for t in range(300):
        if t == 150:
            for lk in links:
                lk[LK.LK_DOWN_CORRUPT] = 3
                lk[LK.LK_UP_CORRUPT] = 4
        digitise(plant.y, k, t, raw)
        for j in range(2):
            b, m, lk = boards[j], mems[j], links[j]
            if j == 0:
                LK.sweep_down(lk, m.down, b.state, b.down)
            else:
                bit.sweep_down(lk, m.down, b.state, b.down)
            control_tick(b.params, b.state, b.down, b.up, raw)
            if j == 0:
                LK.sweep_up(lk, b.up, m.up)
            else:
                bit.sweep_up(lk, b.up, m.up)
        np.testing.assert_array_equal(boards[0].down, boards[1].down, err_msg=f"tick {t}")
        assert boards[0].duty_counts() == boards[1].duty_counts()
        a, b = boards[0].state[B.F_ERR_LINK_CRC], boards[1].state[B.F_ERR_LINK_CRC]
        # The stream decoder confirms a failed word with the one after it: at most one
        # word later than the value level.
        assert 0 <= a - b <= 1, f"tick {t}: crc counts {a} vs {b}"
        a, b = links[0][LK.LK_MASTER_CRC], links[1][LK.LK_MASTER_CRC]
        assert 0 <= a - b <= 1
        plant.advance(1)
    assert boards[0].state[B.F_ERR_LINK_CRC] > 100
    np.testing.assert_array_equal(mems[0].up[:B.U_TICK], mems[1].up[:B.U_TICK])


def test_register_access_checks_ranges(cfg):
    m = LinkMemory(cfg)
    m.write("iq_ref", -5000)
    assert m.down[B.D_IQ_REF] == (-5000) & 0xFFFF
    with pytest.raises(ValueError, match="iq_ref"):
        m.write("iq_ref", 40000)
    with pytest.raises(KeyError, match="no downstream register"):
        m.write("nonsense", 1)


# --- word-level faults of the value-level link: drop, duplicate, delay -----------------------
def _booted(cfg):
    from hil.sim.actuator import FpgaStack

    s = FpgaStack(cfg)
    s.boot()
    return s


def test_dropped_words_are_lost_without_a_crc_count(cfg):
    """Every 3rd upstream word lost: a third of the words never arrive, none is counted as
    a CRC failure, and the MCU side still sees fresh values (the sweep goes on)."""
    s = _booted(cfg)
    words0, crc0 = s.link[LK.LK_UP_WORDS], s.link[LK.LK_MASTER_CRC]
    s.link_fault("up", drop_every=3)
    s.advance(400)
    sent = s.link[LK.LK_UP_WORDS] - words0
    assert s.link[LK.LK_UP_DROPPED] == sent // 3
    assert s.link[LK.LK_MASTER_CRC] == crc0
    assert s.mcu_link.read("tick") > 400  # the tick register still arrives


def test_duplicated_words_slow_the_sweep(cfg):
    """Every 2nd word sent twice: it takes the next word's slot, so over the same ticks the
    sweep pointer moves on by only half of the words sent."""
    clean, dup = _booted(cfg), _booted(cfg)
    dup.link_fault("up", dup_every=2)
    start = [(int(x.link[LK.LK_UP_PTR]), int(x.link[LK.LK_UP_WORDS])) for x in (clean, dup)]
    clean.advance(100)
    dup.advance(100)
    moved = []
    for x, (p0, w0) in zip((clean, dup), start, strict=True):
        words = int(x.link[LK.LK_UP_WORDS]) - w0
        moved.append(((int(x.link[LK.LK_UP_PTR]) - p0) % B.UP_WORDS, words))
    (adv_clean, words), (adv_dup, words_dup) = moved
    assert words == words_dup
    assert adv_clean == words % B.UP_WORDS
    assert adv_dup in {(words - words // 2) % B.UP_WORDS, (words - (words + 1) // 2)
                       % B.UP_WORDS}


@pytest.mark.parametrize("delay", [5, 20])
def test_delay_adds_latency_to_the_tick_register(cfg, delay):
    """The board's tick counter seen on the MCU side lags by ``delay`` more ticks with an
    upstream delay: the words carry the board memory of ``delay`` ticks ago."""
    clean, late = _booted(cfg), _booted(cfg)
    late.link_fault("up", delay_ticks=delay)
    clean.advance(300)
    late.advance(300)
    assert clean.mcu_link.read("tick") - late.mcu_link.read("tick") == delay


def test_new_faults_refused_on_the_bit_level_link_and_bad_values(cfg):
    from hil.sim.actuator import FpgaStack

    s = FpgaStack(cfg, bit_level=True)
    with pytest.raises(ValueError, match="bit-level"):
        s.link_fault("up", drop_every=2)
    v = FpgaStack(cfg)
    with pytest.raises(ValueError, match="delay_ticks"):
        v.link_fault("down", delay_ticks=64)
    with pytest.raises(ValueError, match="drop_every"):
        v.link_fault("down", drop_every=-1)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), ticks=st.integers(1, 300))
def test_the_fault_free_sweep_is_the_general_sweep(seed, ticks):
    """The sweeps take a short loop when no word fault is set; the general loop with a
    fault armed that never fires in the run must leave the same memories, counters, word
    logs and pointers (only the fault's own phase counter differs)."""
    cfg = load_config(None, ["load.kind=fixed"])
    rnd = np.random.default_rng(seed)
    fast, slow = LK.link_state(cfg), LK.link_state(cfg)
    never = 10**9
    slow[LK.LK_DOWN_CORRUPT] = never
    slow[LK.LK_UP_CORRUPT] = never
    phases = (LK.LK_DOWN_PHASE, LK.LK_UP_PHASE)
    ends = [(np.zeros(B.N_STATE, dtype=np.int64), np.zeros(B.DOWN_WORDS, dtype=np.int64),
             np.zeros(B.UP_WORDS, dtype=np.int64)) for _ in range(2)]
    for _ in range(ticks):
        master_down = rnd.integers(0, 1 << 16, B.DOWN_WORDS)
        up = rnd.integers(0, 1 << 16, B.UP_WORDS)
        for lk, (state, down, master_up) in zip((fast, slow), ends, strict=True):
            state[B.F_SINCE_VALID] += 1
            LK.sweep_down(lk, master_down, state, down)
            LK.sweep_up(lk, up, master_up)
    (s1, d1, u1), (s2, d2, u2) = ends
    assert np.array_equal(d1, d2) and np.array_equal(u1, u2) and np.array_equal(s1, s2)
    keep = np.ones(LK.N_LINK_STATE, dtype=bool)
    keep[[LK.LK_DOWN_CORRUPT, LK.LK_UP_CORRUPT, *phases]] = False
    assert np.array_equal(fast[keep], slow[keep])
    assert fast[LK.LK_DOWN_WORDS] > 0 and slow[phases[0]] > 0  # the general loop ran
