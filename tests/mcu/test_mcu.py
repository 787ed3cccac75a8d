"""The MCU model on the value-level stack: float32 arithmetic, the command watchdog, limits
and the status word, five boards at once, and the dual-port memory of the MCU board."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory, to_word
from firmware_model.mcu import dpram as D
from firmware_model.mcu.controller import ActuatorController
from firmware_model.mcu.mcu import (
    BOARD_ENABLED,
    BOARD_FAULT,
    CMD_TIMEOUT,
    CURRENT_LIMITED,
    FORCE_LIMITED,
    LINK_ERROR,
    SAFE_OFF,
    Mcu,
)
from firmware_model.mcu.measure import Measurements
from hil.sim.actuator import FpgaStack
from plant import layout as L
from plant.config import Config, load_config
from protocols.pressure_adc import DEFAULT as PRESSURE_ADC

F32 = np.float32
PC_TICKS = 20  # the PC hands a fresh command every 20 ticks (1 kHz)
DOC = Path(__file__).resolve().parents[2] / "docs" / "mcu.md"


@pytest.fixture(scope="module")
def cfg() -> Config:
    return load_config(None, ["load.kind=fixed"])


class Rig:
    """``n`` FpgaStacks (plant + board + link) under one Mcu, stepped as the scheduler does:
    every MCU period each stack advances, the PC commands (if due and ``commanding``), and
    the MCU steps. With ``dpram`` the MCU runs on a :class:`DualPortRam`'s board views and
    the copy state machine moves the words (``sync_up -> step -> sync_down``)."""

    def __init__(self, cfg: Config, commands: list[tuple[str, float]],
                 dpram: bool = False) -> None:
        self.stacks = [FpgaStack(cfg) for _ in commands]
        self.links = [s.mcu_link for s in self.stacks]
        self.ram = D.DualPortRam(cfg) if dpram else None
        mems = ([self.ram.board(k) for k in range(len(commands))] if self.ram is not None
                else self.links)
        self.mcu = Mcu(cfg, mems)
        self.period = self.mcu.period
        self.commands = list(commands)
        self.commanding = True
        for i, (mode, value) in enumerate(commands):
            self.mcu.command(i, mode, value, tick=0)
            self.mcu.enable(i, self.stacks[i].board.calibrated_offset)
        if self.ram is not None:
            self.ram.sync_down(self.links)

    @property
    def tick(self) -> int:
        return self.stacks[0].tick

    def cycle(self) -> None:
        """One MCU period."""
        for s in self.stacks:
            s.advance(self.period)
        t = self.tick
        if self.commanding and t % PC_TICKS == 0:
            for i, (mode, value) in enumerate(self.commands):
                self.mcu.command(i, mode, value, tick=t)
        if self.ram is not None:
            self.ram.sync_up(self.links)
        self.mcu.step(t)
        if self.ram is not None:
            self.ram.sync_down(self.links)

    def run(self, seconds: float, each: Callable[[Rig], None] | None = None) -> None:
        n = round(seconds / (self.stacks[0].tick_s * self.period))
        for _ in range(n):
            self.cycle()
            if each is not None:
                each(self)


# --- (a) float32 ------------------------------------------------------------------------------
CTRL_FLOATS = ("dt", "kt_eq", "kp", "kd", "bemf", "k_pos", "cos_alpha", "f_lim", "p_lim",
               "i_lim", "tau_p", "f_fb", "f_fil")
#: The controller's filters and loop blocks (firmware_model.mcu.filters): every slot a float.
CTRL_BLOCKS = ("derivative", "observer", "velocity_pi", "force_pi", "highpass",
               "seal_observer")
MEAS_FLOATS = tuple(n for n in Measurements.__slots__
                    if n not in ("strain_samples", "status", "_k", "_analog", "_volts"))


def test_volt_table_holds_the_float32_products(cfg):
    """The ADC decode looks its first product up: every entry is the float32 the
    Cortex-M4 computes for F32(code) * F32(lsb), and a float32."""
    m = Measurements(cfg)
    lsb = F32(PRESSURE_ADC.lsb_v)
    codes = np.random.default_rng(0).integers(0, 1 << 16, 2000).tolist() + [0, 4095, 65535]
    for c in codes:
        v = m._volts[c]
        assert type(v) is np.float32 and v == F32(c) * lsb


def _watch_outputs(mcu: Mcu) -> list[list[tuple]]:
    """Record what every controller's step returns (i_q reference, v_q feed-forward)."""
    seen: list[list[tuple]] = [[] for _ in mcu.ctrl]
    for i, ctrl in enumerate(mcu.ctrl):
        inner = ctrl.step

        def step(m, tau_ref, _inner=inner, _log=seen[i]):
            out = _inner(m, tau_ref)
            _log.append(out)
            return out

        ctrl.step = step
    return seen


