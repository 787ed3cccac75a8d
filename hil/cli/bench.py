"""``eha-hil bench ...``: the verbs of the benchmarks in :mod:`hil.bench` (the engines, the
codecs, the hip joint, what logging costs)."""

from __future__ import annotations

import argparse
import os
from dataclasses import asdict

from hil.cli.args import common, float_range, int_list, int_range, positive_float
from hil.cli.contract import Context, Outcome, command
from hil.cli.verify import add_rtl_option, rtl_verdict
from hil.output.tables import table


# --- engines ---------------------------------------------------------------------------------
def cmd_bench_plant(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.engines import bench_plant

    cfg = ctx.config()
    results = [bench_plant(cfg, args.seconds, mode) for mode in ("scheduled", "kernel")]
    rows = [(r.mode, r.simulated_s, r.wall_s, r.real_time_factor, r.ticks_per_s, r.substeps)
            for r in results]
    text = table(["path", "simulated [s]", "wall [s]", "real-time factor", "ticks/s",
                  "substeps"], rows, fmt=".3g",
                 title=f"plant alone, {cfg.sources[-1]}, 50 us tick (target >= 10x real time)")
    data = {"config": cfg.sources, "results": [
        {"path": r.mode, "simulated_s": r.simulated_s, "wall_s": r.wall_s,
         "real_time_factor": r.real_time_factor, "ticks_per_s": r.ticks_per_s,
         "substeps": r.substeps} for r in results]}
    return Outcome(text, data)


def cmd_bench_fpga(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.engines import bench_fpga

    cfg = ctx.config()
    results = []
    if cfg.get("fpga.impl") == "rtl":  # the board model's figure beside the RTL's
        results.append(bench_fpga(cfg.with_overrides({"fpga.impl": "python"}, "bench"),
                                  args.seconds, bit_level=False))
    results.append(bench_fpga(cfg, args.seconds, bit_level=False))
    ctx.say("value level done; bit level ...")
    results.append(bench_fpga(cfg, args.bit_seconds, bit_level=True))
    rows = [(r.mode, r.loop, r.simulated_s, r.wall_s, r.cpu_s, r.real_time_factor,
             r.cpu_real_time_factor, r.ticks_per_s) for r in results]
    text = table(["sensor and link path", "current loop", "simulated [s]", "wall [s]",
                  "CPU [s]", "real-time factor", "CPU real-time factor", "ticks/s"], rows,
                 fmt=".3g",
                 title=f"plant + driver board + LVDS link, {cfg.sources[-1]}, 20 kHz, MCU-rate "
                 "task writing iq_ref (target >= 5x real time, value level)")
    calls = None
    if cfg.get("fpga.impl") == "rtl":  # what the per-tick call of the loop itself costs
        from hil.bench.engines import bench_loop_call

        calls = bench_loop_call(cfg)
        text += "\n\n" + table(["one tick of the current loop", "wall [ns]", "CPU [ns]"],
                                calls.rows, fmt=".3g",
                                title=f"per tick, {calls.ticks} ticks in one loop")
    load = os.getloadavg()
    text += f"\nload average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} cores)"
    data = {"config": cfg.sources, "load_average": list(load), "results": [
        {"path": r.mode, "current_loop": r.loop, "simulated_s": r.simulated_s,
         "wall_s": r.wall_s, "cpu_s": r.cpu_s, "real_time_factor": r.real_time_factor,
         "cpu_real_time_factor": r.cpu_real_time_factor, "ticks_per_s": r.ticks_per_s}
        for r in results]}
    if calls is not None:
        data["loop_call_ns"] = [{"way": w, "wall_ns": wall, "cpu_ns": cpu}
                                for w, wall, cpu in calls.rows]
    return rtl_verdict(Outcome(text, data), ctx)


def cmd_bench_stack(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.engines import bench_stack

    cfg = ctx.config()
    load = os.getloadavg()[0]
    # A firmware image is timed beside the Python model and the host C build of the law.
    impls = ("python", "c", "image") if cfg.get("mcu.impl") == "image" else (None,)
    rows, data = [], []
    for impl in impls:
        c = cfg if impl in (None, cfg.get("mcu.impl")) else cfg.with_overrides(
            {"mcu.impl": impl}, f"bench {impl}")
        ctx.say(f"bench stack: simulating {args.seconds:g} s (MCU {c.get('mcu.impl')}) ...")
        r = bench_stack(c, args.seconds)
        rows.append((r.mode, r.simulated_s, r.wall_s, r.cpu_s, r.real_time_factor,
                     r.cpu_real_time_factor, r.ticks_per_s))
        data.append({"mcu_impl": c.get("mcu.impl"), "simulated_s": r.simulated_s,
                     "wall_s": r.wall_s, "cpu_s": r.cpu_s,
                     "real_time_factor": r.real_time_factor,
                     "cpu_real_time_factor": r.cpu_real_time_factor})
    text = table(["path", "simulated [s]", "wall [s]", "CPU [s]", "real-time (wall)",
                  "real-time (CPU)", "ticks/s"], rows,
                 fmt=".3g", title=f"plant + driver board + LVDS + MCU (5 kHz, float32) + 1 kHz "
                 f"PC task, value-level sensors, {cfg.sources[-1]}; load average {load:.2f} "
                 f"on {os.cpu_count()} cores at the start (target >= 2x real time; an MCU "
                 "image >= 1x)")
    first = data[0]
    return Outcome(text, {"config": cfg.sources, "load_average": load,
                          "simulated_s": first["simulated_s"], "wall_s": first["wall_s"],
                          "real_time_factor": first["real_time_factor"], "runs": data})


def cmd_bench_robot(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.engines import bench_robot

    cfg = ctx.config()
    load = os.getloadavg()[0]
    if args.stages:
        return _robot_stages(cfg, load, ctx)
    rows, data = [], []
    for w in args.workers:
        for engine, lanes, numerics in _ROBOT_ENGINES[args.engine]:
            ctx.say(f"bench robot: simulating {args.seconds:g} s with {w} worker(s), "
                    f"{engine} ...")
            run_cfg = cfg.with_overrides({"sim.plant_numerics": numerics},
                                         source=f"plant recipe {numerics}") if numerics else cfg
            r = bench_robot(run_cfg, args.seconds, w, lanes=lanes)
            label = f"{r.engine}, recipe {r.numerics}"
            sp = r.split
            by_thread = [r.per_actuator_tick(s) for s in (
                sp.compiled_s, sp.python_s, sp.helpers_s,
                r.cpu_s - sp.calling_s - sp.helpers_s)]
            rows.append((w, label, r.simulated_s, r.wall_s, r.cpu_s, r.real_time_factor,
                         r.cpu_real_time_factor, r.ns_per_actuator_tick,
                         *(f"{v:.0f}" for v in by_thread)))
            data.append({"workers": w, "engine": r.engine, "plant_numerics": r.numerics,
                         "simulated_s": r.simulated_s, "wall_s": r.wall_s,
                         "cpu_s": r.cpu_s, "real_time_factor": r.real_time_factor,
                         "cpu_real_time_factor": r.cpu_real_time_factor,
                         "ns_per_actuator_tick": r.ns_per_actuator_tick,
                         "ns_per_actuator_tick_by_thread": dict(zip(
                             ("calling_compiled", "calling_python", "helpers", "other"),
                             by_thread, strict=True))})
    text = table(["workers", "engine", "simulated [s]", "wall [s]", "CPU [s]",
                  "real-time (wall)", "real-time (CPU)", "CPU ns/actuator/tick",
                  "calling thread: compiled", "calling thread: Python", "helper threads",
                  "other"], rows,
                 fmt=".3g",
                 title=f"hydra_full, {r.actuators} actuators, full stack behind every box "
                 f"(robot engine), PC loop at 1 kHz, {cfg.sources[-1]}; load average "
                 f"{load:.2f} on {os.cpu_count()} cores at the start (target: lanes >= 2x "
                 "wall with 1 worker, >= 3.5x with 2); the last four columns split the CPU "
                 "ns/actuator/tick by thread: the calling thread's compiled calls, the rest "
                 "of it (master, PC loop, chain, hand-offs), the engine's helper threads "
                 "(their compiled calls, spins, sleeps), the rest of the process")
    return Outcome(text, {"config": cfg.sources, "load_average": load, "runs": data})


#: ``bench robot --engine``: (label, lanes, plant recipe or None for the configured one).
#: "both": the engine as it was (one actuator at a time, recipe 2) beside the lanes.
_ROBOT_ENGINES = {
    "both": (("per-actuator", False, 2), ("lanes", True, None)),
    "per-actuator": (("per-actuator", False, None),),
    "lanes": (("lanes", True, None),),
}


def _robot_stages(cfg, load: float, ctx: Context) -> Outcome:  # noqa: ANN001 - a Config
    from hil.bench.robot_stages import stage_costs

    ctx.say("bench robot --stages: 0.2 s of hydra_full, then each stage alone ...")
    r = stage_costs(cfg)
    text = table(["stage", "CPU ns/actuator/tick"], r.rows, fmt=".0f",
                 title=f"hydra_full, {r.actuators} actuators, each stage alone over "
                 f"{r.ticks} ticks from a running robot's state (1 thread, best of 3), "
                 f"{cfg.sources[-1]}; load average {load:.2f} at the start")
    return Outcome(text, {"config": cfg.sources, "load_average": load,
                          "stages": [{"stage": s, "ns_per_actuator_tick": v}
                                     for s, v in r.rows]})


def cmd_bench_codecs(args: argparse.Namespace, ctx: Context) -> Outcome:
    import time

    from hil.bench.codecs import all_cases

    rows = []
    data = []
    for case in all_cases():
        case.run(10)  # warm up (tables, compilation)
        n = 1000 if case.kind == "frame" else 100_000
        frames = 0
        t0 = time.perf_counter()
        elapsed = 0.0
        while elapsed < args.seconds:
            frames += case.run(n)
            elapsed = time.perf_counter() - t0
            n = min(n * 2, 10_000_000)
        fps = frames / elapsed
        if case.target_fps:
            target, ok = f"{case.target_fps:,.0f}", "ok" if fps >= case.target_fps else "BELOW"
        else:
            target, ok = "-", ""
        rows.append((case.name, case.kind, f"{fps:,.0f}", target, ok))
        data.append({"name": case.name, "kind": case.kind, "frames_per_s": fps,
                     "target_frames_per_s": case.target_fps})
        ctx.say(f"\r{case.name}: {fps:,.0f} frames/s")
    text = table(["codec", "path", "frames/s", "target", ""], rows,
                 title="codec throughput: encode+decode per frame; batch = numpy decode")
    return Outcome(text, {"results": data})


def add_parsers(bsub) -> None:  # noqa: ANN001 - argparse's sub-parsers of ``bench``
    """Register ``bench plant|fpga|stack|robot|codecs|joint|log``."""
    p = bsub.add_parser("plant", parents=[common(plot=False, mcu=False)],
                        help="real-time factor of the plant alone, default effects on")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=5.0,
                   help="simulated seconds, in (0, 600]")
    command(p, cmd_bench_plant)
    p = bsub.add_parser("fpga", parents=[common(plot=False, mcu=False)],
                        help="real-time factor of plant + driver board + LVDS link")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=2.0,
                   help="simulated seconds, value-level path, in (0, 600]")
    p.add_argument("--bit-seconds", type=positive_float(60, "s"), default=0.05,
                   help="simulated seconds, bit-level path, in (0, 60]")
    add_rtl_option(p)
    command(p, cmd_bench_fpga)
    p = bsub.add_parser("stack", parents=[common(plot=False)],
                        help="real-time factor of the full actuator stack (plant to MCU)")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=2.0,
                   help="simulated seconds, in (0, 600]")
    command(p, cmd_bench_stack)
    p = bsub.add_parser("robot", parents=[common(plot=False)],
                        help="real-time factor of the whole robot (hydra_full) over the "
                        "fieldbus, full stack behind every box")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=10.0,
                   help="simulated seconds per run, in (0, 600]")
    p.add_argument("--workers", type=int_list(1, os.cpu_count() or 1), default=[1, 2],
                   help="comma-separated numbers of compute threads, one run each "
                   "(default: 1,2)")
    p.add_argument("--engine", choices=sorted(_ROBOT_ENGINES), default="both",
                   help="both (default): the per-actuator engine on plant recipe 2 (as "
                   "before the lanes) and the lanes engine on the configured recipe, one run "
                   "each per number of workers; or one of them on the configured recipe")
    p.add_argument("--stages", action="store_true",
                   help="instead: CPU ns per actuator tick of each stage of the per-tick "
                   "work (plant, sensors, board, link, MCU law), each timed alone, and the "
                   "per-cycle Python around the compiled call")
    command(p, cmd_bench_robot)
    p = bsub.add_parser("codecs", parents=[common(plot=False, config=False)],
                        help="encode+decode throughput of every protocol codec")
    p.add_argument("--seconds", type=positive_float(60, "s"), default=0.5,
                   help="wall seconds per codec, in (0, 60]")
    command(p, cmd_bench_codecs)
    add_joint_parser(bsub)
    add_log_parser(bsub)


