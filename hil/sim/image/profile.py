"""Execution time of an image, as processor-in-the-loop tools report it: per 5 kHz step the
instruction count and estimated cycles (hil/sim/image/cost.py), their mean and max, the worst
step, and the share of the 200 us period at 168 MHz. Every image MCU made while a command
runs adds its steps to :data:`SESSION`, which ``run`` and ``verify`` print."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hil.sim.image import cost


@dataclass
class Profile:
    label: str = ""
    instructions: list[int] = field(default_factory=list)
    cycles: list[int] = field(default_factory=list)
    worst_step: str = ""
    max_cycles: int = 0

    def add(self, instructions: int, cycles: int, step: str) -> None:
        if cycles > self.max_cycles or not self.cycles:
            self.worst_step, self.max_cycles = step, cycles
        self.instructions.append(instructions)
        self.cycles.append(cycles)

    @property
    def steps(self) -> int:
        return len(self.cycles)

    def summary(self) -> dict:
        i = np.asarray(self.instructions, dtype=np.int64)
        c = np.asarray(self.cycles, dtype=np.int64)
        if not len(c):
            return {"label": self.label, "steps": 0}
        us = c / cost.CLOCK_HZ * 1e6
        return {"label": self.label, "steps": int(len(c)),
                "instructions_mean": float(i.mean()), "instructions_max": int(i.max()),
                "cycles_mean": float(c.mean()), "cycles_max": int(c.max()),
                "us_mean": float(us.mean()), "us_max": float(us.max()),
                "period_share_max": float(c.max() / cost.PERIOD_CYCLES),
                "margin_us": float(cost.PERIOD_S * 1e6 - us.max()),
                "worst_step": self.worst_step}


def line(s: dict) -> str:
    """One line of a profile summary."""
    if not s.get("steps"):
        return f"{s.get('label', 'image')}: no steps"
    return (f"{s['label']}: {s['steps']:,} steps, instructions mean {s['instructions_mean']:.0f} "
            f"max {s['instructions_max']}, est. cycles mean {s['cycles_mean']:.0f} max "
            f"{s['cycles_max']} = {s['us_max']:.2f} us = {100 * s['period_share_max']:.1f} % "
            f"of the {cost.PERIOD_S * 1e6:.0f} us period at {cost.CLOCK_HZ / 1e6:.0f} MHz "
            f"(worst: {s['worst_step']})")


#: Profiles of the image MCUs made during this command, in order.
SESSION: list[Profile] = []


def session_summary(label: str) -> dict | None:
    """All of this command's image steps as one summary (None: no image ran)."""
    if not SESSION:
        return None
    total = Profile(label)
    worst = max(SESSION, key=lambda p: p.max_cycles)
    for p in SESSION:
        total.instructions += p.instructions
        total.cycles += p.cycles
    total.worst_step = f"{worst.label} {worst.worst_step}".strip()
    total.max_cycles = worst.max_cycles
    return total.summary()


def take(label: str) -> dict | None:
    """:func:`session_summary`, then forget the session's steps (the next scenario's own)."""
    out = session_summary(label)
    SESSION.clear()
    return out
