"""A private network namespace with a veth pair, the ESC chain served on one end and SOEM
(:mod:`hil.fieldbus.esc.soem_master`) on the other: what the pysoem test and
``eha-hil bench ethercat --wire`` run. Needs root and ``ip`` (iproute2).

The namespace is created on entry and deleted on exit (with it the pair). IPv6 is off
inside it, so that only EtherCAT frames cross the wire.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

MASTER_IF, SLAVE_IF = "ecm", "ecs"
_ROOT = str(Path(__file__).resolve().parents[3])


class NamespaceError(Exception):
    """No namespace possible here; the message says why, in one line."""


def why_not() -> str | None:
    """Why a namespace with a veth pair cannot be made here, or None."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "needs root (network namespace, veth pair, raw sockets)"
    if shutil.which("ip") is None:
        return "needs `ip` (iproute2; make system-deps)"
    return None


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (_ROOT, env.get("PYTHONPATH")) if p)
    return env


def in_ns(ns: str, *cmd: str) -> list[str]:
    return ["ip", "netns", "exec", ns, *cmd]


@contextmanager
def veth_namespace() -> Iterator[str]:
    """The name of a fresh namespace holding the pair ``ecm`` (master) / ``ecs``."""
    why = why_not()
    if why:
        raise NamespaceError(why)
    name = f"ehaec{uuid.uuid4().hex[:8]}"
    r = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True)
    if r.returncode:
        raise NamespaceError(f"cannot create a network namespace: {r.stderr.strip()}")
    try:
        for key in ("all", "default"):
            subprocess.run(in_ns(name, "sh", "-c",
                                 f"echo 1 > /proc/sys/net/ipv6/conf/{key}/disable_ipv6"),
                           check=True, capture_output=True)
        for cmd in (["link", "add", MASTER_IF, "type", "veth", "peer", "name", SLAVE_IF],
                    ["link", "set", MASTER_IF, "up"], ["link", "set", SLAVE_IF, "up"]):
            subprocess.run(["ip", "-n", name, *cmd], check=True, capture_output=True)
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def start_serve(ns: str, *extra: str) -> subprocess.Popen:
    """``eha-hil serve --transport ethercat`` on ``ecs`` (hydra_full, real-time priority,
    --json), returned once it is ready."""
    p = subprocess.Popen(in_ns(ns, sys.executable, "-m", "hil.cli", "serve", "--transport",
                               "ethercat", "--interface", SLAVE_IF, "--topology",
                               "hydra_full", "--realtime", "--json", *extra),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=_env())
    seen = []
    for line in p.stderr:  # (warnings may come first)
        if "ready on" in line:
            return p
        seen.append(line.strip())
    p.kill()
    raise RuntimeError(f"serve did not start: {' | '.join(seen)[-800:]}")


def stop_serve(p: subprocess.Popen) -> dict:
    """Stop it (SIGTERM) and return its JSON report (with ``exit_code``: 1 if a threshold
    was exceeded, the report's ``failures`` say which)."""
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=30)
    try:
        report = json.loads(out)
    except json.JSONDecodeError:
        raise RuntimeError(f"serve failed ({p.returncode}): {err.strip()[-800:]}") from None
    report["exit_code"] = p.returncode
    return report


def master_cpu() -> list[str]:
    """``taskset`` arguments putting the master on the CPU of the served frame thread
    (:mod:`hil.sim.realtime`: the last one), off the CPUs computing the boxes: SOEM waits for
    each reply polling, which at its real-time priority would hold a box thread's CPU."""
    from hil.sim.realtime import split_cpus

    frame_cpus, _ = split_cpus()
    if frame_cpus is None or shutil.which("taskset") is None:
        return []
    return ["taskset", "-c", ",".join(map(str, sorted(frame_cpus)))]


def run_master(ns: str, *args: str, timeout_s: float = 300.0, progress=None) -> dict:  # noqa: ANN001
    """:mod:`hil.fieldbus.esc.soem_master` on ``ecm`` at real-time priority (below the
    frame thread's), on the frame thread's CPU; its JSON. ``progress(line)``: each of its
    progress lines as it prints them."""
    p = subprocess.Popen(in_ns(ns, *master_cpu(), "chrt", "-f", "40", sys.executable, "-m",
                               "hil.fieldbus.esc.soem_master", MASTER_IF, *args),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=_env())
    err: list[str] = []
    out: list[str] = []
    reader = threading.Thread(target=lambda: out.append(p.stdout.read()), daemon=True)
    reader.start()
    timer = threading.Timer(timeout_s, p.kill)
    timer.start()
    try:
        for line in p.stderr:
            if line.startswith("master: ") and progress is not None:
                progress(line.rstrip())
            else:
                err.append(line)
        reader.join()
        p.wait()
    finally:
        timer.cancel()
    if p.returncode:
        raise RuntimeError(f"SOEM master failed ({p.returncode}): {''.join(err).strip()[-500:]}")
    return json.loads(out[0])
