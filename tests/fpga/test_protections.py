"""Driver-board protections on the full value-level stack: link watchdog, over-current trip,
and the enable state machine that will not switch on with a fault present."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.fpga.params import board_params, down_defaults
from firmware_model.fpga.tick import control_tick
from hil.sim.actuator import FpgaStack
from plant import layout as L
from plant.config import load_config


@pytest.fixture(scope="module")
def cfg():
    return load_config(None, ["load.kind=fixed"])


def _running(cfg, iq_ma: int = 10000) -> FpgaStack:
    stack = FpgaStack(cfg)
    stack.boot()
    stack.mcu_link.write("iq_ref", iq_ma)
    stack.advance(200)
    assert stack.board.fsm_state == "enabled"
    assert abs(stack.y[L.Y_IQ] - iq_ma / 1000) < 0.5
    return stack


def _ticks_until_trip(stack: FpgaStack, limit: int = 200) -> int:
    for k in range(1, limit + 1):
        stack.advance(1)
        if not stack.board.pwm_on:
            return k
    raise AssertionError("the board never switched the PWM off")


@pytest.mark.parametrize("fault", [{"stopped": True}, {"corrupt_every": 1}])
def test_watchdog_trips_within_its_time_and_current_decays(cfg, fault):
    stack = _running(cfg)
    wd_ticks = int(stack.board.params[B.C_WD_TICKS])
    crc_before = stack.board.up_value("err_link_crc")
    stack.link_fault("down", **fault)
    k = _ticks_until_trip(stack)
    # The last good word arrived in the tick before the fault at the latest.
    assert k <= wd_ticks, f"tripped after {k} ticks, watchdog is {wd_ticks}"
    assert k >= wd_ticks - 2, f"tripped after only {k} ticks (watchdog {wd_ticks})"
    assert stack.board.fsm_state == "fault"
    stack.advance(2)
    assert stack.y[L.Y_IQ] == 0.0 and stack.y[L.Y_IA] == 0.0
    status = stack.mcu_link.status()  # the upstream direction still works
    assert {"LINK_LOST", "FAULT"} <= status and "ENABLED" not in status
    assert stack.mcu_link.read("wd_trips") == 1
    if "corrupt_every" in fault:
        assert stack.board.up_value("err_link_crc") - crc_before >= 10 * (k - 1)
    # The pressure force decays with no motor torque.
    tq = stack.y[L.Y_TAU_Q]
    stack.advance(2000)
    assert abs(stack.y[L.Y_TAU_Q]) < 0.2 * abs(tq)


def test_occasional_corrupt_words_are_discarded_and_counted_without_a_trip(cfg):
    stack = _running(cfg)
    stack.link_fault("down", corrupt_every=5)
    stack.advance(400)
    assert stack.board.fsm_state == "enabled"
    words = 400 * 500 // 45
    crc = stack.board.up_value("err_link_crc")
    assert abs(crc - words / 5) <= 2
    # A discarded word never reaches the memory half-applied: the reference is intact.
    assert stack.board.down_value("iq_ref") == 10000


def test_over_current_trips_and_latches(cfg):
    stack = _running(cfg, iq_ma=4000)
    stack.mcu_link.write("trip_current", 8000)
    stack.advance(5)
    stack.mcu_link.write("iq_ref", 12000)
    k = _ticks_until_trip(stack, 40)
    assert k <= 10
    stack.advance(2)
    assert stack.y[L.Y_IQ] == 0.0
    st = stack.mcu_link.status()
    assert {"OVER_CURRENT", "FAULT"} <= st
    assert stack.mcu_link.read("oc_trips") == 1
    # Enable still held: the board stays in fault, it does not re-arm itself.
    stack.advance(100)
    assert stack.board.fsm_state == "fault" and stack.y[L.Y_IQ] == 0.0


def test_fault_is_cleared_only_with_enable_low_then_enable_works(cfg):
    stack = _running(cfg, iq_ma=4000)
    stack.mcu_link.write("trip_current", 3000)
    _ticks_until_trip(stack, 20)
    stack.mcu_link.write("trip_current", 30000)
    # CLEAR_FAULT while ENABLE is still set: refused.
    stack.mcu_link.write("control", B.CTRL_ENABLE | B.CTRL_CLEAR_FAULT)
    stack.advance(10)
    assert stack.board.fsm_state == "fault"
    stack.mcu_link.write("control", 0)
    stack.advance(10)
    stack.mcu_link.write("control", B.CTRL_CLEAR_FAULT)
    stack.advance(10)
    assert stack.board.fsm_state == "disabled"
    assert "FAULT" not in stack.mcu_link.status()
    stack.mcu_link.write("control", B.CTRL_ENABLE)
    stack.advance(200)
    assert stack.board.fsm_state == "enabled"
    assert abs(stack.y[L.Y_IQ] - 4.0) < 0.3


def _board(cfg):
    c = board_params(cfg)
    st = np.zeros(B.N_STATE, dtype=np.int64)
    down = down_defaults(cfg)
    up = np.zeros(B.UP_WORDS, dtype=np.int64)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    raw[[B.R_SSI_OK, B.R_BISS_OK]] = 1
    raw[[B.R_IA, B.R_IB]] = 2048
    down[B.D_MODE] = B.BoardMode.CURRENT
    down[B.D_CONTROL] = B.CTRL_ENABLE
    return c, st, down, up, raw


def test_enable_refused_with_encoder_error_or_dead_link(cfg):
    c, st, down, up, raw = _board(cfg)
    raw[B.R_SSI_OK] = 0
    st[B.F_SINCE_VALID] = 0
    control_tick(c, st, down, up, raw)
    assert st[B.F_STATE] == B.STATE_DISABLED
    assert up[B.U_STATUS] & B.ST_ENABLE_REFUSED and up[B.U_STATUS] & B.ST_ENCODER_ERROR
    assert up[B.U_ERR_SSI] == 1
    raw[B.R_SSI_OK] = 1
    st[B.F_SINCE_VALID] = c[B.C_WD_TICKS]  # no valid word for the watchdog time
    control_tick(c, st, down, up, raw)
    assert st[B.F_STATE] == B.STATE_DISABLED and up[B.U_STATUS] & B.ST_ENABLE_REFUSED
    st[B.F_SINCE_VALID] = 0
    control_tick(c, st, down, up, raw)
    assert st[B.F_STATE] == B.STATE_ENABLED
    assert not up[B.U_STATUS] & B.ST_ENABLE_REFUSED


def test_mode_off_disables_and_pwm_stops(cfg):
    c, st, down, up, raw = _board(cfg)
    st[B.F_SINCE_VALID] = 0
    assert control_tick(c, st, down, up, raw) == 1
    down[B.D_MODE] = B.BoardMode.OFF
    st[B.F_SINCE_VALID] = 0
    assert control_tick(c, st, down, up, raw) == 0
    assert st[B.F_STATE] == B.STATE_DISABLED
