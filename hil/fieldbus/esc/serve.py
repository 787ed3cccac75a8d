"""Serve the chain of ESC slaves on a raw Ethernet interface, paced to the wall clock:
``eha-hil serve --transport ethercat --interface IF --topology hydra_full``.

Cycle ``k`` of the boxes (1 ms simulated) is released at ``t0 + k * 1 ms`` (as in
:mod:`hil.cli.serve`); between releases every arriving frame is answered at once. A loop that
falls more than 50 cycles behind moves its schedule forward (slipped cycles).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

from hil.fieldbus.esc.chain import EscChain
from hil.transports.rawether import RawEthernet

PERIOD_S = 1e-3
MAX_LAG_CYCLES = 50


@dataclass
class EcatServeStats:
    cycles: int = 0
    wall_s: float = 0.0
    overruns: int = 0
    slipped_cycles: int = 0
    frames_received: int = 0
    frames_answered: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


def serve(chain: EscChain, link: RawEthernet, seconds: float | None = None,
          stop: Callable[[], bool] = lambda: False) -> EcatServeStats:
    """Run until ``seconds`` of wall time pass or ``stop()`` returns True."""
    st = EcatServeStats()
    clock = time.perf_counter
    t0 = start = clock()
    limit = None if seconds is None else int(round(seconds / PERIOD_S))
    gc.collect()
    gc.freeze()  # long-lived objects out of the collector's way: shorter pauses
    try:
        _loop(chain, link, st, limit, stop, t0)
    finally:
        gc.unfreeze()
    st.wall_s = clock() - start
    return st


def _loop(chain: EscChain, link: RawEthernet, st: EcatServeStats, limit: int | None,
          stop: Callable[[], bool], t0: float) -> None:
    clock = time.perf_counter
    k = 0
    while not stop() and (limit is None or k < limit):
        now = clock()
        release = t0 + k * PERIOD_S
        if now >= release:
            chain.cycle()
            k += 1
            st.cycles = k
            late = clock() - (t0 + k * PERIOD_S)
            if late > 0:
                st.overruns += 1
                behind = int(late / PERIOD_S)
                if behind > MAX_LAG_CYCLES:
                    t0 += behind * PERIOD_S
                    st.slipped_cycles += behind
            timeout = 0.0
        else:
            timeout = release - now
        frame = link.recv(timeout)
        while frame is not None:
            st.frames_received += 1
            reply = chain.handle(frame)
            if reply is not None:
                link.send(reply)
                st.frames_answered += 1
            frame = link.recv(0.0)
