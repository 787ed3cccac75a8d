"""``python -m hil.transports``: an echo responder, a pty server and the round-trip bench.

    python -m hil.transports echo udp --options '{"port": 0}'     # slave-role echo
    python -m hil.transports pty                                 # serve a pty, print its path
    python -m hil.transports bench --size 1600 --n 2000          # rates of every backend

``echo`` prints one line ``ready {json}`` (the options a master needs, e.g. the udp port)
to stdout once it listens, so a parent process can wait for it. Errors are one line on
stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from hil.transports.base import BACKENDS, TransportError, open_transport
from hil.transports.echo import TRANSFORMS, bench_all, echo


def _connect_options(transport: Any) -> dict[str, Any]:
    """What a master needs to reach this slave end."""
    if transport.name == "udp":
        host, port = transport.address
        return {"remote_host": "127.0.0.1" if host == "0.0.0.0" else host, "remote_port": port}
    return {}


def _cmd_echo(args: argparse.Namespace) -> int:
    try:
        options = json.loads(args.options)
    except json.JSONDecodeError as exc:
        raise TransportError(f"--options is not JSON: {exc}") from None
    if not isinstance(options, dict):
        raise TransportError("--options must be a JSON object, e.g. '{\"port\": 0}'")
    with open_transport(args.name, role="slave", **options) as slave:
        print("ready " + json.dumps(_connect_options(slave)), flush=True)
        echo(slave, TRANSFORMS[args.transform], args.count, args.idle_timeout)
    return 0


def _cmd_pty(args: argparse.Namespace) -> int:
    from hil.transports.serialport import SerialTransport, pty_pair

    with pty_pair() as pty_, SerialTransport("slave", fd=pty_.master_fd) as end:
        print(f"ready {json.dumps({'url': pty_.slave_path})}", flush=True)
        print(f"serial echo on {pty_.slave_path} (open it with url=...), Ctrl-C to stop",
              file=sys.stderr, flush=True)
        try:
            echo(end, TRANSFORMS[args.transform], args.count)
        except KeyboardInterrupt:
            pass
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    rows = bench_all(args.size, args.n, include_remote=not args.no_remote)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'backend':<22} {'frame [B]':>9} {'round trips':>11} {'rate [1/s]':>11}")
    for row in rows:
        print(f"{row['backend']:<22} {row['frame_bytes']:>9} {row['round_trips']:>11} "
              f"{row['rate_per_s']:>11.0f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.transports", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("echo", help="slave-role echo responder")
    p.add_argument("name", choices=BACKENDS)
    p.add_argument("--options", default="{}", help="JSON object of transport options")
    p.add_argument("--transform", choices=sorted(TRANSFORMS), default="invert")
    p.add_argument("--count", type=int, default=None, help="stop after this many frames")
    p.add_argument("--idle-timeout", type=float, default=None,
                   help="stop after this many seconds without a frame")
    p.set_defaults(func=_cmd_echo)
    p = sub.add_parser("pty", help="serve a serial echo on a new pseudo-terminal")
    p.add_argument("--transform", choices=sorted(TRANSFORMS), default="invert")
    p.add_argument("--count", type=int, default=None)
    p.set_defaults(func=_cmd_pty)
    p = sub.add_parser("bench", help="round-trip rate of every backend")
    p.add_argument("--size", type=int, default=1600, help="frame size [bytes]")
    p.add_argument("--n", type=int, default=2000, help="round trips per backend")
    p.add_argument("--no-remote", action="store_true", help="skip the two-process udp run")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except TransportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
