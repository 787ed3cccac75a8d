"""The ``eha-hil bus``, ``eha-hil replay`` and ``eha-hil bench bus`` commands."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from hil.cli import progress as cli_progress
from hil.cli.args import common, float_range, input_file, int_range, output_file
from hil.cli.contract import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    Context,
    Outcome,
    UsageError,
    command,
)

if TYPE_CHECKING:  # the simulation (numba) is imported by the commands, not the parser
    from hil.fieldbus.master import Master

#: Cycles between two progress updates of ``bus run`` (a tenth of a simulated second).
PROGRESS_CYCLES = 100

#: Input images ``bus run`` keeps (the last second).
KEEP_CYCLES = 1000


def _topology(name: str):
    from hil.fieldbus.topology import TopologyError, load_topology

    try:
        return load_topology(name)
    except TopologyError as exc:
        raise UsageError(str(exc)) from None


#: The files ``bus run`` streams to while it runs: (option dest, label in messages).
STREAMS = (("log", "log"), ("capture", "capture"), ("can_log", "CAN log"))


def _run_bus(args: argparse.Namespace, cfg, topo, cycles: int, model: str, pc, progress):
    """(record, wall seconds) of the run, logged to ``args.log``, captured to
    ``args.capture`` and its CAN traffic logged to ``args.can_log`` if given.

    Each file is written under a temporary name in its directory and renamed when its
    writer has closed it, also after an interruption (what ran is a readable log of what
    ran); a write that fails mid-run removes it and ends the run (exit 1, one line)."""
    from hil.cli import outputs

    labels = dict(STREAMS)
    try:
        with outputs.streaming({d: getattr(args, d, None) for d in labels}, labels,
                               _READABLE) as tmp:
            return _run_bus_to(argparse.Namespace(**{**vars(args), **tmp}), cfg, topo,
                               cycles, model, pc, progress)
    finally:
        can_log = getattr(args, "can_log", None)
        if can_log and Path(can_log).is_file():
            # what a CAN log has no place for (topology, model, configuration), beside it
            from hil.transports.canlog import write_sidecar

            write_sidecar(can_log, {"topology": args.topology or topo.name, "model": model,
                                    "mode": "lockstep (bus run)",
                                    "config": json.dumps(cfg.data)})


def _readable_traffic(path) -> str:  # noqa: ANN001 - a Path
    """"" if a capture or CAN log reads back whole, else why not."""
    from hil.fieldbus.traffic import TrafficError, read_traffic

    try:
        return read_traffic(path).cut or ""
    except TrafficError as exc:
        return str(exc)


_READABLE = {"log": cli_progress.readable_log, "capture": _readable_traffic,
             "can_log": _readable_traffic}


def _run_bus_to(args: argparse.Namespace, cfg, topo, cycles: int, model: str, pc, progress):
    from hil.fieldbus.capture import CaptureError, CaptureWriter
    from hil.fieldbus.faults import FaultError
    from hil.fieldbus.system import BusSystem
    from hil.transports import TransportError, prefixed_options

    try:
        opts = prefixed_options(args.transport, {"udp_port": args.udp_port,
                                                 "can_interface": args.can_interface,
                                                 "can_channel": args.can_channel})
    except TransportError as exc:
        raise UsageError(str(exc)) from None
    faults = _faults(args.faults, topo, model, cycles / 1000)
    tick_ns = cfg.get("sim.tick_ns")
    meta = {"topology": args.topology, "model": model, "mode": "lockstep (bus run)",
            "config": json.dumps(cfg.data)}
    t0 = time.perf_counter()
    live_addr = args.foxglove
    if args.log or live_addr is not None:
        from hil.transports import backend

        what = "--log" if args.log else "--foxglove"
        if not backend(args.transport).in_memory:
            raise UsageError(f"{what} records the in-process run; use --transport inproc")
        if model not in ("stack", "robot"):
            raise UsageError(f"{what} records the MCU model: use --model stack or robot")
        if args.crc_trailer is not None:
            raise UsageError(f"--crc-trailer/--no-crc-trailer: not with {what} (the logged "
                                "run keeps the in-process default, with the trailer)")
        from hil.replay.record import run_logged

        try:
            cap = (CaptureWriter(args.capture, crc_trailer=True, metadata=meta)
                   if args.capture else None)
        except CaptureError as exc:
            raise UsageError(str(exc)) from None
        try:
            with _live_view(live_addr) as live:
                rec = run_logged(topo, cfg, cycles, pc, args.log, level=args.level,
                                 progress=progress, faults=faults,
                                 capture=None if cap is None else cap.tap(tick_ns), live=live,
                                 model=model, compression=args.log_compression)
        finally:
            if cap is not None:
                cap.close()
        return rec, time.perf_counter() - t0, cap, None
    cap = recorder = None
    try:
        with BusSystem(topo, cfg, args.transport, model=model, transport_options=opts,
                       crc_trailer=args.crc_trailer, faults=faults) as bs:
            end = getattr(bs.m_end, "inner", bs.m_end)  # below any fault wrapper
            try:
                if args.can_log:
                    recorder = end.record_to(args.can_log)
                if args.capture:
                    cap = CaptureWriter(args.capture, bs.crc_trailer, end.capture_endpoints,
                                        metadata=meta)
                    bs.tap = cap.tap(tick_ns)
                # Only the counters are reported: keep the last second of input images
                # (memory bounded for an hour-long run of the whole robot).
                rec = bs.run(cycles, pc, keep=KEEP_CYCLES)
            finally:
                for what in (recorder, cap):
                    if what is not None:
                        what.close()
    except (TransportError, CaptureError, FaultError) as exc:
        raise UsageError(str(exc)) from None
    return rec, time.perf_counter() - t0, cap, recorder


def _faults(path: str | None, topo, model: str, seconds: float) -> dict | None:
    """The ``[[fault]]`` declaration of ``--faults FILE.toml``, checked against the
    topology, the box model and the run's length (one line naming the file, the entry and
    the key; an unknown table such as ``[[faults]]`` is refused, not ignored)."""
    if path is None:
        return None
    import tomllib

    from hil.fieldbus.faults import (
        FaultError,
        check_file,
        check_topology,
        check_window,
        parse_faults,
    )

    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        check_file(data, path)
        plan = parse_faults(data, path)
        check_topology(plan, topo)
        check_window(plan, seconds)
    except OSError as exc:
        raise UsageError(f"--faults {path}: cannot read: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"--faults {path}: not valid TOML: {exc}") from None
    except FaultError as exc:
        raise UsageError(f"--faults {exc}") from None
    if plan.box_faults and model != "stack":
        raise UsageError(f"--faults {path}: {plan.box_faults[0].name}: LVDS and sensor "
                            "faults need --model stack")
    return data


def _live_view(address: str | None):
    """A Foxglove live view for ``--foxglove [HOST:PORT]`` (None: a context giving None)."""
    import contextlib
    import sys

    if address is None:
        return contextlib.nullcontext()
    from hil.framelog.live import FoxgloveLive, LiveError, parse_address

    try:
        live = FoxgloveLive(*parse_address(address))
    except (ValueError, LiveError) as exc:
        raise UsageError(str(exc)) from None
    print(f"foxglove: live view at {live.url} (Foxglove Studio: Open connection > Foxglove "
          "WebSocket)", file=sys.stderr)
    return live


def cmd_bus_run(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.output.tables import table
    from hil.sim.pc import demo_pc

    cfg = ctx.config()
    topo = _topology(args.topology)
    cycles = int(round(args.seconds * 1000))
    model = args.model or ("stack" if topo.n_actuators <= 5 else "echo")
    sine = demo_pc(args.amplitude, args.frequency)
    # the logged run reports its own progress; the others report it from the PC loop
    logged = bool(args.log) or getattr(args, "foxglove", None) is not None
    progress = ctx.progress("bus run", "cycles", note=False)
    report = None if logged else progress
    with cli_progress.interrupt_between_steps() as check:

        def pc(cycle: int, m: Master) -> None:
            # Every cycle passes here: Ctrl-C stops between two cycles (never inside a
            # log write), and the simulated time is what the interrupt line reports.
            check()
            cli_progress.at(f"at t={cycle * 1e-3:.3f} s")
            if report is not None and cycle and cycle % PROGRESS_CYCLES == 0:
                report(cycle, cycles)
            sine(cycle, m)

        # The position is noted by the PC loop (simulated time), not by these counts.
        rec, wall, cap, recorder = _run_bus(args, cfg, topo, cycles, model, pc, progress)
        if report is not None:
            report(cycles, cycles)
    data = {"topology": topo.name, "boxes": len(topo.boxes), "actuators": topo.n_actuators,
            "transport": args.transport, "model": model, "cycles": cycles,
            "wall_s": wall, "real_time_factor": args.seconds / wall,
            "master": rec.master, "chain": rec.chain, "log": args.log,
            "capture": args.capture, "captured_frames": None if cap is None else cap.frames,
            "can_log": args.can_log,
            "can_messages": None if recorder is None else recorder.messages,
            "faults": args.faults, "fault_counts": rec.faults}
    rows = [[k, v] for k, v in rec.master.items()]
    lines = [f"{topo.name}: {len(topo.boxes)} boxes, {topo.n_actuators} actuators, "
             f"model {model}, transport {args.transport}: {cycles} cycles in {wall:.2f} s "
             f"({args.seconds / wall:.1f}x real time)",
             table(["master counter", "value"], rows)]
    if rec.faults:
        lines.append(table(["fieldbus fault counter", "value"], [[k, v] for k, v in
                                                                 rec.faults.items() if v]
                           or [["(none hit)", 0]]))
    if args.log:
        lines.append(f"log: {args.log} (eha-hil log info {args.log}; eha-hil replay {args.log})")
    if cap is not None:
        lines.append(f"capture: {args.capture}, {cap.frames} frames (wireshark {args.capture}; "
                     f"eha-hil log info {args.capture})")
    if recorder is not None:
        lines.append(f"CAN log: {args.can_log}, {recorder.messages} CAN messages (eha-hil log "
                     f"info {args.can_log}; eha-hil replay {args.can_log})")
    # Lost or corrupted frames fail a clean run; with --faults they are what was asked for.
    bad = rec.master["wkc_errors"] + rec.master["lost_frames"] + rec.master["bad_frames"]
    return Outcome("\n".join(lines), data, EXIT_FAILED if bad and not args.faults else EXIT_OK)


def cmd_replay_traffic(args: argparse.Namespace, cfg) -> Outcome:
    """Replay a capture or CAN log of a bus run through a fresh chain (exit 0: every logged
    reply matches; 1: a divergence; 2: the file cannot be read or holds no exchange)."""
    from hil.fieldbus.traffic import TrafficError, read_traffic
    from hil.fieldbus.traffic_replay import TopologyMismatch, replay_traffic
    from plant.config import Config, load_config

    try:
        traffic = read_traffic(args.log)
    except TrafficError as exc:
        raise UsageError(str(exc)) from None
    meta = traffic.metadata
    if cfg is None:
        cfg = (Config(json.loads(meta["config"]), [f"{args.log} (capture metadata)"])
               if "config" in meta else load_config(None))
    if not args.topology and not meta.get("topology") and traffic.kind in ("blf", "asc", "log"):
        from hil.transports.canlog import sidecar_path

        raise UsageError(f"{args.log}: the CAN log names no topology (no "
                         f"{sidecar_path(args.log).name} beside it): give --topology")
    topo = _topology(args.topology or meta.get("topology", "bench_one_box"))
    model = args.model or meta.get("model") or ("stack" if topo.n_actuators <= 5 else "echo")
    t0 = time.perf_counter()
    try:
        res = replay_traffic(traffic, topo, cfg, model)
    except TopologyMismatch as exc:
        raise UsageError(str(exc)) from None
    wall = time.perf_counter() - t0
    data = {"ok": res.ok, "format": traffic.kind, "topology": topo.name, "model": model,
            **{k: v for k, v in res.__dict__.items()}, "wall_s": wall}
    cut = (f"TRUNCATED file ({traffic.cut}), replayed up to t = "
           f"{traffic.read_until_s or 0:.3f} s: " if traffic.cut else "")
    data.update(truncated=traffic.cut is not None, stop_reason=traffic.cut)
    if res.divergence is not None:
        text = f"replay {args.log}: {cut}first divergence at {res.divergence}"
    elif res.ok:
        text = (f"replay {args.log}: {cut}{res.compared} replies of {topo.name} ({model} "
                f"model) match bit for bit ({res.requests} requests, {res.unanswered} without "
                f"a logged reply, {res.skipped} frames skipped; {wall:.2f} s)")
    else:
        # Nothing to compare: a mistake of the input, but --json still gets its reading.
        return Outcome(None, data, EXIT_USAGE,
                       error=f"{args.log}: no request/reply pair to replay "
                       f"({len(traffic.frames)} fieldbus frames: {res.requests} requests, "
                       f"{res.unmatched} unmatched replies, {res.skipped} skipped)")
    if traffic.cut:
        # a cut file that matches is not a whole run that matches: say where it ends
        from hil.cli import cutfiles

        return Outcome(text, data, EXIT_FAILED, error=cutfiles.message(
            args.log, traffic.cut, traffic.read_until_s, "replayed"))
    return Outcome(text, data, EXIT_OK if res.ok else EXIT_FAILED)


def cmd_replay(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Exit 0: the whole log matches; 1: a divergence, or a truncated log replayed up to
    its readable end (one line on stderr says where it ends); 2: nothing could be replayed
    (foreign or damaged file, bad metadata, no MCU data), one line ``eha-hil replay: FILE:
    what`` on stderr. Captures and CAN logs go to :func:`cmd_replay_traffic`."""
    from hil.fieldbus.traffic import is_traffic_file

    cfg = ctx.config_if_given()  # else the configuration the log carries
    if is_traffic_file(args.log):
        return cmd_replay_traffic(args, cfg)
    if args.topology or args.model:
        raise UsageError("--topology/--model: only for a capture or CAN log (an MCAP log "
                            "names its own)")
    from hil.replay.fpga_replay import warm_up
    from hil.replay.replay import ReplayError, replay_mcu
    from plant.config import load_config

    warm_up(cfg or load_config(None))  # load the compiled kernel outside the timing
    t0 = time.perf_counter()
    try:
        res = replay_mcu(args.log, cfg)
    except ReplayError as exc:
        raise UsageError(str(exc)) from None
    wall = time.perf_counter() - t0
    rtf = res.simulated_s / wall if wall > 0 else float("inf")
    data = {"ok": res.ok, "boxes": res.boxes, "cycles": res.cycles, "mcu_steps": res.mcu_steps,
            "fpga_ticks": res.fpga_ticks,
            "simulated_s": res.simulated_s, "wall_s": wall, "real_time_factor": rtf,
            "divergence": None if res.ok else res.divergence.__dict__,
            "truncated": res.truncated, "stop_reason": res.stop_reason}
    cut = (f"TRUNCATED log ({res.stop_reason}), replayed up to t = {res.simulated_s:.3f} s: "
           if res.truncated else "")
    if res.ok:
        board = (f" and {res.fpga_ticks} driver-board ticks" if res.fpga_ticks else "")
        text = (f"replay {args.log}: {cut}{res.mcu_steps} MCU steps{board} over "
                f"{res.simulated_s:.3f} s match bit for bit ({wall:.2f} s, {rtf:.0f}x real "
                "time)")
    else:
        text = f"replay {args.log}: {cut}first divergence at {res.divergence}"
    # A cut log that matches is not a whole run that matches: say where it ends, exit 1.
    from hil.cli import cutfiles

    note = cutfiles.message(args.log, res.stop_reason, res.simulated_s,
                            "replayed") if res.truncated else None
    return Outcome(text, data, EXIT_OK if res.ok and not res.truncated else EXIT_FAILED,
                   error=note)


