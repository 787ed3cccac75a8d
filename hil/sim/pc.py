"""PC loops: what the PC does each 1 kHz cycle on the fieldbus master, as a function
``pc(cycle, master)`` the bus system calls before the cycle's frames go out."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hil.fieldbus.master import Master


def demo_commands(cycle: int, n: int, amplitude_n: float, frequency_hz: float
                  ) -> list[float]:
    """The demo loop's force commands (N) of ``n`` actuators at ``cycle`` (1 ms each): a
    sine, actuator ``j`` phase-shifted by 0.4 j rad. The readable reference of
    :func:`demo_commands_into`."""
    t = cycle * 1e-3
    # math.sin, not numpy's: numpy may pick a SIMD sine by CPU, and the commands must
    # be the same bits on every machine.
    return [amplitude_n * math.sin(2.0 * math.pi * frequency_hz * t + 0.4 * j)
            for j in range(n)]


@njit(cache=True, nogil=True)
def demo_commands_into(out, cycle, amplitude_n, frequency_hz):
    """:func:`demo_commands` into ``out`` in one compiled call: the same float64 operations
    in the same order (no fast-math), the same libm ``sin`` as Python's ``math.sin``, so the
    same bits (``tests/hil/test_pc_loop.py``)."""
    t = cycle * 1e-3
    for j in range(out.shape[0]):
        out[j] = amplitude_n * math.sin(2.0 * math.pi * frequency_hz * t + 0.4 * j)


def demo_pc(amplitude_n: float = 300.0, frequency_hz: float = 2.0):
    """The default PC loop: a force sine on every actuator, each a little phase-shifted."""
    commands = np.zeros(0)

    def pc(cycle: int, m: Master) -> None:
        nonlocal commands
        if commands.shape[0] != len(m.act_offsets):
            commands = np.zeros(len(m.act_offsets))
        demo_commands_into(commands, cycle, amplitude_n, frequency_hz)
        m.set_actuators("force", commands)

    return pc
