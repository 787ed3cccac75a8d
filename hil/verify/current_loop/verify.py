"""``eha-hil verify current-loop``: the Python board model's current loop against the RTL
under Icarus Verilog and cocotb, every output port each cycle."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from firmware_model.fpga.current_loop import run_model
from hil.verify.compare import ComparedSets, Comparison, compare
from hil.verify.current_loop.rtl import RTL_DIR, run_rtl
from hil.verify.current_loop.vectors import loop_sets
from plant.config import Config


@dataclass
class LoopVerification(ComparedSets):
    rtl: str
    sets: list[Comparison] = field(default_factory=list)
    seconds: float = 0.0

    def as_dict(self) -> dict:
        first = self.first
        return {"against": "rtl", "rtl": self.rtl, "vectors": self.vectors,
                "mismatches": self.mismatches,
                "first_mismatch": None if first is None else
                {"set": first.source, **first.as_dict()["first"]},
                "sets": [c.as_dict() for c in self.sets], "seconds": self.seconds}


def verify_current_loop(cfg: Config, vectors: int, seed: int = 1,
                        rtl_dir: Path = RTL_DIR) -> LoopVerification:
    """Golden, edge and random vectors (``vectors`` in all, at least the first two sets) as
    one stream through the model and the RTL; compared per set."""
    t0 = time.perf_counter()
    sets = loop_sets(vectors, seed)
    stream = np.concatenate([x for _, x in sets])
    model = run_model(cfg, stream)
    built = run_rtl(stream, rtl_dir)
    report = LoopVerification(str(rtl_dir))
    start = 0
    for label, x in sets:
        end = start + len(x)
        report.sets.append(compare(label, model[start:end], built[start:end]))
        start = end
    report.seconds = time.perf_counter() - t0
    return report
