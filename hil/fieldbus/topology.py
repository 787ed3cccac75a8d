"""The daisy chain of joint driver boxes, from a TOML file (shipped: hydra_full, bench_one_box).

A topology lists boxes in chain order; each box is an MCU board with 1..5 slots (driver
boards): actuators, foot sensors or the IMU. Errors name the file and the box.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from hil.fieldbus.pdo import SLOT_KINDS, slot_sizes

MAX_SLOTS = 5  # an MCU board serves up to five driver boards (thesis 6.3.1)


class TopologyError(Exception):
    """A topology file that cannot be used; the message names file and place."""


@dataclass(frozen=True)
class Slot:
    name: str
    kind: str

    @property
    def sizes(self) -> tuple[int, int]:
        """(output bytes, input bytes) in the process image."""
        return slot_sizes(self.kind)


@dataclass(frozen=True)
class Box:
    id: int
    slots: tuple[Slot, ...]

    @property
    def actuators(self) -> tuple[int, ...]:
        """Slot indices of the actuators."""
        return tuple(i for i, s in enumerate(self.slots) if s.kind == "actuator")

    @property
    def out_bytes(self) -> int:
        return sum(s.sizes[0] for s in self.slots)

    @property
    def in_bytes(self) -> int:
        return sum(s.sizes[1] for s in self.slots)


@dataclass(frozen=True)
class Topology:
    name: str
    description: str
    boxes: tuple[Box, ...]
    source: str

    @property
    def n_actuators(self) -> int:
        return sum(len(b.actuators) for b in self.boxes)

    def actuator_names(self) -> list[str]:
        return [b.slots[i].name for b in self.boxes for i in b.actuators]


def topology_names() -> list[str]:
    """Shipped topologies."""
    root = resources.files("hil.fieldbus") / "topologies"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_topology(src: str | Path) -> Topology:
    """A shipped topology by name, or a TOML file by path."""
    src = str(src)
    if src in topology_names():
        text = (resources.files("hil.fieldbus") / "topologies" / f"{src}.toml").read_text()
        where = f"topology {src}"
    else:
        path = Path(src)
        if path.is_dir():
            raise TopologyError(f"topology {src}: is a directory, not a TOML file")
        if not path.is_file():
            raise TopologyError(f"topology {src}: no such file and not a shipped topology "
                                f"({', '.join(topology_names())})")
        text = path.read_text(encoding="utf-8", errors="replace")
        where = str(path)
    return parse_topology(text, where)


def parse_topology(text: str, where: str) -> Topology:
    """Check and build a topology from TOML text; ``where`` names it in errors."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TopologyError(f"{where}: not valid TOML: {exc}") from None
    boxes_raw = data.get("box")
    if not isinstance(boxes_raw, list) or not boxes_raw:
        raise TopologyError(f"{where}: needs at least one [[box]] table")
    unknown = set(data) - {"name", "description", "box"}
    if unknown:
        raise TopologyError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
    boxes: list[Box] = []
    names: set[str] = set()
    for n, raw in enumerate(boxes_raw):
        at = f"{where}: box #{n}"
        if not isinstance(raw, dict):
            raise TopologyError(f"{at}: expected a table")
        extra = set(raw) - {"id", "slots"}
        if extra:
            raise TopologyError(f"{at}: unknown key(s) {', '.join(sorted(extra))}")
        box_id = raw.get("id", n)
        if not isinstance(box_id, int) or isinstance(box_id, bool) or box_id != n:
            raise TopologyError(f"{at}: id must be {n} (boxes are listed in chain order)")
        slots_raw = raw.get("slots")
        if not isinstance(slots_raw, list) or not 1 <= len(slots_raw) <= MAX_SLOTS:
            raise TopologyError(f"{at}: slots must list 1..{MAX_SLOTS} driver boards")
        slots = []
        for k, s in enumerate(slots_raw):
            if isinstance(s, str):
                name, kind = s, "actuator"
            elif isinstance(s, dict) and set(s) <= {"name", "kind"} and "name" in s:
                name, kind = s["name"], s.get("kind", "actuator")
            else:
                raise TopologyError(f"{at} slot {k}: expected a name or "
                                    "{ name = ..., kind = ... }")
            if not isinstance(name, str) or not name:
                raise TopologyError(f"{at} slot {k}: name must be a non-empty string")
            if kind not in SLOT_KINDS:
                raise TopologyError(f"{at} slot {k} ({name}): kind {kind!r} is not one of "
                                    f"{', '.join(SLOT_KINDS)}")
            if name in names:
                raise TopologyError(f"{at} slot {k}: name {name!r} used twice")
            names.add(name)
            slots.append(Slot(name, kind))
        boxes.append(Box(n, tuple(slots)))
    return Topology(str(data.get("name", where)), str(data.get("description", "")),
                    tuple(boxes), where)
