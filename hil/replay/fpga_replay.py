"""Bit-exact replay of the driver-board (FPGA) model against logged board traces.

A trace (``/fpga/b.k/trace``, logged at level "full" by :mod:`hil.replay.record`) holds per
tick what the board took in (raw sensor words; the downstream memory, link-watchdog count
and CRC-error count the LVDS receive endpoint left) and what it gave out (upstream memory,
PWM on, compare counts); columns in :data:`hil.sim.actuator.TRACE_WIDTH`. The replay runs
the current board model (``control_tick``, compiled) from its boot state over the logged
inputs and stops at the first tick whose outputs differ. Not replayed: the LVDS receive
endpoint itself (which words arrived, their CRC check); its result is an input here, and
the link codec has its own tests.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import DriverBoard
from firmware_model.fpga.tick import control_tick
from hil.sim.actuator import (
    TRACE_DOWN,
    TRACE_DUTY,
    TRACE_LINK,
    TRACE_ON,
    TRACE_RAW,
    TRACE_UP,
    TRACE_WIDTH,
)
from plant.config import Config

UP_NAMES = [name for _addr, name, *_ in B.UP_REGISTERS]


@njit(cache=True)
def _replay(c, st, down, up, raw, trace):
    """Index (row, column) of the first output that differs, or (-1, -1)."""
    n_raw = raw.shape[0]
    n_down = down.shape[0]
    n_up = up.shape[0]
    for j in range(trace.shape[0]):
        for i in range(n_raw):
            raw[i] = trace[j, TRACE_RAW + i]
        for i in range(n_down):
            down[i] = trace[j, TRACE_DOWN + i]
        st[B.F_SINCE_VALID] = trace[j, TRACE_LINK]
        st[B.F_ERR_LINK_CRC] = trace[j, TRACE_LINK + 1]
        on = control_tick(c, st, down, up, raw)
        for i in range(n_up):
            if up[i] != trace[j, TRACE_UP + i]:
                return j, TRACE_UP + i
        if on != trace[j, TRACE_ON]:
            return j, TRACE_ON
        if st[B.F_DUTY_A] != trace[j, TRACE_DUTY]:
            return j, TRACE_DUTY
        if st[B.F_DUTY_B] != trace[j, TRACE_DUTY + 1]:
            return j, TRACE_DUTY + 1
        if st[B.F_DUTY_C] != trace[j, TRACE_DUTY + 2]:
            return j, TRACE_DUTY + 2
    return -1, -1


def current_trace(frames: np.ndarray) -> np.ndarray | None:
    """A logged trace in today's columns (:data:`TRACE_WIDTH`), or None if its width fits no
    layout. A log written before raw words were appended gets them as zero columns: the
    inputs of parts that did not exist then read 0, and their registers were 0 too."""
    if frames.ndim != 2:
        return None
    missing = TRACE_WIDTH - frames.shape[1]
    if missing == 0:
        return frames
    if not 0 < missing <= B.N_RAW - B.FIRST_N_RAW:
        return None
    at = TRACE_RAW + B.N_RAW - missing
    zeros = np.zeros((frames.shape[0], missing), dtype=frames.dtype)
    return np.concatenate([frames[:, :at], zeros, frames[:, at:]], axis=1)


def column_name(col: int) -> str:
    """The output a trace column holds."""
    if TRACE_UP <= col < TRACE_ON:
        return UP_NAMES[col - TRACE_UP] if col - TRACE_UP < len(UP_NAMES) else f"up[{col}]"
    if col == TRACE_ON:
        return "pwm_on"
    return "duty_" + "abc"[col - TRACE_DUTY]


def replay_board_detail(cfg: Config, trace: np.ndarray) -> tuple[int, int, int]:
    """Replay one board's trace from boot: (row, column, what the model gave) of the first
    difference, or (-1, -1, 0). The kernel stops at the difference, so the board's state
    then holds the value it gave."""
    bd = DriverBoard(cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    row, col = _replay(bd.params, bd.state, bd.down, bd.up, raw,
                       np.ascontiguousarray(trace, dtype=np.int64))
    if row < 0:
        return -1, -1, 0
    if col < TRACE_ON:
        got = bd.up[col - TRACE_UP]
    elif col == TRACE_ON:
        got = int(trace[row, col] == 0)  # the on flag is 0 or 1: a difference flips it
    else:
        got = bd.state[(B.F_DUTY_A, B.F_DUTY_B, B.F_DUTY_C)[col - TRACE_DUTY]]
    return int(row), int(col), int(got)


def replay_board(cfg: Config, trace: np.ndarray) -> tuple[int, int]:
    """(row, column) of the first difference of one board's replay, or (-1, -1)."""
    row, col, _ = replay_board_detail(cfg, trace)
    return row, col


def warm_up(cfg: Config) -> None:
    """Load (or compile) the replay kernel, so that timing a replay measures the replay."""
    replay_board(cfg, np.zeros((0, TRACE_WIDTH), dtype=np.int64))
