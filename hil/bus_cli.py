"""The ``eha-hil bus``, ``eha-hil replay`` and ``eha-hil bench bus`` commands."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from hil.fieldbus.master import Master
from hil.tables import table

EXIT_USAGE = 2


class BusUsageError(Exception):
    """A user mistake on the bus commands; one line."""


def _topology(name: str):
    from hil.fieldbus.topology import TopologyError, load_topology

    try:
        return load_topology(name)
    except TopologyError as exc:
        raise BusUsageError(str(exc)) from None


def demo_pc(amplitude_n: float = 300.0, frequency_hz: float = 2.0):
    """The default PC loop: a force sine on every actuator, each a little phase-shifted."""

    def pc(cycle: int, m: Master) -> None:
        t = cycle * 1e-3
        for j in range(len(m.act_offsets)):
            m.set_actuator(j, "force", amplitude_n * math.sin(
                2.0 * math.pi * frequency_hz * t + 0.4 * j))

    return pc


def cmd_bus_run(args: argparse.Namespace, cfg) -> int:
    from hil.fieldbus.system import BusSystem
    from hil.transports import TransportError

    topo = _topology(args.topology)
    if args.seconds <= 0:
        raise BusUsageError(f"--seconds {args.seconds}: must be > 0")
    cycles = int(round(args.seconds * 1000))
    model = args.model or ("stack" if topo.n_actuators <= 5 else "echo")
    pc = demo_pc(args.amplitude, args.frequency)
    t0 = time.perf_counter()
    if args.log:
        if args.transport != "inproc":
            raise BusUsageError("--log records the in-process run; use --transport inproc")
        if model != "stack":
            raise BusUsageError("--log records the MCU model: use --model stack")
        from hil.replay.record import run_logged

        rec = run_logged(topo, cfg, cycles, pc, args.log, level=args.level,
                         progress=_progress("bus run", not args.json))
    else:
        try:
            with BusSystem(topo, cfg, args.transport, model=model) as bs:
                rec = bs.run(cycles, pc)
        except TransportError as exc:
            raise BusUsageError(str(exc)) from None
    wall = time.perf_counter() - t0
    data = {"topology": topo.name, "boxes": len(topo.boxes), "actuators": topo.n_actuators,
            "transport": args.transport, "model": model, "cycles": cycles,
            "wall_s": wall, "real_time_factor": args.seconds / wall,
            "master": rec.master, "chain": rec.chain, "log": args.log}
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        rows = [[k, v] for k, v in rec.master.items()]
        print(f"{topo.name}: {len(topo.boxes)} boxes, {topo.n_actuators} actuators, "
              f"model {model}, transport {args.transport}: {cycles} cycles in {wall:.2f} s "
              f"({args.seconds / wall:.1f}x real time)")
        print(table(["master counter", "value"], rows))
        if args.log:
            print(f"log: {args.log} (eha-hil log info {args.log}; eha-hil replay {args.log})")
    bad = rec.master["wkc_errors"] + rec.master["lost_frames"] + rec.master["bad_frames"]
    return 1 if bad else 0


def _progress(label: str, enabled: bool):
    if not enabled:
        return None

    def report(i: int, n: int) -> None:
        print(f"\r{label}: {i}/{n} cycles", end="\n" if i >= n else "", file=sys.stderr,
              flush=True)

    return report


def cmd_replay(args: argparse.Namespace, cfg) -> int:
    from hil.replay.replay import ReplayError, replay_mcu

    if not Path(args.log).is_file():
        raise BusUsageError(f"{args.log}: no such file")
    from hil.replay.fpga_replay import warm_up
    from plant.config import load_config

    warm_up(cfg or load_config(None))  # load the compiled kernel outside the timing
    t0 = time.perf_counter()
    try:
        res = replay_mcu(args.log, cfg)
    except ReplayError as exc:
        raise BusUsageError(str(exc)) from None
    wall = time.perf_counter() - t0
    rtf = res.simulated_s / wall if wall > 0 else float("inf")
    data = {"ok": res.ok, "boxes": res.boxes, "cycles": res.cycles, "mcu_steps": res.mcu_steps,
            "fpga_ticks": res.fpga_ticks,
            "simulated_s": res.simulated_s, "wall_s": wall, "real_time_factor": rtf,
            "divergence": None if res.ok else res.divergence.__dict__}
    if args.json:
        print(json.dumps(data, indent=2))
    elif res.ok:
        board = (f" and {res.fpga_ticks} driver-board ticks" if res.fpga_ticks else "")
        print(f"replay {args.log}: {res.mcu_steps} MCU steps{board} over "
              f"{res.simulated_s:.3f} s match bit for bit ({wall:.2f} s, {rtf:.0f}x real time)")
    else:
        print(f"replay {args.log}: first divergence at {res.divergence}")
    return 0 if res.ok else 1


def cmd_bench_bus(args: argparse.Namespace, cfg) -> int:
    from hil.fieldbus.bench import bench_bus, format_table
    from hil.fieldbus.topology import load_topology

    print(f"full robot (hydra_full, echo boxes), {args.cycles} cycles per backend; "
          "bench_one_box with the full stack on inproc")
    print(format_table(bench_bus(args.backends, args.cycles, 1000)))
    if args.replay:
        import tempfile

        from hil.replay.record import run_logged
        from hil.replay.replay import replay_mcu

        with tempfile.TemporaryDirectory() as d:
            log = Path(d) / "bench.mcap"
            run_logged(load_topology("bench_one_box"), cfg, 2000, demo_pc(), log)
            t0 = time.perf_counter()
            res = replay_mcu(log)
            wall = time.perf_counter() - t0
        print(f"replay of a 2 s one-box log: {res.simulated_s / wall:.1f}x real time "
              f"(target >= 20x; {res.mcu_steps} MCU steps in {wall:.3f} s)")
    return 0


def add_parsers(sub, bsub, common, config_fn, wrap) -> None:
    """Register ``bus run``, ``replay`` and ``bench bus`` on the eha-hil parser."""
    from hil.transports import BACKENDS

    bus = sub.add_parser("bus", help="the fieldbus: PC master, transports, chain of boxes")
    bbus = bus.add_subparsers(dest="bus_command", metavar="ACTION", required=True)
    p = bbus.add_parser("run", parents=[common(plot=False)],
                        help="run the 1 kHz fieldbus with a force-sine PC loop",
                        epilog="Topologies: hydra_full (Table 6.4, 16 boxes), bench_one_box, "
                        "or a TOML file (docs/fieldbus.md).")
    p.add_argument("--topology", default="bench_one_box",
                   help="shipped topology name or TOML file (default bench_one_box)")
    p.add_argument("--transport", default="inproc", choices=list(BACKENDS),
                   help="frame transport (default inproc)")
    p.add_argument("--model", choices=("stack", "echo"),
                   help="box model: stack (plant + FPGA + MCU) or echo (behavioural); "
                   "default stack for <= 5 actuators, echo otherwise")
    p.add_argument("--seconds", type=float, default=1.0, help="simulated seconds (default 1)")
    p.add_argument("--amplitude", type=float, default=300.0, help="force sine amplitude, N")
    p.add_argument("--frequency", type=float, default=2.0, help="force sine frequency, Hz")
    p.add_argument("--log", metavar="FILE.mcap", help="log MCU inputs/outputs for replay")
    p.add_argument("--level", default="mcu", choices=("bus", "mcu", "full"),
                   help="log detail (default mcu)")
    p.set_defaults(func=wrap(cmd_bus_run, config_fn))

    p = sub.add_parser("replay", parents=[common(plot=False)],
                       help="feed a log's MCU inputs to the current MCU model; compare outputs "
                       "bit for bit")
    p.add_argument("log", metavar="LOG.mcap")
    p.set_defaults(func=wrap(cmd_replay, config_fn, use_log_config=True))

    p = bsub.add_parser("bus", parents=[common(plot=False)],
                        help="full-robot process-image cycles per second per transport")
    p.add_argument("--backends", nargs="+", default=["inproc", "udp", "serial", "can"],
                   choices=list(BACKENDS))
    p.add_argument("--cycles", type=int, default=500, help="cycles per backend (default 500)")
    p.add_argument("--no-replay", dest="replay", action="store_false",
                   help="skip the replay real-time factor")
    p.set_defaults(func=wrap(cmd_bench_bus, config_fn))