def float32_leaks(mcu: Mcu, outputs: list[list[tuple]] | None = None) -> list[str]:
    """Names of the MCU's floating-point values that are not exactly numpy.float32."""
    bad = []

    def check(name: str, x: object) -> None:
        if type(x) is not np.float32:
            bad.append(f"{name}: {type(x).__name__}")

    for i, ctrl in enumerate(mcu.ctrl):
        for lst in ("tau_ref", "iq_ref", "value"):
            check(f"mcu.{lst}[{i}]", getattr(mcu, lst)[i])
        for n in CTRL_FLOATS:
            check(f"ctrl[{i}].{n}", getattr(ctrl, n))
        for b in CTRL_BLOCKS:
            block = getattr(ctrl, b)
            for n in type(block).__slots__:
                check(f"ctrl[{i}].{b}.{n}", getattr(block, n))
        for n in MEAS_FLOATS:
            check(f"meas[{i}].{n}", getattr(mcu.meas[i], n))
        if outputs is not None:
            for i_ref, v_ff in outputs[i][-1:]:
                check(f"step[{i}].i_ref", i_ref)
                check(f"step[{i}].v_ff", v_ff)
    return bad


VARIANTS = [
    # (mcu.controller, mcu.force_feedback, command mode, load)
    ("current", "pressure", "force", "fixed"),
    ("current", "strain", "force", "fixed"),
    ("current", "complementary", "force", "fixed"),
    ("velocity", "pressure", "force", "fixed"),
    ("velocity", "complementary", "force", "fixed"),
    ("current", "pressure", "position", "conrod"),
]


@pytest.mark.parametrize("controller,feedback,mode,load", VARIANTS)
def test_every_control_value_is_float32_after_every_step(controller, feedback, mode, load):
    cfg = load_config(None, [f"load.kind={load}", f"mcu.controller={controller}",
                             f"mcu.force_feedback={feedback}",
                             # a tilted rod, so cos(alpha) (Eq. 6.5) is not exactly 1
                             "mcu.conrod_length_m=0.12", "mcu.conrod_offset_m=0.01"])
    value = 400.0 if mode == "force" else 2e-4
    rig = Rig(cfg, [(mode, value)])
    seen = _watch_outputs(rig.mcu)
    words = []

    def check(r: Rig) -> None:
        leaks = float32_leaks(r.mcu, seen)
        assert not leaks, f"float64 leaked at tick {r.tick}: {leaks}"
        i_ref, v_ff = seen[0][-1]
        down = r.links[0].down
        assert down[B.D_IQ_REF] == int(np.rint(i_ref * F32(1000.0))) & 0xFFFF
        assert down[B.D_VQ_FF] == int(np.rint(v_ff * F32(1000.0))) & 0xFFFF
        words.append(int(down[B.D_IQ_REF]))

    rig.run(0.06, check)  # 300 MCU steps
    ctrl = rig.mcu.ctrl[0]
    assert len(seen[0]) == 300 and len(set(words)) > 20, "the loop did not move"
    assert ctrl.cos_alpha < F32(1.0)
    if controller == "velocity":
        assert ctrl.force_pi.integral != 0 and ctrl.velocity_pi.integral != 0
    else:
        assert ctrl.observer.r != 0 and ctrl.derivative.y != 0
    if feedback == "complementary":
        assert ctrl.highpass.y != 0


