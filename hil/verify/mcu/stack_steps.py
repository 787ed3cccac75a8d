"""MCU input steps recorded from whole-stack runs (plant, driver board, LVDS link, MCU) with
faults: what the MCU program saw at each of its cycles, as ``mcu_input`` records."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    INPUT,
    MODES,
)
from hil.sim.actuator import ActuatorStack
from plant.config import Config

#: Faults, as fractions of the run: (start, end) of each.
UP_CORRUPT = (0.15, 0.2)     # every 7th upstream word fails its CRC
DOWN_STOPPED = (0.35, 0.4)   # the board loses the link and trips; the PC clears and re-enables
PC_SILENT = (0.6, 0.8)       # no commands: CMD_TIMEOUT, then SAFE_OFF


def _command(t_s: float) -> tuple[str, float]:
    """Force steps and a sine, then a position hold: every mode the PC sends."""
    if t_s < 0.05:
        return "off", 0.0
    if t_s < 0.5:
        return "force", 300.0 * math.sin(2 * math.pi * 7 * t_s) + (400.0 if t_s % 0.2 > 0.1
                                                                      else -200.0)
    return "position", 0.002 * math.sin(2 * math.pi * 3 * t_s)


class _Recorder:
    """Wraps the stack's MCU task and the MCU's command entry; one record per MCU step."""

    def __init__(self, stack: ActuatorStack) -> None:
        mcu = self.mcu = stack.mcu
        self.link = stack.fpga.mcu_link
        self.rows: list[np.ndarray] = []
        self.status: list[int] = []  # the MCU's status word after each step
        self.flags = IN_COMMAND | IN_ENABLE  # what the stack's constructor did
        self.offset = int(stack.fpga.board.calibrated_offset)  # the constructor's enable
        self.cmd = (mcu.mode[0], float(mcu.value[0]), mcu.last_cmd_tick[0])
        command, enable, disable, clear = mcu.command, mcu.enable, mcu.disable, mcu.clear_fault

        def on_command(i: int, mode: str, value: float, tick: int) -> None:
            command(i, mode, value, tick)
            self.flags |= IN_COMMAND
            self.cmd = (mode, value, tick)

        def on_enable(i: int, angle_offset: int) -> None:
            enable(i, angle_offset)
            self.flags |= IN_ENABLE
            self.offset = angle_offset

        def on_disable(i: int) -> None:
            disable(i)
            self.flags |= IN_DISABLE

        def on_clear_fault(i: int) -> None:
            clear(i)
            self.flags |= IN_CLEAR_FAULT

        mcu.command, mcu.enable = on_command, on_enable
        mcu.disable, mcu.clear_fault = on_disable, on_clear_fault
        for k, task in enumerate(stack.sched.tasks):
            if task.name == "mcu":
                stack.sched.tasks[k] = dataclasses.replace(task, fn=self.step)

    def step(self, tick: int) -> None:
        rec = np.zeros((), dtype=INPUT)
        rec["tick"], rec["flags"] = tick, self.flags
        if self.flags & IN_COMMAND:
            mode, value, stamp = self.cmd
            if stamp != tick:
                raise RuntimeError(f"command stamped {stamp} reached the MCU step at {tick}")
            rec["mode"], rec["value"] = MODES.index(mode), value
        rec["angle_offset"] = self.offset
        rec["up"] = self.link.up
        rec["up_crc_errors"] = self.link.up_crc_errors
        self.rows.append(rec)
        self.flags = 0
        self.mcu.step(tick)
        self.status.append(int(self.mcu.status[0]))


def stack_inputs(cfg: Config, seconds: float) -> np.ndarray:
    """Run the whole stack on ``cfg`` for ``seconds`` with the faults above; the MCU's
    input at each of its steps."""
    return stack_run(cfg, seconds)[0]


def stack_run(cfg: Config, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stack_inputs`, and the MCU's status word after each step (CMD_TIMEOUT,
    SAFE_OFF, LINK_ERROR, ...: the watchdog's and the link check's answers)."""
    stack = ActuatorStack(cfg, _command)
    rec = _Recorder(stack)
    silent = False
    pc = next(t for t in stack.sched.tasks if t.name == "pc")

    def pc_task(tick: int) -> None:
        if not silent:
            pc.fn(tick)

    stack.sched.tasks[stack.sched.tasks.index(pc)] = dataclasses.replace(pc, fn=pc_task)
    edges = sorted({x for pair in (UP_CORRUPT, DOWN_STOPPED, PC_SILENT) for x in pair})
    fpga, t0 = stack.fpga, 0.0
    for t in (*edges, 1.0):
        stack.run((t - t0) * seconds)
        t0 = t
        if t == UP_CORRUPT[0] or t == UP_CORRUPT[1]:
            fpga.link_fault("up", corrupt_every=7 if t == UP_CORRUPT[0] else 0)
        elif t == DOWN_STOPPED[0]:
            fpga.link_fault("down", stopped=True)
        elif t == DOWN_STOPPED[1]:
            fpga.link_fault("down", stopped=False)
            stack.mcu.disable(0)                  # the PC's clear-fault sequence
            stack.run(0.001)
            stack.mcu.clear_fault(0)
            stack.run(0.001)
            stack.mcu.enable(0, fpga.board.calibrated_offset)
        elif t == PC_SILENT[0]:
            silent = True
        elif t == PC_SILENT[1]:
            silent = False
            stack.mcu.enable(0, fpga.board.calibrated_offset)
    return np.array(rec.rows, dtype=INPUT), np.array(rec.status, dtype=np.uint32)
