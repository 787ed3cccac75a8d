"""Declarative fault injection for the bus system, from a scenario's ``[[fault]]`` tables.

::

    seed = 7                      # optional: base seed (entry n uses seed + n unless it sets one)
    [[fault]]
    link = "fieldbus.down"        # fieldbus.down | fieldbus.up | lvds.down | lvds.up | sensor
    kind = "bitflip"              # see KINDS below
    rate = 0.01                   # per frame (fieldbus), see below for lvds
    start_s = 0.2                 # simulated time window [start_s, end_s)
    end_s = 0.4

Where each link is hit:

* ``fieldbus.down`` / ``fieldbus.up``: frames master -> chain / chain -> master, in a
  :class:`FaultyTransport` around the master's transport end. Kinds ``bitflip`` (``rate`` =
  probability per frame that the frame is hit; a hit frame gets ``bits`` distinct random
  bits flipped, default 1), ``drop``, ``duplicate`` (sent twice), ``delay`` (held for
  ``delay_cycles`` cycles, then delivered). ``frame = k`` restricts the fault to the k-th
  frame of each cycle. The frame check sequence (:mod:`hil.fieldbus.wire`) catches the
  flips: such frames are discarded and counted, never applied.
* ``lvds.down`` / ``lvds.up``: the LVDS link of one actuator (``box``, ``slot``) of a
  :class:`~hil.fieldbus.boxes.StackBox`, through :meth:`hil.sim.actuator.FpgaStack.link_fault`:
  ``dead`` stops the direction (no word passes), ``bitflip`` corrupts every N-th word with
  N = round(1 / rate) (deterministic: the link's own counter, ``seed`` is not used; the
  receiver discards and counts it), ``drop`` loses every N-th word (no start bit: nothing
  stored, nothing counted at the receiver), ``duplicate`` sends every N-th word twice (it
  takes the next word's slot), ``delay`` gives the direction a latency of ``delay_ticks``
  50 us ticks (1..63: each word carries the sender's memory as it was then). Switched on and
  off at fieldbus cycle boundaries.
* ``sensor``: one plant signal a sensor chip of one actuator (``box``, ``slot``) reads
  (``signal``, see :data:`SENSOR_SIGNALS`), upstream of the FPGA: the chip digitises the
  faulted value, so the board, the LVDS link and the MCU see what they would see.
  ``stuck`` holds the value at ``start_s`` (or ``value``, SI units), ``noisy`` adds Gaussian
  noise of standard deviation ``sigma`` (SI units) every tick, ``dead`` pins the chip's
  output code at 0 (lines low): the ADC channels read code 0, the AD7195 strain gauge
  reports a clamped conversion that the board rejects (ERR); a dead encoder (``theta_m``,
  ``x_piston``) delivers no valid frame (the chip's dead flag, ``plant.sensors.chips``): the
  board's master sees OK = 0 and the counts hold.

Deterministic: every random entry draws from its own ``numpy.random.Generator`` seeded with
its ``seed``, once per frame of its window (fieldbus) or once per tick (noisy sensor), so
the same seed gives the same faults on every transport.
"""

from __future__ import annotations

import math
import tomllib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hil.transports.base import Transport, deadline_of, remaining

CYCLE_S = 1e-3
CYCLE_TICKS = 20

