"""Reply times of a served chain: a 1 us histogram, its percentiles and its decades.

Every transport of ``eha-hil serve`` reports its replies the same way: p50 / p99 / p99.9 /
max, the histogram in decades, and how many were later than the late limit. Percentiles
are read off the histogram (the upper edge of their 1 us bin), the maximum is exact.
"""

from __future__ import annotations

import numpy as np

#: 1 us bins; the last one holds everything from HIST_US us on.
HIST_US = 20_000


class ReplyTimes:
    """Reply times recorded one by one from Python (the serial/udp server)."""

    def __init__(self, late_us: float) -> None:
        self.hist = np.zeros(HIST_US + 1, dtype=np.int64)
        self.late_us = late_us
        self.late = 0
        self.max_us = 0.0

    def add(self, us: float) -> None:
        self.hist[min(max(int(us), 0), HIST_US)] += 1
        if us > self.late_us:
            self.late += 1
        if us > self.max_us:
            self.max_us = us


def summary(hist: np.ndarray, max_us: float) -> dict:
    """p50/p99/p99.9/max [us] (None each if nothing was answered)."""
    total = int(hist.sum())
    if not total:
        return {"p50": None, "p99": None, "p99_9": None, "max": None}
    cum = np.cumsum(hist)
    out = {key: float(np.searchsorted(cum, q * total) + 1)
           for key, q in (("p50", 0.5), ("p99", 0.99), ("p99_9", 0.999))}
    out["max"] = float(max_us)
    return out


def decades(hist: np.ndarray) -> dict[str, int]:
    """The histogram in ranges: "lo-hi us" -> replies."""
    edges = [0, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, len(hist) - 1]
    out = {f"{lo}-{hi} us": int(hist[lo:hi].sum())
           for lo, hi in zip(edges[:-1], edges[1:], strict=True)}
    out[f">= {len(hist) - 1} us"] = int(hist[-1])
    return out


def line(d: dict) -> str:
    """``p50 / p99 / p99.9 / max`` of a :func:`summary`, in us."""
    return " / ".join("-" if d[k] is None else f"{d[k]:.0f}"
                      for k in ("p50", "p99", "p99_9", "max")) + " us"
