"""Round-trip benchmarks of the transports, in one process or against an echo process.

``round_trip_rate(master, slave, payload, n)`` times ``n`` request/response pairs: the
master sends ``payload``, the slave end receives it and sends back ``responder(request)``,
the master receives and checks the reply. With ``slave=None`` the responder runs in
another process (see :func:`remote_echo`, which starts ``python -m hil.transports echo``)
and only the master side runs here.

Example (what ``python -m hil.transports bench`` runs for each backend)::

    master, slave = transport_pair("udp")
    rate = round_trip_rate(master, slave, bytes(1600), 2000)

    with remote_echo("udp", port=0) as connect:          # slave in a child process
        with open_transport("udp", "master", **connect) as master:
            rate = round_trip_rate(master, None, bytes(1600), 2000, responder=invert)
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

from hil.transports.base import Transport, TransportError

#: Size of the full-robot process image per direction [bytes]: the frame size the
#: benchmarks and tests use.
IMAGE_BYTES = 1600

#: Byte table for :func:`invert` (bytes.translate runs in C: ~1 us for 1.6 kB).
_INVERT = bytes(255 - i for i in range(256))

#: Transformations the echo responder can apply, by name (for the command line).
TRANSFORMS: dict[str, Callable[[bytes], bytes]] = {}


def identity(frame: bytes) -> bytes:
    """The request unchanged."""
    return frame


def invert(frame: bytes) -> bytes:
    """Every bit of the request flipped: a reply that cannot be mistaken for the request
    (a loop-back or a stale copy would fail the check)."""
    return frame.translate(_INVERT)


TRANSFORMS.update(none=identity, invert=invert)


def image_frame(seed: int = 0, size: int = IMAGE_BYTES) -> bytes:
    """A process-image-like frame of ``size`` bytes: runs of zeros (idle channels) between
    random bytes, so COBS meets both zero runs and long non-zero blocks. Deterministic for a
    given ``seed``."""
    rng = random.Random(seed)
    out = bytearray()
    while len(out) < size:
        if rng.random() < 0.4:
            out += bytes(rng.randrange(1, 40))
        else:
            out += rng.randbytes(rng.randrange(1, 300))
    return bytes(out[:size])


def round_trip_rate(
    master: Transport,
    slave: Transport | None,
    payload: bytes,
    n: int,
    responder: Callable[[bytes], bytes] = identity,
    timeout: float = 2.0,
) -> float:
    """Request/response pairs per second [1/s] over ``n`` round trips of ``payload``.

    ``slave`` is the other end served in this thread (inproc, udp pair, serial loop/pty,
    can virtual), or None when a responder in another process answers (then
    ``responder`` only computes the expected reply). Each reply is checked against
    ``responder(payload)``; a missing or wrong reply raises :class:`TransportError`.
    ``timeout`` [s] bounds each wait.
    """
    if n < 1:
        raise TransportError(f"round_trip_rate: n must be >= 1, got {n}")
    expected = responder(payload)
    start = time.perf_counter()
    for i in range(n):
        master.send(payload)
        if slave is not None:
            request = slave.recv(timeout)
            if request is None:
                raise TransportError(f"{slave.name}: the slave received nothing in round trip {i}")
            slave.send(responder(request))
        reply = master.recv(timeout)
        if reply is None:
            raise TransportError(f"{master.name}: no reply in round trip {i}")
        if reply != expected:
            raise TransportError(f"{master.name}: wrong reply in round trip {i}")
    return n / (time.perf_counter() - start)


def echo(transport: Transport, responder: Callable[[bytes], bytes] = identity,
         count: int | None = None, idle_timeout: float | None = None) -> int:
    """Answer every frame received on ``transport`` with ``responder(frame)``.

    Stops after ``count`` frames, or when nothing arrives for ``idle_timeout`` seconds
    (None: never). Returns the number of frames answered.
    """
    answered = 0
    while count is None or answered < count:
        frame = transport.recv(idle_timeout)
        if frame is None:
            break
        transport.send(responder(frame))
        answered += 1
    return answered


@contextlib.contextmanager
def remote_echo(name: str, transform: str = "invert", count: int | None = None,
                startup_timeout: float = 20.0, **options: Any) -> Iterator[dict[str, Any]]:
    """Run a slave-role echo responder of backend ``name`` in a child process.

    Yields the options a master needs to reach it (for udp ``{"remote_port": ...}``; for
    serial, whatever the master must know, usually nothing since the caller chose the
    device). ``options`` go to the child's :func:`open_transport` and must be plain
    JSON values. The child is stopped (terminate, then kill) when the block ends.
    """
    cmd = [sys.executable, "-m", "hil.transports", "echo", name, "--transform", transform,
           "--options", json.dumps(options)]
    if count is not None:
        cmd += ["--count", str(count)]
    # The child must import this package even when it is not installed: put the
    # directory holding `hil` on its path.
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    try:
        line = _read_line(proc, startup_timeout)
        if not line.startswith("ready "):
            err = ""
            try:
                # It printed no "ready": it has failed (or hangs); its last stderr line
                # says why.
                _, err = proc.communicate(timeout=2.0)
            except subprocess.TimeoutExpired:
                pass
            last = err.strip().splitlines()[-1] if err and err.strip() else line.strip()
            raise TransportError(f"{name}: echo process did not start: {last or 'no output'}")
        yield json.loads(line[len("ready "):])
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def _read_line(proc: subprocess.Popen[str], timeout: float) -> str:
    """The child's first stdout line, or "" if it exits or stays silent for ``timeout``."""
    import selectors

    assert proc.stdout is not None
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        if not sel.select(timeout):
            return ""
    return proc.stdout.readline()


def bench_all(size: int = IMAGE_BYTES, n: int = 2000, include_remote: bool = True
              ) -> list[dict[str, Any]]:
    """Round-trip rates [1/s] of a ``size``-byte frame for every backend configuration
    that runs on this machine (the table ``python -m hil.transports bench`` prints)."""
    from hil.transports.base import open_transport, transport_pair

    payload = image_frame(0, size)
    rows: list[dict[str, Any]] = []

    def run(label: str, make: Callable[[], tuple[Transport, Transport]], count: int) -> None:
        master, slave = make()
        try:
            round_trip_rate(master, slave, payload, max(1, count // 20), invert)  # warm up
            rate = round_trip_rate(master, slave, payload, count, invert)
        finally:
            master.close()
            slave.close()
        rows.append({"backend": label, "frame_bytes": size, "round_trips": count,
                     "rate_per_s": rate})

    run("inproc", lambda: transport_pair("inproc"), n * 20)
    run("udp (one process)", lambda: transport_pair("udp"), n)
    if include_remote:
        with remote_echo("udp", port=0) as connect:
            with open_transport("udp", "master", **connect) as master:
                round_trip_rate(master, None, payload, n // 20, invert)
                rate = round_trip_rate(master, None, payload, n, invert)
        rows.append({"backend": "udp (two processes)", "frame_bytes": size,
                     "round_trips": n, "rate_per_s": rate})
    run("serial loop://", lambda: transport_pair("serial", url="loop://"), max(1, n // 10))
    run("serial pty", lambda: transport_pair("serial"), n)
    run("can virtual FD", lambda: transport_pair("can", fd=True), n)
    run("can virtual classic", lambda: transport_pair("can", fd=False), max(1, n // 5))
    return rows
