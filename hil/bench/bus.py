"""Bus throughput: full-robot fieldbus cycles per second on each transport, and the real-time
factor of the full stack model on the test bench.

``python -c "from hil.bench.bus import main; main()"`` (or ``eha-hil bench bus``)
prints a table. Figures are wall-clock on this machine: the PC loop (47 force commands per
cycle), the master, the transport and the chain (echo model) all count; the chain process
start (udp) and the first cycles (compiled code loading) are not timed.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

from hil.fieldbus.system import BusSystem
from hil.fieldbus.topology import load_topology
from hil.transports import BACKENDS
from plant.config import load_config

CYCLE_S = 1e-3
WARMUP = 20


def _full_pc(cycle: int, m) -> None:
    for j in range(len(m.act_offsets)):
        m.set_actuator(j, "force", 10.0 * (j + 1) + 0.01 * (cycle % 1000))


def _bench_pc(cycle: int, m) -> None:
    m.set_actuator(0, "force", 300.0 + (cycle % 200))


def _rate(topo, cfg, transport: str, model: str, cycles: int, pc) -> tuple[float, dict]:
    from hil.transports import backend

    # A free port rather than udp's 34980: a benchmark must not meet another run.
    with BusSystem(topo, cfg, transport, model=model,
                   transport_options=backend(transport).private_options()) as bs:
        bs.run(WARMUP, pc)
        t0 = time.perf_counter()
        rec = bs.run(cycles, pc)
        wall = time.perf_counter() - t0
    return cycles / wall, rec.master


def bench_bus(backends: Sequence[str] = BACKENDS,
              cycles: int = 500, stack_cycles: int = 1000,
              preset: str = "hydra_default") -> dict[str, float]:
    """Cycles per second of hydra_full (echo model) per backend (key = backend name), plus
    ``"stack_rtf"``: simulated / wall time of bench_one_box with the stack model on inproc
    (> 1: faster than real time)."""
    cfg = load_config(preset)
    full = load_topology("hydra_full")
    out: dict[str, float] = {}
    for b in backends:
        rate, stats = _rate(full, cfg, b, "echo", cycles, _full_pc)
        if stats["frames_ok"] != stats["frames_sent"]:
            raise RuntimeError(f"bench {b}: frames lost or rejected: {stats}")
        out[b] = rate
    if stack_cycles:
        rate, _ = _rate(load_topology("bench_one_box"), cfg, "inproc", "stack", stack_cycles,
                        _bench_pc)
        out["stack_rtf"] = rate * CYCLE_S
    return out


def format_table(results: dict[str, float]) -> str:
    lines = ["| what | cycles/s | x real time (1 kHz) |", "|---|---:|---:|"]
    for k, v in results.items():
        if k == "stack_rtf":
            lines.append(f"| bench_one_box, stack model, inproc | {v / CYCLE_S:,.0f} | "
                         f"{v:.2f} |")
        else:
            lines.append(f"| hydra_full (47 actuators), echo model, {k} | {v:,.0f} | "
                         f"{v * CYCLE_S:.2f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(prog="eha-hil bench bus", description=__doc__.split("\n")[0])
    ap.add_argument("--backends", default=",".join(BACKENDS),
                    help="comma-separated transports (default: all four)")
    ap.add_argument("--cycles", type=int, default=500, help="timed full-robot cycles")
    ap.add_argument("--stack-cycles", type=int, default=1000,
                    help="timed stack-model cycles (0: skip)")
    args = ap.parse_args(argv)
    res = bench_bus(tuple(b for b in args.backends.split(",") if b), args.cycles,
                    args.stack_cycles)
    print(format_table(res))
    return res


if __name__ == "__main__":
    main()
