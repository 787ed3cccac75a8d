"""``eha-hil config show|presets``: the resolved configuration, the shipped presets."""

from __future__ import annotations

import argparse
import json

from hil.cli.args import common
from hil.cli.contract import Context, Outcome, command


# --- config ----------------------------------------------------------------------------------
def cmd_config_show(args: argparse.Namespace, ctx: Context) -> Outcome:
    cfg = ctx.config()
    out = [f"# {' + '.join(cfg.sources)}"]

    def walk(tree: dict, prefix: str) -> None:
        scalars = {k: v for k, v in tree.items() if not isinstance(v, dict)}
        if scalars:
            out.append(f"\n[{prefix}]")
            for k, v in scalars.items():
                out.append(f"{k} = {json.dumps(v)}")
        for k, v in tree.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}.{k}" if prefix else k)

    walk(cfg.data, "")
    return Outcome("\n".join(out), {"sources": cfg.sources, "config": cfg.data})


def cmd_config_presets(args: argparse.Namespace, ctx: Context) -> Outcome:
    from plant.config import preset_names  # (numpy with it: not for the parser's sake)

    names = preset_names()
    return Outcome("\n".join(names), names)


def add_parser(sub) -> None:  # noqa: ANN001 - argparse's sub-parsers
    """Register ``config show|presets``."""
    cfgp = sub.add_parser("config", help="inspect configurations")
    csub = cfgp.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    p = csub.add_parser("show", parents=[common(plot=False)],
                        help="print the resolved configuration")
    command(p, cmd_config_show)
    p = csub.add_parser("presets", parents=[common(plot=False, config=False)],
                        help="list shipped presets")
    command(p, cmd_config_presets)
