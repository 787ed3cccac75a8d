"""Command line of the EtherCAT slave chain: ``eha-hil esi`` and ``eha-hil bench ethercat``
(``eha-hil serve --transport ethercat`` is in :mod:`hil.cli.serve`)."""

from __future__ import annotations

import argparse
import sys

from hil.cli.args import common, float_range, int_range, only_with
from hil.cli.contract import Context, Outcome, UsageError, command


def add_parsers(sub, bsub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``esi`` and ``bench ethercat``."""
    p = sub.add_parser("esi", help="write the EtherCAT slave information (ESI XML) of the "
                       "boxes of a topology to stdout",
                       epilog="Example: eha-hil esi --topology hydra_full > Hydra.xml "
                       "(docs/ethercat-slaves.md)")
    p.add_argument("--topology", default="hydra_full",
                   help="shipped topology name or TOML file")
    command(p, _cmd_esi)
    p = bsub.add_parser("ethercat", parents=[common(plot=False)],
                        help="round trip and box-cycle time per bus cycle of the ESC chain "
                        "(hydra_full; echo boxes, and the full stack behind one box)")
    only_with(p.add_argument("--cycles", type=int_range(10, 1_000_000), default=2000,
                             help="timed cycles of the echo row (the stack row: a quarter), "
                             "10..1e6; not with --wire"), "wire", False)
    p.add_argument("--wire", action="store_true",
                   help="instead: SOEM (pysoem) as the master over a veth pair, serve "
                   "--realtime on the other end (root; makes and removes its own network "
                   "namespace)")
    wire_only = (
        p.add_argument("--model", choices=("robot", "stack", "echo"), default="robot",
                       help="--wire: the boxes behind every slave (default robot: the full "
                       "stack of all 47 actuators)"),
        p.add_argument("--seconds", type=float_range(1.0, 86_400.0, unit="s"), default=60.0,
                       help="--wire: wall seconds of 1 kHz cycles (default 60)"),
        p.add_argument("--bring-ups", type=int_range(0, 1000), default=25,
                       help="--wire: bring-ups to OP counted first (default 25)"),
        p.add_argument("--busy-cpu", type=int_range(0, 4095), metavar="CPU",
                       help="--wire: a process of the benchmark's own keeps CPU busy during "
                       "the cycles (the figures with one core held busy)"),
    )
    for action in wire_only:  # the echo and stack rows have no use for them
        only_with(action, "wire", True)
    command(p, _cmd_bench)


def _cmd_esi(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.fieldbus.esc.esi import esi_xml
    from hil.fieldbus.topology import TopologyError, load_topology

    try:
        topo = load_topology(args.topology)
    except TopologyError as exc:
        raise UsageError(str(exc)) from None
    return Outcome(esi_xml(topo), end="")  # the XML ends with its own newline


def _cmd_bench(args: argparse.Namespace, ctx: Context) -> Outcome:
    from hil.bench.ethercat import bench_ethercat, format_table

    if args.wire:
        from hil.bench.ethercat import bench_wire, format_wire
        from hil.fieldbus.esc.veth import NamespaceError

        try:
            import pysoem  # noqa: F401
        except ImportError:
            raise UsageError("--wire: needs pysoem (pip install pysoem)") from None
        if args.busy_cpu is not None:
            import os

            if args.busy_cpu not in os.sched_getaffinity(0):
                raise UsageError(f"--busy-cpu {args.busy_cpu}: not a CPU of this machine "
                                 f"({sorted(os.sched_getaffinity(0))})")

        def progress(line: str) -> None:
            print(f"eha-hil bench ethercat: {line}", file=sys.stderr, flush=True)

        try:
            res = bench_wire(args.model, args.seconds, args.bring_ups, args.busy_cpu,
                             progress)
        except NamespaceError as exc:
            raise UsageError(f"--wire: {exc}") from None
        return Outcome(format_wire(res), res)
    rows = bench_ethercat(ctx.config(), args.cycles)
    return Outcome(format_table(rows), rows)
