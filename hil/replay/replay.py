"""Bit-exact replay of the MCU firmware model against a log of :mod:`hil.replay.record`.

For each box the replay builds the current MCU model over bare link memories (no driver
board, no plant), and walks the log in time order: each cycle it applies the logged
fieldbus outputs exactly as the box did, each 5 kHz step it loads the logged upstream
memory and CRC-error count, steps the MCU and compares the downstream registers with the
logged ones; at the end of each cycle it compares the fieldbus input record. The first
difference is reported with its time, link, field, expected and got values.

A log that cannot be replayed (missing, foreign, damaged, without replay metadata, with
metadata that does not parse, with nothing to replay) is a :class:`ReplayError` of one line
naming the file. A truncated log (a killed run) is replayed up to the last MCU step all of
its channels cover, and the result says so (``truncated``, ``stop_reason``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from hil.fieldbus.boxes import McuBox
from hil.fieldbus.chain import CYCLE_TICKS
from hil.fieldbus.topology import Topology, TopologyError, load_topology
from hil.framelog import FrameLogError, FrameLogReader
from hil.framelog.formats import split_mcu_up
from hil.framelog.reader import LogInfo
from hil.replay.fpga_replay import column_name, current_trace, replay_board_detail
from hil.replay.record import topics
from hil.sim.actuator import TRACE_WIDTH
from plant.config import (
    DECLARED,
    RUN_CHOICES,
    Config,
    ConfigError,
    as_recorded,
    schema,
)

DOWN_NAMES = [name for _addr, name, *_ in B.DOWN_REGISTERS]


class ReplayError(Exception):
    """A log that cannot be replayed (missing channels or metadata); one line."""


@dataclass
class Divergence:
    t_s: float
    link: str
    field: str
    expected: int | float
    got: int | float

    def __str__(self) -> str:
        return (f"t = {self.t_s:.6f} s, {self.link}, field {self.field}: expected "
                f"{self.expected}, got {self.got}")


@dataclass
class ReplayResult:
    boxes: int
    mcu_steps: int
    cycles: int
    divergence: Divergence | None
    simulated_s: float
    fpga_ticks: int = 0  # driver-board ticks replayed (logs of level "full")
    truncated: bool = False  # the log was cut short: replayed up to where it is readable
    stop_reason: str = ""  # where a truncated log ends (FrameLogReader's words)

    @property
    def ok(self) -> bool:
        return self.divergence is None


class _ReplayBox(McuBox):
    """A box's MCU board over bare link memories, which the replay fills from the log."""

    def __init__(self, box, cfg: Config, offsets: list[int]) -> None:  # noqa: ANN001
        links = [LinkMemory(cfg) for _ in box.actuators]
        super().__init__(box, cfg, links, offsets)
        self.links = links
        self._fill()


def _field_of_record(dtype: np.dtype, byte: int) -> str:
    for slot, (sub, off) in dtype.fields.items():
        if off <= byte < off + sub.itemsize:
            for name, (_, o2) in sorted(sub.fields.items(), key=lambda kv: kv[1][1]):
                size = sub.fields[name][0].itemsize
                if off + o2 <= byte < off + o2 + size:
                    return f"{slot}.{name}"
    return f"byte {byte}"


def _record_value(dtype: np.dtype, raw: np.ndarray, field: str) -> int | float:
    if "." not in field:
        return int(raw[int(field.split()[-1])]) if field.startswith("byte") else 0
    slot, name = field.split(".")
    return np.frombuffer(raw.tobytes(), dtype=dtype)[0][slot][name].item()


