"""PC loops: what the PC does each 1 kHz cycle on the fieldbus master, as a function
``pc(cycle, master)`` the bus system calls before the cycle's frames go out."""

from __future__ import annotations

import math

from hil.fieldbus.master import Master


def demo_pc(amplitude_n: float = 300.0, frequency_hz: float = 2.0):
    """The default PC loop: a force sine on every actuator, each a little phase-shifted."""

    def pc(cycle: int, m: Master) -> None:
        t = cycle * 1e-3
        # math.sin, not numpy's: numpy may pick a SIMD sine by CPU, and the commands must
        # be the same bits on every machine.
        m.set_actuators("force", [amplitude_n * math.sin(2.0 * math.pi * frequency_hz * t
                                                         + 0.4 * j)
                                  for j in range(len(m.act_offsets))])

    return pc
