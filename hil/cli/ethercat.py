"""Command line of the EtherCAT slave chain: ``eha-hil esi`` and ``eha-hil bench ethercat``
(``eha-hil serve --transport ethercat`` is in :mod:`hil.cli.serve`)."""

from __future__ import annotations

import argparse
import json


def add_parsers(sub, bsub, common, config_fn, wrap) -> None:
    from hil.cli.args import float_range, int_range
    from hil.fieldbus.esc import esi

    esi.add_parser(sub)
    p = bsub.add_parser("ethercat", parents=[common(plot=False)],
                        help="round trip and box-cycle time per bus cycle of the ESC chain "
                        "(hydra_full; echo boxes, and the full stack behind one box)")
    p.add_argument("--cycles", type=int_range(10, 1_000_000), default=2000,
                   help="timed cycles of the echo row (the stack row: a quarter), 10..1e6")
    p.add_argument("--wire", action="store_true",
                   help="instead: SOEM (pysoem) as the master over a veth pair, serve "
                   "--realtime on the other end (root; makes and removes its own network "
                   "namespace)")
    p.add_argument("--model", choices=("robot", "stack", "echo"), default="robot",
                   help="--wire: the boxes behind every slave (default robot: the full "
                   "stack of all 47 actuators)")
    p.add_argument("--seconds", type=float_range(1.0, 86_400.0, unit="s"), default=60.0,
                   help="--wire: wall seconds of 1 kHz cycles (default 60)")
    p.add_argument("--bring-ups", type=int_range(0, 1000), default=25,
                   help="--wire: bring-ups to OP counted first (default 25)")
    p.set_defaults(func=wrap(_cmd_bench, config_fn))


def _cmd_bench(args: argparse.Namespace, cfg) -> int:
    from hil.bench.ethercat import bench_ethercat, format_table

    if args.wire:
        from hil.bench.ethercat import bench_wire, format_wire
        from hil.cli.bus import BusUsageError
        from hil.fieldbus.esc.veth import NamespaceError

        try:
            import pysoem  # noqa: F401
        except ImportError:
            raise BusUsageError("--wire: needs pysoem (pip install pysoem)") from None
        try:
            res = bench_wire(args.model, args.seconds, args.bring_ups)
        except NamespaceError as exc:
            raise BusUsageError(f"--wire: {exc}") from None
        print(json.dumps(res, indent=2) if args.json else format_wire(res))
        return 0
    rows = bench_ethercat(cfg, args.cycles)
    print(json.dumps(rows, indent=2) if args.json else format_table(rows))
    return 0