@pytest.mark.parametrize("where", ["ctrl.kp", "ctrl.bemf", "meas.v0", "ctrl.k_pos"])
def test_the_float32_check_catches_a_float64_constant(cfg, where):
    """One np.float64 constant anywhere in the chain must show up in the check."""
    mode, value = ("position", 1e-4) if where == "ctrl.k_pos" else ("force", 300.0)
    rig = Rig(cfg, [(mode, value)])
    seen = _watch_outputs(rig.mcu)
    rig.run(0.002)
    assert not float32_leaks(rig.mcu, seen)
    ctrl, meas = rig.mcu.ctrl[0], rig.mcu.meas[0]
    if where == "meas.v0":  # the ADC's zero-pressure voltage, used in every pressure decode
        meas._analog = [(n, r, np.float64(v0) if n == "p_cyl_a" else v0, mul, div)
                        for n, r, v0, mul, div in meas._analog]
    else:
        attr = where.split(".")[1]
        setattr(ctrl, attr, np.float64(getattr(ctrl, attr)))
    rig.cycle()
    leaks = float32_leaks(rig.mcu, seen)
    expected = {"ctrl.kp": "step[0].i_ref", "ctrl.bemf": "step[0].v_ff",
                "meas.v0": "meas[0].p_cyl_a", "ctrl.k_pos": "mcu.tau_ref[0]"}[where]
    assert any(s.startswith(expected + ":") for s in leaks), leaks


# --- (b) command watchdog ----------------------------------------------------------------------
def _until(rig: Rig, cond: Callable[[Rig], bool], seconds: float) -> int:
    for _ in range(round(seconds / (rig.stacks[0].tick_s * rig.period))):
        rig.cycle()
        if cond(rig):
            return rig.tick
    raise AssertionError(f"condition not reached within {seconds} s")


def test_command_timeout_zeroes_the_force_then_safe_off_disables_the_board(cfg):
    rig = Rig(cfg, [("force", 400.0)])
    mcu, stack = rig.mcu, rig.stacks[0]
    rig.run(0.04)
    assert mcu.status[0] & BOARD_ENABLED and not mcu.status[0] & (CMD_TIMEOUT | SAFE_OFF)
    assert abs(stack.y[L.Y_TAU_Q] - 400.0) < 40.0
    rig.commanding = False
    t0 = mcu.last_cmd_tick[0]
    timeout = round(cfg.get("mcu.command_timeout_s") / stack.tick_s)  # 200 ticks, 10 ms
    off = timeout + round(cfg.get("mcu.safe_off_delay_s") / stack.tick_s)  # + 50 ms
    assert (mcu.timeout_ticks, mcu.off_ticks) == (timeout, off)
    history: list[tuple[int, int, np.float32]] = []

    def log(r: Rig) -> None:
        history.append((r.tick, r.mcu.status[0], r.mcu.tau_ref[0]))

    t_out = _until(rig, lambda r: (log(r), r.mcu.status[0] & CMD_TIMEOUT)[1], 0.05)
    # Before the timeout the last command held; at the first step past it the force is zero.
    assert all(tau == F32(400.0) for t, _, tau in history if t < t_out)
    assert timeout < t_out - t0 <= timeout + rig.period
    assert type(mcu.tau_ref[0]) is np.float32 and mcu.tau_ref[0] == 0.0
    assert mcu.status[0] & BOARD_ENABLED and not mcu.status[0] & SAFE_OFF
    # While only CMD_TIMEOUT: the force loop drives the actuator force to zero.
    history.clear()
    t_off = _until(rig, lambda r: (log(r), r.mcu.status[0] & SAFE_OFF)[1], 0.1)
    assert all(s & CMD_TIMEOUT and tau == 0.0 for _, s, tau in history)
    assert off < t_off - t0 <= off + rig.period
    assert abs(stack.y[L.Y_TAU_Q]) < 40.0
    assert stack.board.fsm_state == "enabled"  # the word is on its way down
    rig.run(0.001)  # 5 cycles: the down sweep delivers control = 0
    assert stack.board.down_value("control") == 0
    assert stack.board.fsm_state == "disabled" and not stack.board.pwm_on
    y = stack.y
    assert y[L.Y_IQ] == 0.0 and y[L.Y_ID] == 0.0 and y[L.Y_IA] == 0.0 and y[L.Y_IB] == 0.0
    assert mcu.status[0] & (CMD_TIMEOUT | SAFE_OFF) == CMD_TIMEOUT | SAFE_OFF
    assert not mcu.status[0] & BOARD_ENABLED


