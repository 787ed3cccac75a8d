"""Run the chain of boxes as its own process, answering frames on a transport.

``python -m hil.fieldbus.serve_chain --transport udp --port 0 --topology hydra_full``
prints ``READY <port or path>`` on stdout once it listens, then serves until killed or
until the transport closes; if it cannot listen (a port already taken), one line
``ERROR <reason>`` and exit 2. ``--crc-trailer``: frames carry the CRC-32 trailer
(:mod:`hil.fieldbus.wire`).
"""

from __future__ import annotations

import argparse
import json
import sys

from hil.fieldbus.chain import Chain
from hil.fieldbus.topology import load_topology
from hil.transports import BACKENDS, TransportError, backend
from plant.config import Config


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hil.fieldbus.serve_chain")
    ap.add_argument("--transport", required=True,
                    choices=[b for b in BACKENDS if backend(b).can_listen()])
    ap.add_argument("--port", required=True,
                    help="the backend's address: UDP port (0: any free), serial device, CAN "
                    "channel")
    ap.add_argument("--topology", default="hydra_full")
    ap.add_argument("--model", default="stack", choices=("stack", "robot", "echo"))
    ap.add_argument("--config-json", required=True)
    ap.add_argument("--faults-json", help="LVDS and sensor faults to put on the boxes")
    ap.add_argument("--crc-trailer", action="store_true",
                    help="frames carry the CRC-32 trailer")
    args = ap.parse_args(argv)
    cfg = Config(json.loads(args.config_json), ["chain process"])
    chain = Chain(load_topology(args.topology), cfg, args.model, crc_trailer=args.crc_trailer)
    if args.faults_json:
        from hil.fieldbus.faults import parse_faults
        from hil.fieldbus.stack_faults import install_box_faults

        plan = parse_faults(json.loads(args.faults_json), "faults (from the master)")
        if plan.box_faults:
            install_box_faults(chain, plan)
    try:
        listening = backend(args.transport).listen(args.port)
    except TransportError as exc:
        print(f"ERROR {exc}", flush=True)
        return 2
    end = listening.end
    print(f"READY {listening.address}", flush=True)
    try:
        while True:
            frame = end.recv(timeout=1.0)
            if frame is None:
                continue
            reply = chain.handle(frame)
            if reply is not None:
                end.send(reply)
    except (TransportError, KeyboardInterrupt):
        return 0
    finally:
        end.close()
        if listening.close is not None:
            listening.close()


if __name__ == "__main__":
    sys.exit(main())
