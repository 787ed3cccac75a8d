"""The byte layout of a raw channel's frames, as its MCAP schema (encoding ``eha-hil/layout``).

A raw channel carries frames the replay needs bit for bit (register words, process
records, FPGA traces). Its schema says what the bytes of one frame are, so that the file
documents itself and ``eha-hil log export`` decodes any such channel without knowing it
by name: a JSON object

``{"encoding": <frame encoding>, "size": <bytes per frame>, "doc": <where described>,
"fields": [{"name", "offset", "type", "scale", "unit"}, ...]}``

``type`` is one of :data:`TYPES` (little endian); a field's value in its ``unit`` is the
stored integer times ``scale`` (``unit`` "" and ``scale`` 1: a code, count or flag). Viewers
that do not know the encoding list the channel as raw (``docs/framelog.md``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

SCHEMA_ENCODING = "eha-hil/layout"
TYPES: dict[str, str] = {"u8": "<u1", "i8": "<i1", "u16": "<u2", "s16": "<i2", "u32": "<u4",
                         "i32": "<i4", "u64": "<u8", "i64": "<i8"}
DOC = "docs/framelog.md"


@dataclass(frozen=True)
class LayoutField:
    name: str
    offset: int
    type: str
    scale: float = 1.0
    unit: str = ""


@dataclass(frozen=True)
class Layout:
    """The frames of one raw channel: ``size`` bytes each, ``fields`` at their offsets."""

    encoding: str
    size: int
    fields: tuple[LayoutField, ...]

    def schema(self) -> bytes:
        """The schema data (JSON, compact, keys sorted: equal layouts share one schema)."""
        return json.dumps({"encoding": self.encoding, "size": self.size, "doc": DOC,
                           "fields": [f.__dict__ for f in self.fields]},
                          sort_keys=True, separators=(",", ":")).encode()

    def dtype(self) -> np.dtype:
        """The numpy record of one frame (made once per layout: decoded often)."""
        dt = self.__dict__.get("_dtype")
        if dt is None:
            dt = np.dtype({"names": [f.name for f in self.fields],
                           "formats": [TYPES[f.type] for f in self.fields],
                           "offsets": [f.offset for f in self.fields], "itemsize": self.size})
            object.__setattr__(self, "_dtype", dt)  # a cache, not a field
        return dt

    def units(self) -> dict[str, str]:
        return {f.name: f.unit for f in self.fields if f.unit}

    def decode(self, frames: np.ndarray) -> dict[str, np.ndarray]:
        """Columns of ``frames`` ((n, width) array whose rows are ``size`` bytes): ints for
        codes, floats in the field's unit where it has a scale."""
        raw = np.ascontiguousarray(frames)
        n = raw.shape[0]
        if raw.nbytes != n * self.size:
            raise ValueError(f"{self.encoding}: frames of {raw.nbytes // max(n, 1)} bytes, "
                             f"the layout has {self.size}")
        dt = self.dtype()
        rec = raw.view(np.uint8).reshape(n, self.size).view(dt)[:, 0] if n else \
            np.zeros(0, dt)
        out = {}
        for f in self.fields:
            v = rec[f.name]
            out[f.name] = v * f.scale if f.scale != 1.0 else v.astype(np.int64)
        return out


def words(encoding: str, names: Iterable[tuple[str, str]], word_bytes: int,
          extra: Iterable[tuple[str, str]] = (), total: int | None = None) -> Layout:
    """A layout of consecutive words of ``word_bytes`` each: ``names`` (name, type) from
    offset 0 (a 16-bit register in a 32-bit word is read from its low half), then
    ``extra`` fields; ``total`` words in all (default: as many as named)."""
    fields = [LayoutField(n, i * word_bytes, t) for i, (n, t) in enumerate(names)]
    fields += [LayoutField(n, (len(fields) + i) * word_bytes, t)
               for i, (n, t) in enumerate(list(extra))]
    count = total if total is not None else len(fields)
    return Layout(encoding, count * word_bytes, tuple(fields))


def parse(schema_data: bytes) -> Layout:
    """The :class:`Layout` of a schema written by :meth:`Layout.schema`; ValueError if the
    data is not one."""
    try:
        obj = json.loads(schema_data)
        fields = tuple(LayoutField(str(f["name"]), int(f["offset"]), str(f["type"]),
                                   float(f.get("scale", 1.0)), str(f.get("unit", "")))
                       for f in obj["fields"])
        lay = Layout(str(obj["encoding"]), int(obj["size"]), fields)
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"not an {SCHEMA_ENCODING} schema ({exc})") from None
    for f in fields:
        if f.type not in TYPES or f.offset < 0 or \
                f.offset + np.dtype(TYPES[f.type]).itemsize > lay.size:
            raise ValueError(f"{SCHEMA_ENCODING} schema: field {f.name!r} does not fit")
    return lay