def test_a_fresh_command_clears_the_timeout_and_safe_off_needs_a_re_enable(cfg):
    rig = Rig(cfg, [("force", 300.0)])
    mcu, stack = rig.mcu, rig.stacks[0]
    rig.run(0.02)
    rig.commanding = False
    _until(rig, lambda r: r.mcu.status[0] & CMD_TIMEOUT, 0.05)
    mcu.command(0, "force", 250.0, rig.tick)
    rig.cycle()
    assert not mcu.status[0] & CMD_TIMEOUT and mcu.tau_ref[0] == F32(250.0)
    assert mcu.status[0] & BOARD_ENABLED
    # Now all the way to SAFE_OFF; a fresh command alone does not switch the motor on again.
    _until(rig, lambda r: r.mcu.status[0] & SAFE_OFF, 0.1)
    rig.commanding = True
    rig.commands = [("force", 250.0)]
    rig.run(0.005)
    assert not mcu.status[0] & (CMD_TIMEOUT | SAFE_OFF)
    assert stack.board.fsm_state == "disabled" and not mcu.status[0] & BOARD_ENABLED
    mcu.enable(0, stack.board.calibrated_offset)
    rig.run(0.05)
    assert stack.board.fsm_state == "enabled" and mcu.status[0] & BOARD_ENABLED
    assert abs(stack.y[L.Y_TAU_Q] - 250.0) < 25.0


def test_mode_off_never_times_out(cfg):
    rig = Rig(cfg, [("off", 0.0)])
    rig.commanding = False
    rig.run(0.08)
    assert rig.mcu.status[0] & (CMD_TIMEOUT | SAFE_OFF) == 0
    assert rig.mcu.iq_ref[0] == 0.0 and rig.stacks[0].board.down_value("iq_ref") == 0


# --- (c) limits and board/link trouble ---------------------------------------------------------
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_force_command_above_the_limit_is_clamped(cfg, sign):
    rig = Rig(cfg, [("force", sign * 2500.0)])
    f_lim = float(rig.mcu.ctrl[0].f_lim)
    assert f_lim == pytest.approx(1500.0)
    flags = []
    rig.run(0.1, lambda r: flags.append(r.mcu.status[0]))
    assert all(s & FORCE_LIMITED for s in flags)
    # The actuator settles at the limit, not at the command.
    f = rig.mcu.meas[0].f_pres
    assert abs(f - sign * f_lim) < 0.03 * f_lim, f
    assert abs(rig.stacks[0].y[L.Y_TAU_Q] - sign * f_lim) < 0.03 * f_lim
    rig.commands = [("force", sign * 1200.0)]
    rig.run(0.01)
    assert not rig.mcu.status[0] & FORCE_LIMITED