def _flat(tree: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _metadata(path: str | Path, info: LogInfo) -> tuple[Config, Topology, dict[str, int]]:
    """The logged configuration (checked against the schema), topology and board offsets.

    In a log whose end is cut off nothing checks the metadata's bytes (the data-section CRC
    is at the end), so every field is parsed defensively: ReplayError, one line, otherwise.
    """
    meta = info.metadata.get("eha-hil.replay")
    if not meta:
        if info.truncated:
            raise ReplayError(f"{path}: truncated before its replay metadata "
                              f"({info.stop_reason}): nothing to replay")
        raise ReplayError(f"{path}: no replay metadata (not a log of `eha-hil bus run --log`)")
    where = f"{path}: replay metadata"
    try:
        data = json.loads(meta["config"])
        if not isinstance(data, dict):
            raise ValueError("not a JSON object")
        logged = as_recorded(_flat(data))  # logs from before [firmware], plant_numerics
        # A sensor's declared keys and the run choices missing from an older log keep their
        # defaults.
        missing = sorted(set(_flat(schema())) - set(logged) - set(DECLARED) - set(RUN_CHOICES))
        if missing:
            raise ValueError(f"no key {missing[0]}")
        cfg = Config(schema(), [f"log {path}"]).with_overrides(logged, f"log {path}")
    except KeyError:
        raise ReplayError(f"{where}: no 'config'") from None
    except (ValueError, ConfigError) as exc:  # JSONDecodeError is a ValueError
        raise ReplayError(f"{where}: config: {exc}") from None
    try:
        name = meta["topology"]
        topo = load_topology(name.split()[-1] if name.startswith("topology ") else name)
    except KeyError:
        raise ReplayError(f"{where}: no 'topology'") from None
    except TopologyError as exc:
        raise ReplayError(f"{where}: {exc}") from None
    try:
        offsets = json.loads(meta["offsets"])
        want = [f"{b.id}.{k}" for b in topo.boxes for k in range(len(b.actuators))]
        for key in want:
            if not isinstance(offsets.get(key), int):
                raise ValueError(f"no integer offset for board {key}")
    except KeyError:
        raise ReplayError(f"{where}: no 'offsets'") from None
    except (ValueError, AttributeError) as exc:
        raise ReplayError(f"{where}: offsets: {exc}") from None
    return cfg, topo, offsets


def _check_width(path: str | Path, topic: str, frames: np.ndarray, width: int) -> None:
    if frames.ndim != 2 or frames.shape[1] != width:
        raise ReplayError(f"{path}: {topic}: frames of {frames.shape[-1]} values, the replay "
                          f"needs {width} (a log of another version?)")


def _check_up(path: str | Path, topic: str, frames: np.ndarray) -> None:
    # upstream frames: uint16 x 34, or uint32 x 33 in logs written before that
    try:
        split_mcu_up(frames[:0])
    except ValueError as exc:
        raise ReplayError(f"{path}: {topic}: {exc} (a log of another version?)") from None


def replay_mcu(path: str | Path, config_override: Config | None = None) -> ReplayResult:
    """Replay every box of a log; the first divergence, or none.

    ReplayError (one line) for a log that cannot be replayed or holds no MCU step to
    replay; a truncated log is replayed up to its readable end (``truncated`` is set).
    """
    try:
        reader = FrameLogReader(path)
        info = reader.info()
    except FrameLogError as exc:
        raise ReplayError(str(exc)) from None
    logged_cfg, topo, offsets = _metadata(path, info)
    cfg = config_override or logged_cfg
    tick_ns = cfg.get("sim.tick_ns")
    # MCU steps per fieldbus cycle as the run logged them (not inferred from the counts,
    # which a truncated log no longer has in that ratio).
    per = CYCLE_TICKS // logged_cfg.get("mcu.period_ticks")
    steps = cycles = planned = 0
    first: Divergence | None = None
    traces: list = []  # (box, board, logged trace) for the FPGA replay
    t_end = 0
    for box in topo.boxes:
        n_act = len(box.actuators)
        rbox = _ReplayBox(box, cfg, [offsets[f"{box.id}.{k}"] for k in range(n_act)])
        tp = topics(box.id)
        want = [tp["inputs"]] + ([tp["outputs"]] if rbox.out_dtype.itemsize else [])
        traced = {c.topic for c in info.channels if c.topic.startswith("/fpga/")}
        for k in range(n_act):
            tk = topics(box.id, k)
            want += [tk["up"], tk["down"]] + ([tk["trace"]] if tk["trace"] in traced else [])
        try:
            blk = reader.blocks_many(want)
        except FrameLogError as exc:
            if info.truncated and "no topic" in str(exc):
                raise ReplayError(f"{path}: truncated before the MCU channels of box "
                                  f"{box.id} ({info.stop_reason}): nothing to replay") from None
            raise ReplayError(str(exc)) from None
        ins = blk[tp["inputs"]]
        outs = blk.get(tp["outputs"])
        ups = [blk[topics(box.id, k)["up"]] for k in range(n_act)]
        downs = [blk[topics(box.id, k)["down"]] for k in range(n_act)]
        _check_width(path, tp["inputs"], ins.frames, rbox.in_dtype.itemsize)
        if outs is not None:
            _check_width(path, tp["outputs"], outs.frames, rbox.out_dtype.itemsize)
        for k in range(n_act):
            _check_up(path, topics(box.id, k)["up"], ups[k].frames)
            _check_width(path, topics(box.id, k)["down"], downs[k].frames, B.DOWN_WORDS)
            if topics(box.id, k)["trace"] in blk:
                tr = blk[topics(box.id, k)["trace"]]
                if current_trace(tr.frames) is None:
                    _check_width(path, topics(box.id, k)["trace"], tr.frames, TRACE_WIDTH)
        n_cycles = len(ins.t_ns)
        covered = min([len(x.t_ns) for x in ups + downs]) // per if n_act else n_cycles
        if info.truncated:
            # The channels of one box end at different points of a cut log: replay the
            # cycles that every one of them covers, outputs included (a cycle's outputs are
            # logged at its start).
            n_cycles = min(n_cycles, covered)
            last_out = int(outs.t_ns[-1]) if outs is not None and len(outs.t_ns) else -1
            cycle_ns = CYCLE_TICKS * tick_ns
            while outs is not None and n_cycles and \
                    int(ins.t_ns[n_cycles - 1]) - cycle_ns > last_out:
                n_cycles -= 1
        elif any(len(x.t_ns) != per * n_cycles for x in ups + downs):
            raise ReplayError(f"{path}: box {box.id}: {n_cycles} cycles but "
                              f"{[len(x.t_ns) for x in ups + downs]} MCU steps logged per "
                              f"link (expected {per} per cycle): the log is inconsistent")
        planned += n_cycles
        div = None
        s = 0
        # Per-step data as plain Python objects / row views: the loop runs 5000x per s.
        ticks = (ups[0].t_ns // tick_ns).tolist() if n_act else []
        up_split = [split_mcu_up(u.frames) for u in ups]
        up_rows = [w for w, _ in up_split]
        up_crc = [c.tolist() for _, c in up_split]
        down_exp = [d.frames.tolist() for d in downs]
        links = rbox.links
        # Outputs by the tick they were applied at: a cycle whose frame was lost applied
        # none, a duplicated frame applied its record twice.
        applied: dict[int, list[bytes]] = {}
        if outs is not None:
            for t_ns, frame in zip(outs.t_ns.tolist(), outs.frames, strict=True):
                applied.setdefault(t_ns // tick_ns, []).append(frame.tobytes())
        for c in range(n_cycles):
            start = ticks[s] if s < len(ticks) else rbox.tick
            for frame in applied.get(start, ()):
                rbox.apply(frame)
            for _ in range(per if n_act else 0):  # (a box of sensors has no MCU steps)
                tick = ticks[s]
                for k, link in enumerate(links):
                    link.up = up_rows[k][s]
                    link.up_crc_errors = up_crc[k][s]
                rbox.board.step(tick)
                for k, link in enumerate(links):
                    got = link.down.tolist()
                    exp = down_exp[k][s]
                    if got != exp:
                        r = next(i for i, (a, b) in enumerate(zip(got, exp, strict=True)) if a != b)
                        div = Divergence(tick * tick_ns * 1e-9, f"/lvds/{box.id}.{k}/down",
                                         DOWN_NAMES[r], exp[r], got[r])
                        break
                if div:
                    break
                s += 1
                rbox.tick = tick + rbox.period
            if div:
                break
            rbox._fill(per * rbox.period)
            got = np.frombuffer(rbox.inputs(), dtype=np.uint8)
            exp = ins.frames[c]
            if not np.array_equal(got, exp):
                byte = int(np.flatnonzero(got != exp)[0])
                field = _field_of_record(rbox.in_dtype, byte)
                div = Divergence(int(ins.t_ns[c]) * 1e-9, f"/mcu/{box.id}/inputs", field,
                                 _record_value(rbox.in_dtype, exp, field),
                                 _record_value(rbox.in_dtype, got, field))
                break
            cycles += 1
        steps += s
        t_end = max(t_end, int(ins.t_ns[n_cycles - 1]) if n_cycles else 0)
        if div and (first is None or div.t_s < first.t_s):
            first = div
        for k in range(n_act):
            topic = topics(box.id, k)["trace"]
            if topic in blk:
                traces.append((box.id, k, blk[topic]))
    fpga_ticks = 0
    for box_id, k, tr in traces:
        frames = current_trace(tr.frames)
        row, col, got = replay_board_detail(cfg, frames)
        fpga_ticks += len(tr.t_ns) if row < 0 else row
        if row >= 0:
            div = Divergence(int(tr.t_ns[row]) * 1e-9, f"/fpga/{box_id}.{k}/trace",
                             column_name(col), int(frames[row, col]), got)
            if first is None or div.t_s < first.t_s:
                first = div
    if planned == 0:
        why = f"truncated ({info.stop_reason}) before the first MCU cycle" if info.truncated \
            else "no MCU cycle logged"
        raise ReplayError(f"{path}: {why}: nothing to replay")
    return ReplayResult(len(topo.boxes), steps, cycles, first, t_end * 1e-9, fpga_ticks,
                        info.truncated, "" if info.complete else info.stop_reason)


__all__ = ["Divergence", "ReplayError", "ReplayResult", "replay_mcu"]