def cmd_bench_joint(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.joint import bench_joint

    cfg = ctx.config()
    r = bench_joint(cfg, args.seconds)
    text = table(["path", "simulated [s]", "wall [s]", "CPU [s]", "real-time factor (wall)",
                  "real-time factor (CPU)"],
                 [("hip joint stack", r.simulated_s, r.wall_s, r.cpu_s,
                   r.real_time_factor, r.cpu_real_time_factor)], fmt=".3g",
                 title="PC joint loop 1 kHz + fieldbus + MCU 5 kHz + 2 driver boards + "
                 f"2 plants + thigh at 20 kHz, {cfg.sources[-1]}")
    return Outcome(text, {"config": cfg.sources, "simulated_s": r.simulated_s,
                          "wall_s": r.wall_s, "cpu_s": r.cpu_s,
                          "real_time_factor": r.real_time_factor,
                          "cpu_real_time_factor": r.cpu_real_time_factor})


def add_joint_parser(bsub) -> None:  # noqa: ANN001
    """``eha-hil bench joint``."""
    p = bsub.add_parser("joint", parents=[common(plot=False)],
                        help="real-time factor of the hip joint stack (PC loop to the thigh)")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=1.0,
                   help="simulated seconds, in (0, 600]")
    command(p, cmd_bench_joint)


