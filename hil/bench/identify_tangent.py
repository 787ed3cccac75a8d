"""``python -m hil.bench.identify_tangent``: what one tangent-linear simulation costs, in
simulations, against the columns it replaces.

On the 16 s bench records of :mod:`hil.bench.identify_batch` (a linear model, the conrod
with pump friction and pulsation, the free piston with both frictions), it times
:func:`hil.identify.tangent.state_sensitivities` for a Jacobian's simulated columns (the
linear part, the input's gain and skew, the effects' levels) against one
:meth:`FastModel.states`-sized run of the kernel, CPU minima over runs taking turns.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

#: The columns a fit's Jacobian simulates on these records, besides the case's effects.
BASE_COLUMNS = ("gain_n_per_a", "ds", "dp", "dc", "ks", "k_rod", "c_rod", "jp", "jc",
                "skew_s")


def measure(case: str, samples: int, reps: int, seconds: float = 16.0,
            seed: int = 3) -> dict:
    from hil.bench.identify_batch import CASES
    from hil.identify.experiment import prepare
    from hil.identify.model import IDX, FastModel
    from hil.identify.rig import generate_rig
    from hil.identify.tangent import state_sensitivities
    from plant.config import load_config

    load, effects, params = CASES[case]
    rig = generate_rig(load, list(effects), seconds=seconds, seed=seed)
    model = FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))
    theta = model.start_vector()
    for name, value in params.items():
        theta[IDX[name]] = value
    names = [n for n in BASE_COLUMNS if load == "conrod_fixed" or n not in ("k_rod", "c_rod")]
    names += list(params)
    steps = np.array([1e-6 * max(abs(theta[IDX[n]]), 1e-6) for n in names])
    plus, minus = [], []
    for name, step in zip(names, steps, strict=True):
        plus.append(theta.copy())
        plus[-1][IDX[name]] += step
        minus.append(theta.copy())
        minus[-1][IDX[name]] -= step
    state_sensitivities(model, theta, plus, minus, steps, samples)  # compiled, warm
    model._simulate_states(theta, samples)
    t_tan = t_sim = float("inf")
    for _ in range(reps):
        t0 = time.process_time()
        state_sensitivities(model, theta, plus, minus, steps, samples)
        t_tan = min(t_tan, time.process_time() - t0)
        t0 = time.process_time()
        model._simulate_states(theta, samples)
        t_sim = min(t_sim, time.process_time() - t0)
    return {"case": case, "columns": len(names), "tangent_ms": 1e3 * t_tan,
            "simulation_ms": 1e3 * t_sim, "simulations": t_tan / t_sim}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.bench.identify_tangent",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=30_000,
                        help="samples simulated (default: a fit's iteration head)")
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.samples < 2 or args.reps < 1:
        print("samples must be >= 2 and reps >= 1", file=sys.stderr)
        return 2
    rows = [measure(c, args.samples, args.reps) for c in ("linear", "conrod", "free")]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['case']:7s} {r['columns']:2d} columns: tangent {r['tangent_ms']:.1f} ms "
                  f"= {r['simulations']:.1f} simulations of {r['simulation_ms']:.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
