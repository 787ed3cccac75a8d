"""The ``eha-hil verify`` verbs: the firmware models against independent builds."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from hil.tables import table

EXIT_MISMATCH = 1


class ToolMissing(Exception):
    """A system tool the check needs is not installed."""


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    return n


def _seconds(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not 0 <= x <= 60:
        raise argparse.ArgumentTypeError(f"must be within 0..60 s, got {x:g}")
    return x


def add_parsers(sub: argparse._SubParsersAction,
                common: Callable[..., argparse.ArgumentParser]) -> None:
    verify = sub.add_parser("verify", help="check the firmware models bit for bit against "
                            "independent builds (C on the host or a Cortex-M4 under QEMU; "
                            "RTL under Icarus/cocotb); exit 1 on any mismatch")
    vsub = verify.add_subparsers(dest="verify_command", metavar="CHECK", required=True)
    p = vsub.add_parser("mcu", parents=[common(plot=False)],
                        help="the MCU law: Python model against the C build")
    p.add_argument("--against", required=True, choices=("host-c", "qemu"),
                   help="host-c: the C as a host shared library; qemu: the Cortex-M4F image "
                   "on QEMU's netduinoplus2")
    p.add_argument("--steps", type=_positive, default=10_000,
                   help="random input steps, split over the six controller variants "
                   "(default 10000)")
    p.add_argument("--stack-seconds", type=_seconds, default=0.4,
                   help="seconds of whole-stack run with faults recorded per variant "
                   "(default 0.4 s = 2000 steps; 0: none)")
    p.add_argument("--seed", type=_positive, default=1, help="random steps' seed (default 1)")
    p.add_argument("--contract", choices=("off", "fast"), default="off",
                   help="the build's -ffp-contract (default off, as the firmware is built; "
                   "fast shows what fused multiply-adds change)")
    p.set_defaults(func=cmd_verify_mcu)


def cmd_verify_mcu(args: argparse.Namespace) -> int:
    from hil.verify import mcu_builds
    from hil.verify.mcu_verify import verify_mcu

    target = "host-c" if args.against == "host-c" else "qemu"
    missing = mcu_builds.missing_tools(target)
    if missing:
        raise ToolMissing(f"verify mcu --against {args.against}: {', '.join(missing)} not "
                          "installed (make system-deps installs them)")
    try:
        rep = verify_mcu(args.against, args.steps, args.seed, args.stack_seconds,
                         args.contract, args.config, args.set or ())
    except mcu_builds.BuildError as exc:
        print(f"eha-hil: error: {exc}", file=sys.stderr)
        return EXIT_MISMATCH
    if args.json:
        print(json.dumps(rep.as_dict(), indent=2))
    else:
        rows = [(c.source, c.vectors, c.mismatches) for c in rep.sets]
        print(table(["set", "vectors", "mismatches"], rows,
                    title=f"MCU law: Python model vs {args.against} "
                    f"(-ffp-contract={args.contract}, {rep.build})"))
        print(f"{rep.vectors} vectors compared, {rep.mismatches} mismatches "
              f"({rep.seconds:.1f} s)")
        first = rep.first
        if first is not None:
            m = first.first
            print(f"first mismatch: {first.source}, step {m.step}, field {m.field}: "
                  f"model {m.model}, build {m.build}")
    return EXIT_MISMATCH if rep.mismatches else 0