LINKS = ("fieldbus.down", "fieldbus.up", "lvds.down", "lvds.up", "sensor")
KINDS: dict[str, tuple[str, ...]] = {
    "fieldbus.down": ("bitflip", "drop", "duplicate", "delay"),
    "fieldbus.up": ("bitflip", "drop", "duplicate", "delay"),
    "lvds.down": ("dead", "bitflip", "drop", "duplicate", "delay"),
    "lvds.up": ("dead", "bitflip", "drop", "duplicate", "delay"),
    "sensor": ("stuck", "noisy", "dead"),
}
#: Sensor signal name -> (plant output row name, chip). A dead encoder delivers no valid
#: frame (its master's OK flag drops, the counts hold); other dead chips read code 0.
SENSOR_SIGNALS: dict[str, tuple[str, str]] = {
    "theta_m": ("Y_THETA_M", "encoder"),
    "x_piston": ("Y_X_PISTON", "encoder"),
    "f_strain": ("Y_F_STRAIN", "strain"),
    "p_acc": ("Y_P_ACC", "pressure"),
    "p_pump_a": ("Y_P_PUMP_A", "pressure"),
    "p_pump_b": ("Y_P_PUMP_B", "pressure"),
    "p_cyl_a": ("Y_P_CYL_A", "pressure"),
    "p_cyl_b": ("Y_P_CYL_B", "pressure"),
    "temperature": ("Y_TEMP", "temperature"),
    "i_a": ("Y_IA", "current"),
    "i_b": ("Y_IB", "current"),
}

_COMMON = {"link", "kind", "start_s", "end_s", "seed"}
_EXTRA: dict[tuple[str, str], set[str]] = {}
for _l in ("fieldbus.down", "fieldbus.up"):
    _EXTRA[(_l, "bitflip")] = {"rate", "frame", "bits"}
    _EXTRA[(_l, "drop")] = {"rate", "frame"}
    _EXTRA[(_l, "duplicate")] = {"rate", "frame"}
    _EXTRA[(_l, "delay")] = {"rate", "frame", "delay_cycles"}
for _l in ("lvds.down", "lvds.up"):
    _EXTRA[(_l, "dead")] = {"box", "slot"}
    _EXTRA[(_l, "bitflip")] = {"box", "slot", "rate"}
    _EXTRA[(_l, "drop")] = {"box", "slot", "rate"}
    _EXTRA[(_l, "duplicate")] = {"box", "slot", "rate"}
    _EXTRA[(_l, "delay")] = {"box", "slot", "delay_ticks"}
_EXTRA[("sensor", "stuck")] = {"box", "slot", "signal", "value"}
_EXTRA[("sensor", "noisy")] = {"box", "slot", "signal", "sigma"}
_EXTRA[("sensor", "dead")] = {"box", "slot", "signal"}


class FaultError(ValueError):
    """A fault table that cannot be used; one line naming the entry and the key."""


@dataclass(frozen=True)
class Fault:
    """One validated ``[[fault]]`` entry."""

    index: int
    link: str
    kind: str
    start_s: float = 0.0
    end_s: float = math.inf
    rate: float = 1.0
    frame: int | None = None
    bits: int = 1
    delay_cycles: int = 1
    delay_ticks: int = 1
    box: int | None = None
    slot: int | None = None
    signal: str | None = None
    sigma: float = 0.0
    value: float | None = None
    seed: int = 0

    @property
    def name(self) -> str:
        return f"fault #{self.index} ({self.link} {self.kind})"

    @property
    def start_cycle(self) -> int:
        """First fieldbus cycle (1 ms) inside the window."""
        return _cycle_at(self.start_s)

    @property
    def end_cycle(self) -> float:
        """First cycle after the window (inf if open-ended)."""
        return math.inf if math.isinf(self.end_s) else _cycle_at(self.end_s)

    def active(self, cycle: int) -> bool:
        return self.start_cycle <= cycle < self.end_cycle


def _cycle_at(t_s: float) -> int:
    return math.ceil(t_s / CYCLE_S - 1e-9)


@dataclass(frozen=True)
class FaultPlan:
    """All faults of a scenario; build with :func:`parse_faults` or :func:`load_faults`."""

    faults: tuple[Fault, ...]
    where: str = "faults"

    def on(self, *links: str) -> tuple[Fault, ...]:
        return tuple(f for f in self.faults if f.link in links)

    @property
    def fieldbus(self) -> tuple[Fault, ...]:
        return self.on("fieldbus.down", "fieldbus.up")

    @property
    def box_faults(self) -> tuple[Fault, ...]:
        return self.on("lvds.down", "lvds.up", "sensor")

    def __bool__(self) -> bool:
        return bool(self.faults)


