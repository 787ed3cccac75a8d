"""Where the CPU of one identification goes: its stages, with the simulations each ran.

``eha-hil bench identify`` gives the whole CPU of a record's identification; this splits it
by the loop's own progress messages (each stage runs from its message to the next one: the
intersample choice, the baseline fit, each round's score tests, each refit, the joint
search, the held parameters freed again, the final judgement) and counts the model's
simulations in each (:meth:`~hil.identify.model.FastModel._simulate_states`, all threads),
so a stage's CPU reads as simulations times their cost plus the Python around them.

Run: ``python -m hil.bench.identify_stages --load free_piston --profile slide --effect
pump_coulomb_friction --effect seal_friction`` (the record ``bench identify`` times: 16 s at
5 kHz from the rig, seed 3; ``--seed``, ``--seconds``, ``--threads`` as there). The kernels
are compiled and the CSV reader imported outside the timing. The figures grow with the
machine's load: quote them with ``uptime``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from functools import partial
from pathlib import Path


def stages(load: str, effects: list[str], profile: str = "multisine", seed: int = 3,
           seconds: float = 16.0, threads: int | None = None) -> dict:
    """One timed identification of a rig record, split by its progress messages:
    ``{"stages": [{"stage", "cpu_s", "wall_s", "sims"}], "cpu_s", "wall_s", "sims",
    "effects_added", "unexplained"}``."""
    from hil.identify import model
    from hil.identify.csvdata import read_measured, write_measured
    from hil.identify.pipeline import identify
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    cfg = load_config(None, ())
    if threads is not None:
        model.set_threads(threads)
    make = partial(generate_rig, profile=profile)
    res = make(load, effects, seconds=seconds, seed=seed)
    count = [0]
    lock = threading.Lock()
    simulate = model.FastModel._simulate_states

    def counted(self, theta, n_stop):  # noqa: ANN001, ANN202 - the wrapped method's own
        with lock:
            count[0] += 1
        return simulate(self, theta, n_stop)

    marks: list[tuple[float, float, int, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        # the timed path on a 2 s record first: the kernels compile and the CSV reader's
        # imports load outside the timing, as in ``eha-hil bench identify``
        warm = Path(tmp) / "warm.csv"
        write_measured(warm, make(load, effects, seconds=2.0, seed=7).data)
        identify(read_measured(warm), cfg, max_effects=1)
        path = Path(tmp) / "record.csv"
        write_measured(path, res.data)
        model.FastModel._simulate_states = counted
        try:
            c0, w0 = time.process_time(), time.perf_counter()

            def say(msg: str) -> None:
                marks.append((time.process_time() - c0, time.perf_counter() - w0, count[0],
                              msg))

            say("reading the record")
            rep = identify(read_measured(path), cfg, progress=say)
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        finally:
            model.FastModel._simulate_states = simulate
    rows = []
    ends = [*marks[1:], (cpu, wall, count[0], "")]
    for (c, w, n, msg), (c1, w1, n1, _) in zip(marks, ends, strict=True):
        rows.append({"stage": msg, "cpu_s": c1 - c, "wall_s": w1 - w, "sims": n1 - n})
    return {"load": load, "profile": profile, "effects_in_data": effects, "seed": seed,
            "seconds": seconds, "stages": rows, "cpu_s": cpu, "wall_s": wall,
            "sims": count[0], "effects_added": [e.label for e in rep.effects_added],
            "unexplained": rep.unexplained}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.bench.identify_stages",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--load", default="free_piston",
                        choices=("fixed_piston", "free_piston", "conrod_fixed"))
    parser.add_argument("--profile", default="multisine",
                        choices=("multisine", "slide", "resonance"))
    parser.add_argument("--effect", action="append", default=None)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=16.0)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args(argv)
    effects = args.effect or ["pump_coulomb_friction", "seal_friction"]
    out = stages(args.load, effects, args.profile, args.seed, args.seconds, args.threads)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{args.load}, {' + '.join(effects)} ({args.profile}), seed {args.seed}, "
          f"{args.seconds:g} s: CPU {out['cpu_s']:.2f} s, wall {out['wall_s']:.2f} s, "
          f"{out['sims']} simulations; added: {', '.join(out['effects_added']) or 'none'}; "
          f"{'unexplained' if out['unexplained'] else 'explained'}")
    print("   CPU s  sims  stage (from its progress message to the next)")
    for r in out["stages"]:
        print(f"  {r['cpu_s']:6.2f} {r['sims']:5d}  {r['stage'][:110]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
