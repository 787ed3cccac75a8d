"""The bus system: PC loop + master on one side of a transport, the chain of boxes on the
other, stepped cycle by cycle (1 kHz) in lockstep.

The chain runs in this process for ``inproc`` (and for ``serial`` over ``loop://``-style
pairs and ``can`` on python-can's virtual bus), or in a separate process for ``udp`` and
``serial`` over a pseudo-terminal (``python -m hil.fieldbus.serve_chain``). The master
waits for each cycle's replies (``reply_timeout_s`` of wall time), so the same scenario
gives the same bytes on every transport when nothing is lost.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.fieldbus.chain import CYCLE_TICKS, Chain
from hil.fieldbus.master import Master
from hil.fieldbus.topology import Topology
from plant.config import Config

#: pc(cycle, master): sets the outputs for this cycle from the inputs of the last one.
PcFn = Callable[[int, Master], None]
#: Called with (cycle, tick, frame bytes, direction "tx"/"rx") for logs and captures.
TapFn = Callable[[int, int, bytes, str], None]
#: Called once per cycle with (cycle, tick, frames sent, frames received), in the orders a
#: tap sees them, once the cycle has ended (the master's counters hold it): one call per
#: cycle for a log.
CycleTapFn = Callable[[int, int, list[bytes], list[bytes]], None]


@dataclass
class BusRecord:
    """What a run leaves: the input image after every cycle and the counters."""

    inputs: np.ndarray          # (cycles kept, input bytes) uint8, oldest first
    master: dict[str, int]
    chain: dict[str, int] | None
    transport: dict[str, int]
    faults: dict[str, int] | None = None  # what the fieldbus faults did (hil.fieldbus.faults)
    first_cycle: int = 0        # the run's cycle (from 0) of ``inputs[0]``


class BusSystem:
    """Master + transport + chain; :meth:`run` steps cycles."""

    def __init__(self, topo: Topology, cfg: Config, transport: str = "inproc",
                 model: str = "stack", reply_timeout_s: float = 2.0,
                 remote: bool | None = None, tap: TapFn | None = None,
                 transport_options: dict | None = None, faults: object = None,
                 crc_trailer: bool | None = None, tap_cycle: CycleTapFn | None = None) -> None:
        from hil.transports import TransportError, backend, transport_pair

        kind = backend(transport)
        #: Frames carry the CRC-32 trailer (hil.fieldbus.wire): the backend's default
        #: (every one but udp) unless given.
        self.crc_trailer = kind.crc_trailer_by_default if crc_trailer is None else crc_trailer
        if faults is not None and not self.crc_trailer:
            _refuse_undetectable_flips(faults)
        self.topology = topo
        self.master = Master(topo, self.crc_trailer)
        self.transport = transport
        #: In-process chain on a pty/CAN pair: how long to wait for a sent frame to arrive.
        self.inline_wait_s = 0.5
        self.reply_timeout_s = reply_timeout_s
        self.tap = tap
        self.tap_cycle = tap_cycle
        self.proc: subprocess.Popen | None = None
        self.m_end = self.s_end = None
        self._release = None  # what the remote peer's set-up made (e.g. a pty)
        self._in_memory = kind.in_memory
        self.chain: Chain | None = None
        opts = dict(transport_options or {})
        if remote is None:
            remote = kind.remote_by_default
        # A remote chain gets the LVDS/sensor faults as the raw declaration (JSON).
        self._remote_faults = None
        if remote and faults is not None:
            from hil.fieldbus.faults import check_topology, parse_faults

            plan = parse_faults(faults)  # validate here: errors name the caller's entry
            check_topology(plan, topo)
            if plan.box_faults:
                try:
                    self._remote_faults = json.dumps(faults)
                except TypeError:
                    raise ValueError("faults for a remote chain must be a plain declaration "
                                     "(dict or list), not a FaultPlan") from None
        if not remote:
            self.chain = Chain(topo, cfg, model, crc_trailer=self.crc_trailer)
            self.m_end, self.s_end = transport_pair(transport, **opts)
        else:
            try:
                peer = kind.remote_master(**opts)
            except TransportError:
                raise ValueError(f"transport {transport!r} cannot run the chain in another "
                                 "process") from None
            self._release = peer.close
            args = ["--transport", transport, "--port", peer.child_address]
            if self.crc_trailer:
                args.append("--crc-trailer")
            self.proc = _spawn_chain(args, topo, cfg, model, self._remote_faults)
            try:
                address = _ready_line(self.proc)
            except BaseException:
                self.close()
                raise
            self.m_end = peer.connect(address)
            self.s_end = None
        self.faults = None
        if faults is not None:
            self._install_faults(faults)

    def _install_faults(self, faults: object) -> None:
        """Fieldbus faults around the master's end; LVDS/sensor faults on the chain's boxes
        (which must then run in this process). See :mod:`hil.fieldbus.faults`."""
        from hil.fieldbus.faults import FaultError, FaultyTransport, parse_faults
        from hil.fieldbus.stack_faults import install_box_faults

        plan = parse_faults(faults)
        self.faults = plan
        if plan.box_faults and self._remote_faults is None:
            if self.chain is None:
                raise FaultError(f"{plan.where}: {plan.box_faults[0].name}: LVDS and sensor "
                                 "faults need the chain in this process (not remote)")
            install_box_faults(self.chain, plan)
        if plan.fieldbus:
            self.m_end = FaultyTransport(self.m_end, plan, lambda: self.master.cycle)

    def run(self, cycles: int, pc: PcFn, keep: int | None = None) -> BusRecord:
        """Run ``cycles`` fieldbus cycles; the input image is recorded after each, of which
        the last ``keep`` (None: all) are kept, in a ring: memory bounded for any length."""
        m = self.master
        if keep is not None and keep < 0:
            raise ValueError(f"keep = {keep}: expected >= 0 cycles")
        n_rows = cycles if keep is None else min(cycles, keep)
        rows = np.zeros((n_rows, len(m.input_image())), dtype=np.uint8)
        tap_cycle = self.tap_cycle
        for k in range(cycles):
            pc(m.cycle, m)
            frames = m.frames()
            tick = m.cycle * CYCLE_TICKS
            wire = getattr(self.m_end, "inner", self.m_end).stats  # below any fault wrapper
            sent0 = wire.frames_sent
            for f in frames:
                if self.tap:
                    self.tap(m.cycle, tick, f, "tx")
                self.m_end.send(f)
            if self.chain is not None:
                self._serve_inline(wire.frames_sent - sent0)
            if self.proc:
                timeout = self.reply_timeout_s
            else:
                timeout = 0.0 if self._in_memory else 0.05
            # Until every frame of the cycle is answered: stale replies (duplicated or
            # delayed ones) are read and counted, they do not stand for this cycle's.
            replies = []
            while not all(m._answered):
                reply = self.m_end.recv(timeout=timeout)
                if reply is None:
                    break
                if self.tap:
                    self.tap(m.cycle, tick, reply, "rx")
                replies.append(reply)
                m.receive(reply)
            cycle = m.cycle
            m.end_cycle()
            if tap_cycle is not None:
                tap_cycle(cycle, tick, frames, replies)
            if n_rows:
                rows[k % n_rows] = np.frombuffer(m.input_image(), dtype=np.uint8)
        first = cycles - n_rows
        if n_rows and first % n_rows:
            rows = np.roll(rows, -(first % n_rows), axis=0)
        return BusRecord(rows, m.stats.as_dict(),
                         None if self.chain is None else self.chain.stats.__dict__.copy(),
                         self.m_end.stats.as_dict(),
                         None if not hasattr(self.m_end, "fault_stats")
                         else self.m_end.fault_stats.as_dict(), first)

    def _serve_inline(self, expected: int) -> None:
        """Answer the frames the master just sent. In-process queues deliver at once; a pty
        or a CAN bus takes a moment, so wait (briefly) for as many frames as were sent.
        On an echoing port (serial ``loop://``: one end for both sides) the chain would read
        its own replies back, so it takes exactly the frames that were sent."""
        wait = 0.0 if self._in_memory else self.inline_wait_s
        shared = self.s_end is getattr(self.m_end, "inner", self.m_end)
        got = 0
        while not (shared and got >= expected):
            frame = self.s_end.recv(timeout=wait if got < expected else 0.0)
            if frame is None:
                return
            got += 1
            reply = self.chain.handle(frame)
            if reply is not None:
                self.s_end.send(reply)

    def close(self) -> None:
        if self.chain is not None and self.chain.engine is not None:
            self.chain.engine.close()  # (its helper threads)
        for end in (self.m_end, self.s_end):
            if end is not None:
                end.close()
        self.m_end = self.s_end = None
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
            self.proc = None
        if self._release is not None:
            self._release()
            self._release = None

    def __enter__(self) -> BusSystem:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _spawn_chain(args: list[str], topo: Topology, cfg: Config, model: str,
                 faults_json: str | None = None) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "hil.fieldbus.serve_chain", *args, "--topology",
           topo.source if topo.source.endswith(".toml") else topo.source.split()[-1],
           "--model", model, "--config-json", cfg_to_json(cfg)]
    if faults_json:
        cmd += ["--faults-json", faults_json]
    env = dict(os.environ)
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)


def _refuse_undetectable_flips(faults: object) -> None:
    """Bit flips on the fieldbus are injected above the transport, so only the CRC-32
    trailer can catch them: without it a flipped frame would be applied as if sent."""
    from hil.fieldbus.faults import FaultError, parse_faults

    plan = parse_faults(faults)
    for entry in plan.fieldbus:
        if entry.kind == "bitflip":
            raise FaultError(f"{plan.where}: {entry.name}: fieldbus bit flips need the CRC-32 "
                             "trailer to be caught; run with crc_trailer=True (--crc-trailer)")


def _ready_line(proc: subprocess.Popen) -> str:
    """The address the chain process listens on (its ``READY`` line); a TransportError with
    its one-line reason if it could not listen (e.g. the port is taken)."""
    from hil.transports import TransportError

    line = proc.stdout.readline()
    if line.startswith("ERROR "):
        proc.wait(5)
        raise TransportError(line[len("ERROR "):].strip())
    if not line.startswith("READY"):
        err = proc.stderr.read() if proc.poll() is not None else ""
        raise RuntimeError(f"chain process did not start: {line.strip()} {err.strip()}")
    return line.split()[1]


def cfg_to_json(cfg: Config) -> str:
    """A configuration as JSON (handed to the chain process)."""
    import json

    return json.dumps(cfg.data)
