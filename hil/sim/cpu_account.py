"""Where a served chain's wall time went, as the kernel counts it, to tell a late reply's
cause: the hypervisor not running this machine's CPUs (*steal*, ``/proc/stat``), or a
thread runnable but waiting for its CPU inside this machine (*run delay*,
``/proc/thread-self/schedstat``).

A virtual machine's CPU is a thread on its host: when the host runs something else (or
throttles the machine's CPU quota), every thread here stops, whatever its priority, and
the only trace inside is the steal counter. A reply late by that much is the host's, not
the frame path's.
"""

from __future__ import annotations

import os

#: /proc/stat counts in USER_HZ ticks.
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def steal_s() -> dict[int, float] | None:
    """Per CPU: time [s] its hypervisor did not run it since boot (None: not Linux)."""
    try:
        with open("/proc/stat") as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    out = {}
    for line in lines:
        if line.startswith("cpu") and line[3:4].isdigit():
            parts = line.split()
            if len(parts) > 8:
                out[int(parts[0][3:])] = int(parts[8]) * _TICK_S
    return out


def steal_during(before: dict[int, float] | None,
                 after: dict[int, float] | None) -> dict[str, float] | None:
    """Per CPU ("cpu0" ...): stolen time [ms] between two :func:`steal_s` readings."""
    if before is None or after is None:
        return None
    return {f"cpu{c}": round((after[c] - before.get(c, 0.0)) * 1e3, 1) for c in sorted(after)}


def run_delay_ns(tid: int | None = None) -> int | None:
    """Time [ns] thread ``tid`` (default: the calling thread) was runnable but waited for
    its CPU, since it started; None if the kernel does not say."""
    path = "/proc/thread-self/schedstat" if tid is None else f"/proc/self/task/{tid}/schedstat"
    try:
        with open(path) as f:
            return int(f.read().split()[1])
    except (OSError, IndexError, ValueError):
        return None
