"""Protobuf messages of fixed layout, declared once as fields, encoded a block at a time.

A decoded-signal channel carries one protobuf message per sample, so that Foxglove Studio,
PlotJuggler and the MCAP libraries decode it with their stock protobuf support. Our
messages hold only fixed-width scalars (``double``, ``float``, ``fixed32``, ``fixed64``,
``sfixed64``, ``bool``), each field written every time, in field-number order. The wire
bytes of such a message have the same layout in every sample: per field a constant key
(field number and wire type, a varint), then the value in 1, 4 or 8 bytes, little endian.
So a whole block of samples is one numpy structured array whose ``tobytes()`` is the
concatenated messages: no per-sample Python, which is what keeps logging at 5 kHz per
actuator cheap (``hil.framelog.signal_bench`` measures it against JSON). Any protobuf
parser reads these bytes (writing a field although it holds its default value is legal
protobuf; a parser keeps the last occurrence); the schema is a ``FileDescriptorSet`` built
with the protobuf runtime's own descriptor classes, so no ``protoc`` step and no generated
code.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from google.protobuf import descriptor_pb2

#: Scalar kind -> (wire type, numpy dtype of the value, descriptor field type, JSON type).
KINDS: dict[str, tuple[int, str, int, str]] = {
    "double": (1, "<f8", descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE, "number"),
    "float": (5, "<f4", descriptor_pb2.FieldDescriptorProto.TYPE_FLOAT, "number"),
    "fixed64": (1, "<u8", descriptor_pb2.FieldDescriptorProto.TYPE_FIXED64, "integer"),
    "sfixed64": (1, "<i8", descriptor_pb2.FieldDescriptorProto.TYPE_SFIXED64, "integer"),
    "fixed32": (5, "<u4", descriptor_pb2.FieldDescriptorProto.TYPE_FIXED32, "integer"),
    "bool": (0, "u1", descriptor_pb2.FieldDescriptorProto.TYPE_BOOL, "boolean"),
}
#: Schema encoding and message encoding of these channels in MCAP.
SCHEMA_ENCODING = "protobuf"
MESSAGE_ENCODING = "protobuf"


@dataclass(frozen=True)
class Field:
    """One scalar of a message: ``unit`` is the SI unit ("" for counts, codes and flags)."""

    name: str
    kind: str
    unit: str = ""
    doc: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name!r}: kind {self.kind!r} is not one of "
                             f"{', '.join(KINDS)}")
        if not self.name.isidentifier():
            raise ValueError(f"field name {self.name!r} is not an identifier")


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


class MessageType:
    """A protobuf message type ``package.Name`` of fixed-width scalar fields (numbered 1..n
    in the given order)."""

    def __init__(self, full_name: str, fields: Sequence[Field], doc: str = "") -> None:
        package, _, name = full_name.rpartition(".")
        if not name.isidentifier() or not all(p.isidentifier() for p in package.split(".")):
            raise ValueError(f"message name {full_name!r} is not package.Name")
        names = [f.name for f in fields]
        if len(set(names)) != len(names):
            raise ValueError(f"{full_name}: duplicate field names")
        self.full_name = full_name
        self.package = package
        self.name = name
        self.fields = tuple(fields)
        self.doc = doc
        layout = []
        self._keys: list[np.ndarray] = []
        for number, f in enumerate(self.fields, start=1):
            wire, value_dtype, _, _ = KINDS[f.kind]
            key = np.frombuffer(_varint(number << 3 | wire), np.uint8)
            self._keys.append(key)
            layout.append((f"k{number}", np.uint8, (len(key),)))
            layout.append((f.name, value_dtype))
        #: One packed sample: key, value, key, value, ... (no padding).
        self.record = np.dtype(layout)

    @property
    def size(self) -> int:
        """Bytes of one encoded message (every sample has this length)."""
        return self.record.itemsize

    @cached_property
    def schema(self) -> bytes:
        """The serialized ``FileDescriptorSet`` (MCAP schema data of encoding ``protobuf``)."""
        fd = descriptor_pb2.FileDescriptorProto(
            name=f"{self.full_name.replace('.', '/')}.proto", package=self.package,
            syntax="proto3")
        msg = fd.message_type.add(name=self.name)
        for number, f in enumerate(self.fields, start=1):
            msg.field.add(name=f.name, number=number, type=KINDS[f.kind][2],
                          label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL)
        return descriptor_pb2.FileDescriptorSet(file=[fd]).SerializeToString()

    def units(self) -> dict[str, str]:
        """Field -> SI unit, for the fields that have one (channel metadata, export)."""
        return {f.name: f.unit for f in self.fields if f.unit}

    def encode(self, columns: Mapping[str, np.ndarray], n: int) -> list[bytes]:
        """``n`` messages from ``columns`` (field -> (n,) array, or a scalar for all);
        a missing field is written as 0. Floats are stored as they come (NaN included),
        a ``float`` field's value rounded to the nearest float32 (numpy's cast)."""
        buf = self.encode_array(columns, n).tobytes()
        s = self.size
        return [buf[i:i + s] for i in range(0, n * s, s)]

    def encode_array(self, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """:meth:`encode` as one (n, :attr:`size`) uint8 array, row i the i-th message."""
        out = np.empty((n, self.size), np.uint8)
        self.encode_into(columns, out)
        return out

    def encode_into(self, columns: Mapping[str, np.ndarray], out: np.ndarray) -> None:
        """:meth:`encode_array` written into ``out`` ((n, :attr:`size`) uint8, rows of any
        stride, e.g. the messages' places in their MCAP records)."""
        if out.ndim != 2 or out.shape[1] != self.size or out.strides[1] != 1:
            raise ValueError(f"{self.full_name}: need out (n, {self.size}) with contiguous "
                             f"rows, got {out.shape}")
        out[:] = self._blank  # every key, every value 0: one byte copy, not a field loop
        rec = out.view(self.record)[:, 0]
        for f in self.fields:
            v = columns.get(f.name)
            if v is not None:
                rec[f.name] = np.asarray(v) != 0 if f.kind == "bool" else v

    @cached_property
    def _blank(self) -> np.ndarray:
        """The bytes of one message with its keys and all values 0."""
        rec = np.zeros(1, self.record)
        for number, key in enumerate(self._keys, 1):
            rec[f"k{number}"] = key
        return rec.view(np.uint8)

    def decode(self, data: bytes | memoryview) -> dict[str, float | int]:
        """One message of exactly our layout (the fast path; any protobuf parser reads it
        too). ValueError if the length or a key differs."""
        if len(data) != self.size:
            raise ValueError(f"{self.full_name}: message of {len(data)} bytes, "
                             f"expected {self.size}")
        rec = np.frombuffer(data, self.record, 1)[0]
        for number, key in enumerate(self._keys, 1):
            if not np.array_equal(rec[f"k{number}"], key):
                raise ValueError(f"{self.full_name}: field {number} key differs")
        return {f.name: rec[f.name].item() for f in self.fields}

    # -- the JSON alternative (measured against protobuf by hil.framelog.signal_bench) ---
    @cached_property
    def json_schema(self) -> bytes:
        """A ``jsonschema`` of the same fields (one type per field, as Foxglove needs)."""
        return json.dumps({"type": "object", "title": self.full_name, "properties": {
            f.name: {"type": KINDS[f.kind][3],
                     **({"description": f.unit} if f.unit else {})}
            for f in self.fields}}, sort_keys=True).encode()

    def encode_json(self, columns: Mapping[str, np.ndarray], n: int) -> list[bytes]:
        """``n`` JSON messages of the same values (NaN as null)."""
        cols = {f.name: np.broadcast_to(np.asarray(columns.get(f.name, 0)), (n,)).tolist()
                for f in self.fields}
        out = []
        for i in range(n):
            row = {}
            for f in self.fields:
                v = cols[f.name][i]
                if f.kind == "bool":
                    v = bool(v)
                elif isinstance(v, float) and v != v:
                    v = None
                row[f.name] = v
            out.append(json.dumps(row, separators=(",", ":")).encode())
        return out


def markdown_table(message: MessageType) -> str:
    """The message's fields as a Markdown table (``docs/framelog.md`` carries this output)."""
    rows = ["| # | field | type | unit | meaning |", "|---|---|---|---|---|"]
    for number, f in enumerate(message.fields, 1):
        rows.append(f"| {number} | `{f.name}` | {f.kind} | {f.unit or '-'} | {f.doc} |")
    return "\n".join(rows)