@pytest.mark.parametrize("sign", [1, -1])
def test_current_demand_above_18_a_is_clamped(cfg, sign):
    rig = Rig(cfg, [("force", 0.0)])
    rig.run(0.005)
    rig.commands = [("force", sign * 1000.0)]  # K_p step: tau_p = 3000 N -> 25 A demanded
    rig.mcu.command(0, "force", sign * 1000.0, rig.tick)
    rig.cycle()
    mcu = rig.mcu
    assert mcu.status[0] & CURRENT_LIMITED
    assert mcu.iq_ref[0] == F32(sign * 18.0)
    assert rig.links[0].read("iq") * sign < 1000  # not yet there: the clamp is ours
    rig.run(0.001)
    board = rig.stacks[0].board
    assert board.down_value("iq_ref") == sign * 18000
    peak = []
    rig.run(0.01, lambda r: peak.append(abs(r.stacks[0].y[L.Y_IQ])))
    assert max(peak) < 18.0 + 1.5  # the board's PI follows the clamped reference
    rig.run(0.1)
    assert not mcu.status[0] & CURRENT_LIMITED
    assert abs(rig.stacks[0].y[L.Y_TAU_Q] - sign * 1000.0) < 50.0


def test_corrupted_downstream_words_raise_link_error(cfg):
    rig = Rig(cfg, [("force", 300.0)])
    flags: list[int] = []
    rig.run(0.01, lambda r: flags.append(r.mcu.status[0]))
    assert not any(s & LINK_ERROR for s in flags)
    rig.stacks[0].link_fault("down", corrupt_every=3)
    flags.clear()
    rig.run(0.01, lambda r: flags.append(r.mcu.status[0]))
    assert sum(bool(s & LINK_ERROR) for s in flags) >= len(flags) - 2
    assert rig.stacks[0].board.fsm_state == "enabled"  # 2 words in 3 keep the watchdog fed
    rig.stacks[0].link_fault("down", corrupt_every=0)
    rig.run(0.002)
    assert not rig.mcu.status[0] & LINK_ERROR


def test_saturated_downstream_crc_counter_keeps_link_error(cfg):
    """The board's err_link_crc saturates at 0xFFFF instead of wrapping; from then on new
    errors no longer change it, so the MCU must keep LINK_ERROR up rather than read the
    unchanged count as a clean link."""
    rig = Rig(cfg, [("force", 300.0)])
    rig.run(0.01)
    board = rig.stacks[0].board
    board.state[B.F_ERR_LINK_CRC] = 0xFFFF - 2
    rig.stacks[0].link_fault("down", corrupt_every=3)
    flags: list[int] = []
    rig.run(0.02, lambda r: flags.append(r.mcu.status[0]))
    assert rig.links[0].read("err_link_crc") == 0xFFFF
    assert all(s & LINK_ERROR for s in flags[-50:])


def test_corrupted_upstream_words_raise_link_error(cfg):
    rig = Rig(cfg, [("force", 300.0)])
    rig.run(0.01)
    rig.stacks[0].link_fault("up", corrupt_every=3)
    flags: list[int] = []
    rig.run(0.01, lambda r: flags.append(r.mcu.status[0]))
    assert any(s & LINK_ERROR for s in flags)


def test_stopped_downstream_link_gives_link_error_and_board_fault(cfg):
    rig = Rig(cfg, [("force", 300.0)])
    rig.run(0.01)
    rig.stacks[0].link_fault("down", stopped=True)
    rig.run(0.003)
    s = rig.mcu.status[0]
    assert s & LINK_ERROR and s & BOARD_FAULT and not s & BOARD_ENABLED
    assert "LINK_LOST" in rig.links[0].status()


def test_over_current_trip_reports_board_fault(cfg):
    rig = Rig(cfg, [("force", 500.0)])  # about 4.2 A
    rig.run(0.03)
    assert rig.mcu.status[0] & BOARD_ENABLED and not rig.mcu.status[0] & BOARD_FAULT
    rig.links[0].write("trip_current", 2000)
    rig.run(0.002)
    s = rig.mcu.status[0]
    assert s & BOARD_FAULT and not s & BOARD_ENABLED
    assert {"FAULT", "OVER_CURRENT"} <= rig.links[0].status()
    assert rig.stacks[0].y[L.Y_IQ] == 0.0


# --- (d) five boards ---------------------------------------------------------------------------
FIVE = [-900.0, -350.0, 150.0, 600.0, 1100.0]


