"""Replay of fieldbus traffic (a capture or a CAN log of ``eha-hil bus run``): the logged
requests go through a fresh chain of boxes, and each reply it gives is compared bit for bit
with the logged reply to the same request.

The chain runs in lockstep, as in ``bus run`` (a request of a newer cycle advances the
boxes), so a run's traffic replays exactly with the same topology, box model and
configuration. Traffic served by ``eha-hil serve`` does not: there the wall clock moved
the boxes, not the frames. Requests and replies are paired by datagram index and logical
address (the master's cycle number mod 256 and the frame's window); PDUs are compared, the
CRC-32 trailer (if any) was checked on reading.
"""

from __future__ import annotations

from collections import defaultdict, deque
from dataclasses import dataclass

from hil.fieldbus.chain import Chain
from hil.fieldbus.topology import Topology
from hil.fieldbus.traffic import Traffic
from plant.config import Config
from protocols import ethercat as ec


@dataclass
class TrafficReplayResult:
    requests: int = 0          # requests fed to the chain
    rejected: int = 0          # requests the chain discarded (stale, undecodable)
    compared: int = 0          # logged replies compared with the chain's
    unmatched: int = 0         # logged replies with no request before them
    unanswered: int = 0        # requests whose reply is not in the log (lost)
    skipped: int = 0           # malformed frames or frames of unknown direction
    divergence: str | None = None
    first_s: float | None = None   # times relative to the file's first frame
    last_s: float | None = None

    @property
    def ok(self) -> bool:
        return self.divergence is None and self.compared > 0


def _key(pdu: bytes) -> tuple[int, int]:
    d = ec.decode_pdu(pdu, allow_trailing=False)[0]
    return d.idx, d.lad


def _difference(logged: bytes, replayed: bytes, topo_windows) -> str:
    """Where two reply PDUs first differ: the datagram field, or the box's input bytes."""
    want = ec.decode_pdu(logged, allow_trailing=False)
    have = ec.decode_pdu(replayed, allow_trailing=False)
    for k, (a, b) in enumerate(zip(want, have, strict=False)):
        if a.wkc != b.wkc:
            return f"datagram {k} working counter: logged {a.wkc}, replayed {b.wkc}"
        if a.data != b.data:
            i = next(j for j, (x, y) in enumerate(zip(a.data, b.data, strict=False)) if x != y)
            address = a.lad + i
            box = next((w for w in topo_windows if w.lad <= address < w.end), None)
            where = ""
            if box is not None:
                inputs = box.lad + box.out_len
                part, start = ("inputs", inputs) if address >= inputs else ("outputs", box.lad)
                where = f" (box {box.box} {part} byte {address - start})"
            return (f"datagram {k} logical address {address}{where}: logged "
                    f"{a.data[i]:#04x}, replayed {b.data[i]:#04x}")
    return f"{len(want)} datagrams logged, {len(have)} replayed"


class TopologyMismatch(ValueError):
    """The file's cycle does not have the frames the topology sends (one line)."""


def _layout_text(frames: object) -> str:
    return ", ".join(f"LRW lad {lad} len {n}" for lad, n in sorted(frames)) or "none"


def check_layout(traffic: Traffic, topo: Topology,
                 plan: tuple[tuple[int, int, int], ...]) -> None:
    """TopologyMismatch when the logged requests' LRW datagrams (address, length) are not
    the ones ``topo`` sends each cycle: a capture of another robot would else be reported
    as a firmware divergence at its first reply."""
    logged: set[tuple[int, int]] = set()
    for f in traffic.frames:
        if f.direction == "tx" and f.pdu is not None:
            logged.update((d.adp | d.ado << 16, len(d.data)) for d in f.datagrams
                          if d.cmd == ec.Command.LRW)
            if len(logged) > len(plan):
                break
    want = {(lad, n) for lad, n, _ in plan}
    if logged and logged != want:
        meta = traffic.metadata.get("topology")
        hint = (f"; it was recorded with --topology {meta}" if meta and meta != topo.name
                else "; give the run's --topology")
        raise TopologyMismatch(
            f"{traffic.path}: its cycle ({_layout_text(logged)}) is not that of topology "
            f"{topo.name} ({_layout_text(want)}){hint}")


def replay_traffic(traffic: Traffic, topo: Topology, cfg: Config,
                   model: str = "stack") -> TrafficReplayResult:
    """Feed ``traffic``'s requests to a fresh chain; compare every logged reply. Stops at the
    first divergence."""
    chain = Chain(topo, cfg, model, crc_trailer=False)
    check_layout(traffic, topo, chain.plan.frames)
    windows = chain.plan.windows
    res = TrafficReplayResult()
    pending: dict[tuple[int, int], deque[bytes]] = defaultdict(deque)
    # times relative to the file's first frame (a CAN log stamps wall-clock epoch time)
    t0 = min((f.ts_ns for f in traffic.frames), default=0)
    for f in traffic.frames:
        if f.pdu is None or f.direction is None:
            res.skipped += 1
            continue
        if res.first_s is None:
            res.first_s = (f.ts_ns - t0) / 1e9
        res.last_s = (f.ts_ns - t0) / 1e9
        if f.direction == "tx":
            res.requests += 1
            reply = chain.handle(f.pdu)
            if reply is None:
                res.rejected += 1
            else:
                pending[_key(reply)].append(reply)
            continue
        queue = pending.get(_key(f.pdu))
        if not queue:
            res.unmatched += 1
            continue
        expected = queue.popleft()
        res.compared += 1
        if expected != f.pdu:
            d = ec.decode_pdu(f.pdu, allow_trailing=False)[0]
            res.divergence = (f"reply at t = {(f.ts_ns - t0) / 1e9:.6f} s after the first "
                              f"frame (idx {d.idx}, lad {d.lad}): "
                              + _difference(f.pdu, expected, windows))
            break
    res.unanswered = sum(len(q) for q in pending.values())
    return res