def cmd_bench_bus(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.bus import bench_bus, format_table
    from hil.fieldbus.topology import load_topology

    cfg = ctx.config()
    rates = bench_bus(args.backends, args.cycles, 1000)
    lines = [f"full robot (hydra_full, echo boxes), {args.cycles} cycles per backend; "
             "bench_one_box with the full stack on inproc", format_table(rates)]
    data = {"cycles": args.cycles, "rates": rates, "replay": None}
    if args.replay:
        import tempfile

        from hil.replay.record import run_logged
        from hil.replay.replay import replay_mcu
        from hil.sim.pc import demo_pc

        with tempfile.TemporaryDirectory() as d:
            log = Path(d) / "bench.mcap"
            run_logged(load_topology("bench_one_box"), cfg, 2000, demo_pc(), log)
            t0 = time.perf_counter()
            res = replay_mcu(log)
            wall = time.perf_counter() - t0
        lines.append(f"replay of a 2 s one-box log: {res.simulated_s / wall:.1f}x real time "
                     f"(target >= 20x; {res.mcu_steps} MCU steps in {wall:.3f} s)")
        data["replay"] = {"simulated_s": res.simulated_s, "wall_s": wall,
                          "real_time_factor": res.simulated_s / wall,
                          "mcu_steps": res.mcu_steps}
    return Outcome("\n".join(lines), data)


def add_wire_options(p: argparse.ArgumentParser) -> None:
    """``--capture`` and ``--crc-trailer``: shared by ``bus run`` and ``serve``."""
    p.add_argument("--capture", metavar="FILE.pcapng|.pcap",
                   type=output_file((".pcapng", ".pcap")),
                   help="write every fieldbus frame to a Wireshark capture (EtherCAT over "
                   "Ethernet, or over UDP on the udp transport)")
    p.add_argument("--crc-trailer", action=argparse.BooleanOptionalAction, default=None,
                   help="append a CRC-32 to every EtherCAT frame (and expect one): the "
                   "default on inproc, serial and can; off on udp, whose standard frame has "
                   "none (docs/fieldbus.md)")


def add_parsers(sub, bsub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``bus run``, ``replay`` and ``bench bus`` on the eha-hil parser."""
    from hil.transports import BACKENDS

    bus = sub.add_parser("bus", help="the fieldbus: PC master, transports, chain of boxes")
    bbus = bus.add_subparsers(dest="bus_command", metavar="ACTION", required=True)
    p = bbus.add_parser("run", parents=[common(plot=False)],
                        help="run the 1 kHz fieldbus with a force-sine PC loop",
                        epilog="Topologies: hydra_full (Table 6.4, 16 boxes), bench_one_box, "
                        "or a TOML file (docs/fieldbus.md).")
    p.add_argument("--topology", default="bench_one_box",
                   help="shipped topology name or TOML file")
    p.add_argument("--transport", default="inproc", choices=list(BACKENDS),
                   help="frame transport")
    p.add_argument("--model", choices=("stack", "robot", "echo"),
                   help="box model: stack (plant + FPGA + MCU), robot (the same, every box "
                   "in one compiled engine: docs/robot-engine.md) or echo (behavioural); "
                   "default stack for <= 5 actuators, echo otherwise")
    # At least one 1 ms cycle; an hour of a 16-box robot is already a long run.
    p.add_argument("--seconds", type=float_range(1e-3, 3600, unit="s"), default=1.0,
                   help="simulated seconds, in [0.001, 3600]")
    p.add_argument("--amplitude", type=float_range(0.0, 1e5, unit="N"), default=300.0,
                   help="force sine amplitude, N, in [0, 1e5]")
    p.add_argument("--frequency", type=float_range(0.0, 500.0, unit="Hz"), default=2.0,
                   help="force sine frequency, Hz, in [0, 500] (the 1 kHz cycle's Nyquist)")
    p.add_argument("--faults", metavar="FILE.toml", type=input_file("fault table (.toml)"),
                   help="inject the faults of FILE's [[fault]] tables (docs/fieldbus-faults.md):"
                   " lost, corrupted, duplicated or delayed frames, LVDS and sensor faults")
    p.add_argument("--log", metavar="FILE.mcap", type=output_file((".mcap",)),
                   help="log MCU inputs/outputs for replay")
    p.add_argument("--log-compression", default="zstd", choices=("zstd", "lz4", "none"),
                   help="--log: compression of the log's chunks (default zstd; lz4 costs "
                   "about half the CPU for ~1.8x the file, docs/framelog.md)")
    p.add_argument("--level", default="mcu", choices=("bus", "mcu", "full"),
                   help="log detail")
    add_wire_options(p)
    p.add_argument("--udp-port", type=int_range(0, 65535), metavar="PORT",
                   help="udp: the chain's port (default 34980, EtherCAT's: Wireshark decodes "
                   "it without options; 0: any free port)")
    p.add_argument("--can-interface", choices=("virtual", "socketcan"),
                   help="can: python-can interface (default virtual, in-process; socketcan: "
                   "a vcan or real CAN device)")
    p.add_argument("--can-channel", metavar="NAME",
                   help="can: channel (virtual: any name, default a private one; socketcan: "
                   "the device, default vcan0)")
    p.add_argument("--can-log", metavar="FILE.blf|.asc|.log",
                   type=output_file((".blf", ".asc", ".log")),
                   help="can: log every CAN message of the run (python-can's BLF, ASC or "
                   "candump writer, by the file name)")
    p.add_argument("--foxglove", nargs="?", const="", metavar="HOST:PORT",
                   help="stream the decoded signals to Foxglove Studio (WebSocket; default "
                   "127.0.0.1:8765, loopback)")
    command(p, cmd_bus_run)

    p = sub.add_parser("replay", parents=[common(plot=False)],
                       help="feed a log's MCU inputs to the current MCU model; compare outputs "
                       "bit for bit")
    p.add_argument("log", metavar="LOG", type=input_file("frame log (.mcap)"),
                   help="frame log written by eha-hil bus run --log (.mcap), or its traffic: "
                   "a --capture (.pcapng/.pcap) or --can-log (.blf/.asc/.log)")
    p.add_argument("--topology", help="capture/CAN log: the run's topology (default: from "
                   "the pcapng's metadata, else bench_one_box)")
    p.add_argument("--model", choices=("stack", "robot", "echo"),
                   help="capture/CAN log: the run's box model (default: from the metadata, "
                   "else as bus run chooses)")
    command(p, cmd_replay)

    p = bsub.add_parser("bus", parents=[common(plot=False)],
                        help="full-robot process-image cycles per second per transport")
    p.add_argument("--backends", nargs="+", default=list(BACKENDS),
                   choices=list(BACKENDS), help="transports to measure")
    p.add_argument("--cycles", type=int_range(1, 1_000_000), default=500,
                   help="cycles per backend, 1..1000000")
    p.add_argument("--no-replay", dest="replay", action="store_false",
                   help="skip the replay real-time factor")
    command(p, cmd_bench_bus)