@pytest.mark.parametrize("dpram", [False, True], ids=["links", "dpram"])
def test_five_boards_each_get_their_own_command(cfg, dpram):
    rig = Rig(cfg, [("force", f) for f in FIVE], dpram=dpram)
    rig.run(0.08)
    iq_words = [s.board.down_value("iq_ref") for s in rig.stacks]
    assert [np.sign(w) for w in iq_words] == [np.sign(f) for f in FIVE], iq_words
    for i, (f, s) in enumerate(zip(FIVE, rig.stacks, strict=True)):
        assert abs(s.y[L.Y_TAU_Q] - f) < 0.05 * abs(f) + 15.0, (i, s.y[L.Y_TAU_Q], f)
        assert s.board.fsm_state == "enabled"
        assert rig.mcu.status[i] == BOARD_ENABLED, hex(rig.mcu.status[i])
        # Each board's current follows its own reference, about f / K_t,eq (plus friction).
        assert abs(s.y[L.Y_IQ] - iq_words[i] / 1000.0) < 1.0
        assert abs(iq_words[i] / 1000.0 - f / float(rig.mcu.ctrl[i].kt_eq)) < 2.5


@pytest.mark.parametrize("n", [0, 6])
def test_mcu_serves_one_to_five_boards(cfg, n):
    with pytest.raises(ValueError, match=r"1\.\.5 driver boards, got " + str(n)):
        Mcu(cfg, [LinkMemory(cfg) for _ in range(n)])


# --- (e) dual-port memory ----------------------------------------------------------------------
def test_dpram_address_map(cfg):
    ram = D.DualPortRam(cfg)
    seen = set()
    for k in range(D.MAX_BOARDS):
        for addr, name, *_ in B.DOWN_REGISTERS:
            a = D.address(k, name)
            assert a == 0x40 * k + addr and D.decode(a) == (k, "down", addr)
            seen.add(a)
        for addr, name, *_ in B.UP_REGISTERS:
            a = D.address(k, name)
            assert a == 0x40 * k + 0x20 + addr and D.decode(a) == (k, "up", addr)
            seen.add(a)
    assert len(seen) == D.MAX_BOARDS * (len(B.DOWN_REGISTERS) + len(B.UP_REGISTERS))
    assert D.DPRAM_WORDS == 0x140 and max(seen) < D.DPRAM_WORDS
    # Named writes land at the mapped word; raw writes read back by name (typed).
    for k in range(D.MAX_BOARDS):
        v = -1234 - k
        ram.board(k).write("iq_ref", v)
        assert ram.read(D.address(k, "iq_ref")) == to_word(v, "s16", "iq_ref")
        ram.write(D.address(k, "vq_ff"), 0xFFFF - k)
        assert ram.board(k).read("vq_ff") == -1 - k
        ram.write(D.address(k, "sequence"), 0x8000 + k)
        assert ram.board(k).read("sequence") == 0x8000 + k  # u16 stays unsigned
    for k in range(D.MAX_BOARDS):  # no board's write reached another board
        assert ram.board(k).read("iq_ref") == -1234 - k
    # Boot values, as a LinkMemory starts with them.
    fresh = LinkMemory(cfg)
    assert np.array_equal(D.DualPortRam(cfg).board(3).down, fresh.down)
    assert D.markdown() in DOC.read_text(encoding="utf-8"), (
        "docs/mcu.md DPRAM table is stale: paste firmware_model.mcu.dpram.markdown()")