def cmd_bench_log(args: argparse.Namespace, ctx: Context) -> Outcome:
    """``eha-hil bench log``."""
    from hil.bench.log import bench_encodings, bench_overhead, format_report

    cfg = ctx.config()
    if args.topology is not None:
        from hil.cli.bus import _topology

        _topology(args.topology)  # a bad name or file: one line, before any run
    ov = None if args.seconds == 0 else bench_overhead(cfg, args.seconds, args.level,
                                                       args.pairs, args.topology, args.model,
                                                       args.compression, args.parts)
    enc = bench_encodings(args.samples)
    return Outcome(format_report(ov, enc),
                   {"overhead": None if ov is None else asdict(ov),
                    "encodings": [asdict(e) for e in enc]})


def add_log_parser(bsub) -> None:  # noqa: ANN001
    """``eha-hil bench log``."""
    p = bsub.add_parser("log", parents=[common(plot=False)],
                        help="what --log costs bus run (CPU and wall, logged / bare), and "
                        "protobuf against JSON for the decoded signals")
    p.add_argument("--seconds", type=float_range(0.0, 600, unit="s"), default=1.0,
                   help="simulated seconds per run, in [0, 600]; 0: only the encodings")
    p.add_argument("--level", default="mcu", choices=("bus", "mcu", "full"),
                   help="log level of the logged runs")
    p.add_argument("--pairs", type=int_range(1, 50), default=7,
                   help="bare/logged pairs, 1..50 (default 7: a run's CPU time on a shared "
                   "machine scatters by ~10 %%, a ratio's median of 3 by nearly as much)")
    p.add_argument("--model", choices=("stack", "robot"), default="stack",
                   help="box model: stack (each box on its own) or robot (every box in the "
                   "whole-robot engine)")
    p.add_argument("--compression", default="zstd", choices=("zstd", "lz4", "none"),
                   help="compression of the logged runs' chunks (bus run --log-compression)")
    p.add_argument("--topology", help="shipped topology name or TOML file (default: "
                   "bench_one_box for --model stack, hydra_full for --model robot)")
    p.add_argument("--samples", type=int_range(10, 1_000_000), default=5000,
                   help="samples for the encoding comparison")
    p.add_argument("--parts", action=argparse.BooleanOptionalAction, default=True,
                   help="after the pairs, one more pair with the logging's parts timed (file "
                   "side, producer, the engine's compiled calls; default: on)")
    command(p, cmd_bench_log)
