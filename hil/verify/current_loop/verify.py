"""``eha-hil verify current-loop``: the Python board model's current loop against the RTL,
every output port each cycle: under Verilator (the library the stack runs, all vectors in
one call) or under Icarus Verilog and cocotb."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from firmware_model.fpga.current_loop import INPUT_PORTS, LOOP_OUTPUT, OUTPUT_PORTS, run_model
from firmware_model.fpga.params import board_params
from hil.verify.compare import ComparedSets, Comparison, compare
from hil.verify.current_loop.rtl import RTL_DIR, run_rtl
from hil.verify.current_loop.vectors import loop_sets
from plant.config import Config

SIMULATORS = ("verilator", "icarus")


@dataclass
class LoopVerification(ComparedSets):
    rtl: str
    simulator: str = "verilator"
    sets: list[Comparison] = field(default_factory=list)
    seconds: float = 0.0

    def as_dict(self) -> dict:
        first = self.first
        return {"against": "rtl", "rtl": self.rtl, "simulator": self.simulator,
                "vectors": self.vectors,
                "mismatches": self.mismatches,
                "first_mismatch": None if first is None else
                {"set": first.source, **first.as_dict()["first"]},
                "sets": [c.as_dict() for c in self.sets], "seconds": self.seconds}


def run_verilator(cfg: Config, inputs: np.ndarray, rtl_dir: Path = RTL_DIR) -> np.ndarray:
    """Replay ``inputs`` through the Verilated RTL (one clock edge each, from reset)."""
    from hil.sim.verilator import RtlLoop, build

    loop = RtlLoop(build(rtl_dir, board_params(cfg)), rtl_dir)
    flat = loop.run(np.stack([inputs[name] for name in INPUT_PORTS], axis=1))
    out = np.zeros(len(inputs), dtype=LOOP_OUTPUT)
    for j, name in enumerate(OUTPUT_PORTS):
        out[name] = flat[:, j]
    return out


def verify_current_loop(cfg: Config, vectors: int, seed: int = 1,
                        rtl_dir: Path = RTL_DIR, simulator: str = "verilator"
                        ) -> LoopVerification:
    """Golden, edge and random vectors (``vectors`` in all, at least the first two sets) as
    one stream through the model and the RTL under ``simulator``; compared per set."""
    if simulator not in SIMULATORS:
        raise ValueError(f"simulator {simulator!r}: expected one of {', '.join(SIMULATORS)}")
    t0 = time.perf_counter()
    sets = loop_sets(vectors, seed)
    stream = np.concatenate([x for _, x in sets])
    model = run_model(cfg, stream)
    if simulator == "verilator":
        built = run_verilator(cfg, stream, rtl_dir)
    else:
        built = run_rtl(stream, rtl_dir)
    report = LoopVerification(str(rtl_dir), simulator)
    start = 0
    for label, x in sets:
        end = start + len(x)
        report.sets.append(compare(label, model[start:end], built[start:end]))
        start = end
    report.seconds = time.perf_counter() - t0
    return report