def test_dpram_rejects_bad_addresses_and_values(cfg):
    ram = D.DualPortRam(cfg)
    for bad in (-1, 0x140, 0x1000):
        with pytest.raises(ValueError, match="outside 0x000..0x13F"):
            ram.read(bad)
        with pytest.raises(ValueError, match="outside 0x000..0x13F"):
            ram.write(bad, 0)
    with pytest.raises(ValueError, match="board 1's reserved gap"):
        ram.read(0x55)
    with pytest.raises(ValueError, match="board 2's reserved gap"):
        ram.write(0x90, 1)
    with pytest.raises(ValueError, match="upstream block"):
        ram.write(D.address(0, "status"), 1)
    for value in (-1, 0x10000):
        with pytest.raises(ValueError, match="outside 0..0xFFFF"):
            ram.write(0x002, value)
    with pytest.raises(ValueError, match="outside s16 range"):
        ram.board(0).write("iq_ref", 40000)
    with pytest.raises(KeyError, match="no register 'bogus'"):
        ram.board(0).read("bogus")
    with pytest.raises(KeyError, match="no downstream register 'status'"):
        ram.board(0).write("status", 1)  # upstream registers are not written by name either
    for k in (-1, 5):
        with pytest.raises(ValueError, match="boards 0..4"):
            ram.board(k)
    assert ram.read(0x13F) == 0  # the last word is mapped (board 4's spare upstream word)


def test_dpram_sync_copies_both_ways_and_only_its_boards(cfg):
    rng = np.random.default_rng(3)
    ram = D.DualPortRam(cfg)
    links = [LinkMemory(cfg), LinkMemory(cfg)]
    for k, link in enumerate(links):
        link.up[:] = rng.integers(0, 0x10000, B.UP_WORDS)
        ram.board(k).write("iq_ref", 1000 * (k + 1))
        ram.board(k).write("sequence", 77 + k)
    ram.board(3).write("iq_ref", 4242)  # board 3 has no link here
    before = ram.words.copy()
    ram.sync(links)
    assert ram.cycles == 1
    for k, link in enumerate(links):
        d, u = D.down_base(k), D.up_base(k)
        assert np.array_equal(link.down, before[d:d + B.DOWN_WORDS])
        assert np.array_equal(ram.words[u:u + B.UP_WORDS], link.up)
        assert link.read("status") == ram.board(k).read("status")
    assert links[0].down[B.D_IQ_REF] == 1000 and links[1].down[B.D_IQ_REF] == 2000
    # Everything else is untouched: downstream blocks and gaps of all, boards 2..4 entirely.
    changed = np.flatnonzero(ram.words != before)
    assert all(D.decode(int(a))[:2] in ((0, "up"), (1, "up")) for a in changed)
    assert np.array_equal(ram.words[0x80:], before[0x80:])
    assert ram.board(3).read("iq_ref") == 4242
    # The MCU's next writes go out with the next sync, not before.
    ram.board(0).write("iq_ref", -5)
    assert links[0].down[B.D_IQ_REF] == 1000
    ram.sync(links)
    assert links[0].read("status") == ram.board(0).read("status")
    assert LinkMemory.read(links[0], "status") == int(links[0].up[B.U_STATUS])
    assert links[0].down[B.D_IQ_REF] == to_word(-5, "s16", "iq_ref")
    for bad in ([], [LinkMemory(cfg) for _ in range(6)]):
        with pytest.raises(ValueError, match="1..5 link memories"):
            ram.sync(bad)
    with pytest.raises(ValueError, match="view of this DPRAM"):
        ram.sync([ram.board(0)])


def test_mcu_through_the_dpram_is_bit_identical_to_direct_link_access(cfg):
    """sync_up -> step -> sync_down adds nothing: the same words reach the same boards."""
    direct = Rig(cfg, [("force", 700.0), ("force", -200.0)])
    via = Rig(cfg, [("force", 700.0), ("force", -200.0)], dpram=True)
    for _ in range(150):
        direct.cycle()
        via.cycle()
        for a, b in zip(direct.stacks, via.stacks, strict=True):
            assert np.array_equal(a.mcu_link.down, b.mcu_link.down)
            assert np.array_equal(a.y, b.y)
    assert via.ram is not None and via.ram.board(1).read("iq_ref") < 0


