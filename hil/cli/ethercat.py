"""Command line of the EtherCAT slave chain: ``eha-hil esi`` and ``eha-hil bench ethercat``
(``eha-hil serve --transport ethercat`` is in :mod:`hil.cli.serve`)."""

from __future__ import annotations

import argparse
import json


def add_parsers(sub, bsub, common, config_fn, wrap) -> None:
    from hil.cli.args import int_range
    from hil.fieldbus.esc import esi

    esi.add_parser(sub)
    p = bsub.add_parser("ethercat", parents=[common(plot=False)],
                        help="round trip and box-cycle time per bus cycle of the ESC chain "
                        "(hydra_full; echo boxes, and the full stack behind one box)")
    p.add_argument("--cycles", type=int_range(10, 1_000_000), default=2000,
                   help="timed cycles of the echo row (the stack row: a quarter), 10..1e6")
    p.add_argument("--wire", action="store_true",
                   help="also over a veth pair with SOEM (pysoem) as the master (root; "
                   "makes and removes its own network namespace)")
    p.set_defaults(func=wrap(_cmd_bench, config_fn))


def _cmd_bench(args: argparse.Namespace, cfg) -> int:
    from hil.bench.ethercat import bench_ethercat, format_table

    rows = bench_ethercat(cfg, args.cycles)
    if args.wire:
        from hil.bench.ethercat import bench_wire
        from hil.cli.bus import BusUsageError
        from hil.fieldbus.esc.veth import NamespaceError

        try:
            import pysoem  # noqa: F401
        except ImportError:
            raise BusUsageError("--wire: needs pysoem (pip install pysoem)") from None
        try:
            rows += bench_wire(args.cycles)
        except NamespaceError as exc:
            raise BusUsageError(f"--wire: {exc}") from None
    print(json.dumps(rows, indent=2) if args.json else format_table(rows))
    return 0
