"""pytest-benchmark cases for the driver board on the plant (value level).

Run with ``.venv/bin/python -m pytest tests/bench --benchmark-enable``; the normal suite runs
each once as a smoke test. No timing is asserted.
"""

from __future__ import annotations

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import DriverBoard
from firmware_model.fpga.tick import control_tick
from hil.sim.actuator import FpgaStack


def test_fpga_stack_one_second(benchmark, default_cfg):
    """Plant + board + link for 20,000 ticks in one compiled call."""
    stack = FpgaStack(default_cfg)
    stack.boot()
    stack.mcu_link.write("iq_ref", 5000)
    benchmark(stack.advance, 20000)
    assert stack.board.fsm_state == "enabled"


def test_board_tick_call(benchmark, default_cfg):
    """One control tick called from Python (the bit-level path pays this per tick)."""
    board = DriverBoard(default_cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    raw[[B.R_IA, B.R_IB]] = 2048

    def thousand() -> None:
        for _ in range(1000):
            control_tick(board.params, board.state, board.down, board.up, raw)

    benchmark(thousand)
    assert board.state[B.F_TICK] >= 1000