def test_one_sync_per_cycle_before_the_step_delays_the_downstream_by_one_period(cfg):
    stack = FpgaStack(cfg)
    ram = D.DualPortRam(cfg)
    mcu = Mcu(cfg, [ram.board(0)])
    mcu.command(0, "force", 300.0, 0)
    mcu.enable(0, stack.board.calibrated_offset)
    for _ in range(20):
        stack.advance(mcu.period)
        ram.sync([stack.mcu_link])
        mcu.step(stack.tick)
        assert stack.mcu_link.down[B.D_SEQUENCE] == mcu._seq - 1  # the previous step's words
        assert ram.board(0).read("sequence") == mcu._seq
    assert stack.board.fsm_state == "enabled"


def test_controller_is_float32_from_a_fresh_object(cfg):
    """Construction alone gives float32 constants and states (no step needed)."""
    ctrl = ActuatorController(cfg)
    bad = [n for n in CTRL_FLOATS if type(getattr(ctrl, n)) is not np.float32]
    assert not bad


def _meas(cfg: Config, f_pres: float, f_strain: float) -> Measurements:
    """Measurements with a steady pressure force and strain force, the rest at rest."""
    m = Measurements(cfg)
    for name in ("p_acc", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "tau_q", "omega_m",
                 "v_pump", "x_piston", "iq", "theta_rotor", "temperature_c"):
        setattr(m, name, F32(0.0))
    m.f_pres = F32(f_pres)
    m.f_strain_raw = F32(f_strain)
    m.strain_samples = 1
    return m


def test_seal_observer_learns_the_seal_force_and_adds_it_to_the_reference(cfg):
    """Strain feedback: a steady 12 N gap between pressure and rod force (seal friction)
    is estimated at the observer's rate and added to the pressure reference."""
    c_cfg = cfg.with_overrides({"mcu.force_feedback": "strain"})
    ctrl = ActuatorController(c_cfg)
    fc = c_cfg.get("mcu.seal_observer_hz")
    m = _meas(c_cfg, f_pres=100.0, f_strain=88.0)
    n_tau = int(round(1.0 / (2 * np.pi * fc) / float(ctrl.dt)))
    for _ in range(n_tau):
        ctrl.step(m, F32(100.0))
    assert 0.55 < float(ctrl.seal_observer.y) / 12.0 < 0.7  # one time constant: 1 - 1/e
    for _ in range(20 * n_tau):
        i_ref, _ = ctrl.step(m, F32(100.0))
    assert abs(float(ctrl.seal_observer.y) - 12.0) < 0.01
    # The loop now asks for 112 N of pressure force: PD error (112 - 100) times kp on top.
    kp = c_cfg.get("mcu.kp_force")
    expect = (112.0 + kp * 12.0 - float(ctrl.observer.r)) / float(ctrl.kt_eq)
    assert float(i_ref) == pytest.approx(expect, rel=1e-4)
    assert type(ctrl.seal_observer.y) is np.float32


def test_pressure_feedback_has_no_seal_term(cfg):
    ctrl = ActuatorController(cfg)
    m = _meas(cfg, f_pres=100.0, f_strain=88.0)
    for _ in range(500):
        ctrl.step(m, F32(100.0))
    assert float(ctrl.seal_observer.y) == 0.0


def test_complementary_filter_starts_on_the_first_strain_conversion(cfg):
    """Before the AD7195's first conversion its register reads code 0 (-3000 N); the Eq. 4.4
    high-pass must not start on that, or the 3000 N step leaks out for seconds."""
    ctrl = ActuatorController(cfg.with_overrides({"mcu.force_feedback": "complementary"}))
    m = _meas(cfg, f_pres=100.0, f_strain=-3000.0)
    m.strain_samples = 0
    for _ in range(20):
        assert ctrl.step(m, F32(100.0)) is not None and ctrl.f_fil == F32(100.0)
    m.f_strain_raw, m.strain_samples = F32(95.0), 1
    ctrl.step(m, F32(100.0))
    assert ctrl.f_fil == F32(100.0)  # starts at rest on the valid sample
    for _ in range(1000):
        ctrl.step(m, F32(100.0))
    assert abs(float(ctrl.f_fil) - 100.0) < 0.1  # the constant gap decays, no -3000 N leak