# --- parsing ----------------------------------------------------------------------------------

def load_faults(path: str | Path) -> FaultPlan:
    """The ``[[fault]]`` tables (and optional ``seed``) of a TOML file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise FaultError(f"{path}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise FaultError(f"{path}: not valid TOML: {exc}") from None
    check_file(data, str(path))
    return parse_faults(data, str(path))


#: What a fault file (``--faults FILE.toml``) may hold at its top level.
FILE_KEYS = ("seed", "fault")


def check_file(data: dict, where: str) -> None:
    """A fault file holds ``seed`` and ``[[fault]]`` tables and at least one fault: a
    misspelt table (``[[faults]]``) would otherwise inject nothing and say nothing."""
    for key, value in data.items():
        if key not in FILE_KEYS:
            what = ("table" if isinstance(value, dict | list) else "key")
            shown = f"[[{key}]]" if isinstance(value, list) else (
                f"[{key}]" if isinstance(value, dict) else key)
            raise FaultError(f"{where}: unknown {what} {shown} (a fault file holds "
                             "seed = N and [[fault]] tables)")
    if not data.get("fault"):
        raise FaultError(f"{where}: no [[fault]] table: nothing to inject")


def check_window(plan: FaultPlan, seconds: float) -> None:
    """Every fault's window must start inside a run of ``seconds``: one that starts
    after the end would never act (a run of N cycles holds cycles 0..N-1)."""
    cycles = _cycle_at(seconds)
    for f in plan.faults:
        if f.start_cycle >= cycles:
            raise FaultError(f"{plan.where}: {f.name}: key 'start_s' = {f.start_s:g} s is "
                             f"not inside the run ({seconds:g} s): the fault would never act")


def parse_faults(data: Any, where: str = "faults") -> FaultPlan:
    """Validate fault entries: a table ``{"seed": s, "fault": [...]}`` (the scenario's
    tables; other keys are left to the scenario), a list of entries, or a FaultPlan."""
    if isinstance(data, FaultPlan):
        return data
    if data is None:
        return FaultPlan((), where)
    base_seed = 0
    if isinstance(data, dict):
        base_seed = data.get("seed", 0)
        if isinstance(base_seed, bool) or not isinstance(base_seed, int) or base_seed < 0:
            raise FaultError(f"{where}: seed must be an integer >= 0, got {base_seed!r}")
        entries = data.get("fault", [])
    else:
        entries = data
    if not isinstance(entries, list | tuple):
        raise FaultError(f"{where}: [[fault]] must be a list of tables")
    return FaultPlan(tuple(_parse_one(n, e, where, base_seed) for n, e in enumerate(entries)),
                     where)


def _parse_one(n: int, raw: Any, where: str, base_seed: int) -> Fault:
    at = f"{where}: fault #{n}"
    if not isinstance(raw, dict):
        raise FaultError(f"{at}: expected a table, got {type(raw).__name__}")
    link = raw.get("link")
    if link not in LINKS:
        raise FaultError(f"{at}: key 'link': {link!r} is not one of {', '.join(LINKS)}")
    kind = raw.get("kind")
    if kind not in KINDS[link]:
        raise FaultError(f"{at} ({link}): key 'kind': {kind!r} is not one of "
                         f"{', '.join(KINDS[link])}")
    at = f"{where}: fault #{n} ({link} {kind})"
    allowed = _COMMON | _EXTRA[(link, kind)]
    for key in raw:
        if key not in allowed:
            raise FaultError(f"{at}: key {key!r} does not apply here; valid keys: "
                             f"{', '.join(sorted(allowed))}")

    def num(key: str, default: float, lo: float = -math.inf, hi: float = math.inf,
            lo_open: bool = False) -> float:
        v = raw.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or math.isnan(v):
            raise FaultError(f"{at}: key {key!r} must be a number, got {v!r}")
        v = float(v)
        if v < lo or v > hi or (lo_open and v == lo):
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
            raise FaultError(f"{at}: key {key!r} = {v:g} is outside {rng}")
        return v

    def integer(key: str, default: int | None, lo: int) -> int | None:
        v = raw.get(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise FaultError(f"{at}: key {key!r} must be an integer >= {lo}, got {v!r}")
        return v

    start = num("start_s", 0.0, 0.0)
    end = num("end_s", math.inf, 0.0)
    if end <= start:
        raise FaultError(f"{at}: key 'end_s' = {end:g} must be after start_s = {start:g}")
    kw: dict[str, Any] = {"start_s": start, "end_s": end,
                          "seed": integer("seed", base_seed + n, 0)}
    if "rate" in allowed:
        kw["rate"] = num("rate", 1.0, 0.0, 1.0, lo_open=link.startswith("lvds"))
    if "frame" in allowed:
        kw["frame"] = integer("frame", None, 0)
    if "bits" in allowed:
        kw["bits"] = integer("bits", 1, 1)
    if "delay_cycles" in allowed:
        kw["delay_cycles"] = integer("delay_cycles", 1, 1)
    if "delay_ticks" in allowed:
        kw["delay_ticks"] = integer("delay_ticks", 1, 1)
        if kw["delay_ticks"] > 63:
            raise FaultError(f"{at}: key 'delay_ticks' = {kw['delay_ticks']} exceeds the 63 "
                             "ticks of sender memory the link keeps")
    if "box" in allowed:
        for key in ("box", "slot"):
            if key not in raw:
                raise FaultError(f"{at}: key {key!r} is required")
        kw["box"] = integer("box", None, 0)
        kw["slot"] = integer("slot", None, 0)
    if "signal" in allowed:
        sig = raw.get("signal")
        if sig not in SENSOR_SIGNALS:
            raise FaultError(f"{at}: key 'signal': {sig!r} is not one of "
                             f"{', '.join(SENSOR_SIGNALS)}")
        kw["signal"] = sig
    if "sigma" in allowed:
        if "sigma" not in raw:
            raise FaultError(f"{at}: key 'sigma' is required (noise standard deviation, SI)")
        kw["sigma"] = num("sigma", 0.0, 0.0, lo_open=True)
    if "value" in allowed and "value" in raw:
        kw["value"] = num("value", 0.0)
    return Fault(n, link, kind, **kw)


def check_topology(plan: FaultPlan, topo: Any) -> None:
    """Box and slot of every box fault exist and the slot is an actuator."""
    for f in plan.box_faults:
        if f.box >= len(topo.boxes):
            raise FaultError(f"{plan.where}: {f.name}: key 'box' = {f.box}: topology "
                             f"{topo.name} has boxes 0..{len(topo.boxes) - 1}")
        box = topo.boxes[f.box]
        if f.slot >= len(box.slots) or box.slots[f.slot].kind != "actuator":
            raise FaultError(f"{plan.where}: {f.name}: key 'slot' = {f.slot}: box {f.box} "
                             f"has actuator slots {list(box.actuators)}")


# --- fieldbus: a transport wrapper -----------------------------------------------------------

@dataclass
class FaultStats:
    """What the fieldbus faults did, per direction, in frames: ``flipped`` corrupted frames
    passed on (a corrupted frame that is also duplicated counts twice), ``dropped`` frames
    removed, ``duplicated`` extra copies sent, ``delayed`` frames held for later cycles."""

    down_flipped: int = 0
    down_dropped: int = 0
    down_duplicated: int = 0
    down_delayed: int = 0
    up_flipped: int = 0
    up_dropped: int = 0
    up_duplicated: int = 0
    up_delayed: int = 0
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "extra"}


class _Direction:
    """The fieldbus faults of one direction and their generators."""

    def __init__(self, faults: tuple[Fault, ...], tag: str, stats: FaultStats) -> None:
        self.faults = faults
        self.rngs = [np.random.default_rng(f.seed) for f in faults]
        self.tag = tag
        self.stats = stats
        self.held: list[tuple[int, int, bytes]] = []  # (release cycle, order, frame)
        self._order = 0
        self._cycle = -1
        self._k = 0  # frame index within the cycle

    def _count(self, what: str) -> None:
        key = f"{self.tag}_{what}"
        setattr(self.stats, key, getattr(self.stats, key) + 1)

    def apply(self, frame: bytes, cycle: int) -> list[bytes]:
        """The frames to pass on now for ``frame`` (0, 1 or 2; delayed ones are held)."""
        if cycle != self._cycle:
            self._cycle, self._k = cycle, 0
        k = self._k
        self._k += 1
        out = [frame]
        flipped, held = False, 0
        for f, rng in zip(self.faults, self.rngs, strict=True):
            if not f.active(cycle) or (f.frame is not None and f.frame != k):
                continue
            u = rng.random()
            if f.kind == "bitflip":
                pos = rng.choice(8 * len(frame), size=f.bits, replace=False)
                if u < f.rate:
                    buf = bytearray(out[0])
                    for p in pos:
                        buf[p >> 3] ^= 1 << (p & 7)
                    out = [bytes(buf)] * len(out)
                    flipped = True
            elif u >= f.rate:
                continue
            elif f.kind == "drop":
                self._count("dropped")
                return []
            elif f.kind == "duplicate":
                out = out + [out[0]]
                self._count("duplicated")
            elif f.kind == "delay":
                for x in out:
                    self.held.append((cycle + f.delay_cycles, self._order, x))
                    self._order += 1
                    self._count("delayed")
                    held += 1
                out = []
                break
        if flipped:  # counted per corrupted frame put on the wire (duplicates included)
            for _ in range(len(out) + held):
                self._count("flipped")
        return out

    def release(self, cycle: int) -> list[bytes]:
        """Held frames due by ``cycle``, in the order they were held."""
        due = sorted(h for h in self.held if h[0] <= cycle)
        if due:
            self.held = [h for h in self.held if h[0] > cycle]
        return [h[2] for h in due]


class FaultyTransport(Transport):
    """A transport end with fieldbus faults: what it sends passes the ``fieldbus.down``
    faults, what it receives the ``fieldbus.up`` faults (as the master's end; wrap the
    chain's end with ``down``/``up`` swapped by passing ``role="slave"``).

    ``cycle`` returns the current fieldbus cycle (the fault windows are in cycles of 1 ms).
    :attr:`stats` counts what the caller gave and got; ``inner.stats`` what went on the
    wire; :attr:`fault_stats` what the faults did.
    """

    name = "faulty"

    def __init__(self, inner: Transport, plan: FaultPlan | Any, cycle: Callable[[], int],
                 role: str = "master") -> None:
        super().__init__(role, inner.max_frame)
        plan = parse_faults(plan)
        self.inner = inner
        self.cycle = cycle
        self.fault_stats = FaultStats()
        out_link, in_link = (("fieldbus.down", "fieldbus.up") if role == "master"
                             else ("fieldbus.up", "fieldbus.down"))
        self._out = _Direction(plan.on(out_link), out_link.split(".")[1], self.fault_stats)
        self._in = _Direction(plan.on(in_link), in_link.split(".")[1], self.fault_stats)
        self._ready: deque[bytes] = deque()

    def _send(self, frame: bytes) -> None:
        c = self.cycle()
        for f in self._out.release(c) + self._out.apply(frame, c):
            self.inner.send(f)

    def _recv(self, timeout: float | None) -> bytes | None:
        c = self.cycle()
        self._ready.extend(self._in.release(c))
        if self._ready:
            return self._ready.popleft()
        deadline = deadline_of(timeout)
        while True:
            got = self.inner.recv(remaining(deadline))
            if got is None:
                return None
            self._ready.extend(self._in.apply(got, c))
            if self._ready:
                return self._ready.popleft()
            # dropped or held: look again (frames already queued even when time is up)

    def _close(self) -> None:
        self.inner.close()
