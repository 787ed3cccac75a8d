"""A channel's frames decoded into columns at once (numpy), for ``eha-hil log export``.

The reader hands over each channel whole (:meth:`FrameLogReader.raw_channels`); a channel
is then decoded by columns, not frame by frame:

* block channels (register snapshots, traces, records): the stacked (n, width) frames go
  through the encoding's batch decoder or the byte layout's numpy dtype in one call;
* protobuf channels whose message holds fixed-width scalars only (every decoded-signal
  channel of ``bus run``): the messages, all of one length, are one numpy structured array
  whose field keys are checked against the schema for every row, then read as columns;
  anything else (a foreign protobuf message with varints, strings, nesting) goes through
  the stock protobuf runtime message by message;
* the rest (EtherCAT frames of varying length, JSON): the channel's per-frame decoder.

Each column is an int64, float64 or float32 array with a validity mask (a frame may lack
a field: an EtherCAT frame with fewer datagrams, a frame that failed to decode). float32
stays float32 (a protobuf ``float`` field, a layout's ``f32``): the export writes it as
such (Parquet ``float``, CSV the shortest text that reads back to the same float32).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from google.protobuf import descriptor_pb2

from hil.framelog.channel_decode import channel_decoder, channel_layout
from hil.framelog.decoders import DecodeError, decode_block, has_decoder
from hil.framelog.rawpb import _varint
from hil.framelog.reader import ChannelInfo, RawChannel

_FD = descriptor_pb2.FieldDescriptorProto
#: protobuf scalar type -> (wire type, numpy dtype of the value) for fixed-width scalars
_FIXED = {_FD.TYPE_DOUBLE: (1, "<f8"), _FD.TYPE_FLOAT: (5, "<f4"),
          _FD.TYPE_FIXED64: (1, "<u8"), _FD.TYPE_SFIXED64: (1, "<i8"),
          _FD.TYPE_FIXED32: (5, "<u4"), _FD.TYPE_SFIXED32: (5, "<i4"),
          _FD.TYPE_BOOL: (0, "u1")}


@dataclass
class Columns:
    """One channel decoded: frame times, tie-break keys, columns and their masks (None:
    every frame has the field), units, per-frame decode errors (None: none failed).
    ``fixed``: decoded by a whole-array path (a block decoder, a byte layout, fixed-width
    protobuf), so any other part of the channel decodes into the same columns."""

    topic: str
    t_ns: np.ndarray
    seq: np.ndarray
    row: np.ndarray
    columns: dict[str, np.ndarray]
    valid: dict[str, np.ndarray | None]
    units: dict[str, str] = field(default_factory=dict)
    errors: list[str | None] | None = None
    fixed: bool = False

    @property
    def n(self) -> int:
        return int(self.t_ns.shape[0])


class _Fixed(NamedTuple):
    """A protobuf message of fixed-width scalars only, as a numpy record: its dtype, per
    field (name, is bool), and where the record holds its key bytes and their values."""

    dtype: np.dtype
    fields: list[tuple[str, bool]]
    key_at: np.ndarray
    key_bytes: np.ndarray


def _fixed_record(ch: ChannelInfo) -> _Fixed | None:
    """The record of a protobuf message whose fields are all fixed-width scalars written
    in field-number order (how our signal channels write them); None for any other."""
    return _fixed_record_of(ch.schema_name, ch.schema_data)


@functools.lru_cache(maxsize=256)
def _fixed_record_of(schema_name: str, schema_data: bytes) -> _Fixed | None:
    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    except Exception:  # noqa: BLE001 - a foreign schema: the runtime path reports it
        return None
    for f in fds.file:
        for m in f.message_type:
            if (f"{f.package}.{m.name}" if f.package else m.name) != schema_name:
                continue
            layout, fields, key = [], [], b""
            at: list[int] = []
            for fd in sorted(m.field, key=lambda x: x.number):
                kind = _FIXED.get(fd.type)
                if kind is None or fd.label == _FD.LABEL_REPEATED:
                    return None
                k = _varint(fd.number << 3 | kind[0])
                here = sum(np.dtype(x[1]).itemsize * (x[2][0] if len(x) > 2 else 1)
                           for x in layout)
                at += range(here, here + len(k))
                key += k
                layout += [(f"_k{fd.number}", np.uint8, (len(k),)), (fd.name, kind[1])]
                fields.append((fd.name, fd.type == _FD.TYPE_BOOL))
            return _Fixed(np.dtype(layout), fields, np.asarray(at, np.intp),
                          np.frombuffer(key, np.uint8))
    return None


def _protobuf_fast(ch: ChannelInfo, payloads: list[memoryview]) -> dict[str, np.ndarray] | None:
    rec = _fixed_record(ch)
    if rec is None or not payloads:
        return None
    size = rec.dtype.itemsize
    if any(len(p) != size for p in payloads):
        return None
    buf = b"".join(payloads)
    raw = np.frombuffer(buf, np.uint8).reshape(len(payloads), size)
    if not (raw[:, rec.key_at] == rec.key_bytes).all():
        return None  # fields in another order or form: the runtime reads it
    a = np.frombuffer(buf, rec.dtype)
    out = {}
    for name, is_bool in rec.fields:
        v = a[name]
        out[name] = (v != 0).astype(np.int64) if is_bool else v.astype(_wide(v.dtype))
    return out


def _wide(dt: np.dtype) -> type:
    """The column type of values of type ``dt``: float32 and float64 as they are, other
    floats as float64, integers as int64."""
    if dt.kind == "f":
        return np.float32 if dt == np.float32 else np.float64
    return np.int64


def _from_dicts(rows: list[dict[str, object]]) -> tuple[dict[str, np.ndarray],
                                                       dict[str, np.ndarray | None]]:
    names: dict[str, None] = {}
    for r in rows:
        names.update(dict.fromkeys(r))
    cols, valid = {}, {}
    n = len(rows)
    for c in names:
        vals = [r.get(c) for r in rows]
        mask = np.fromiter((v is not None for v in vals), bool, n)
        ints = all(isinstance(v, int) for v in vals if v is not None)
        fill = 0 if ints else np.nan
        arr = np.array([fill if v is None else v for v in vals],
                       np.int64 if ints else np.float64)
        cols[c], valid[c] = arr, None if mask.all() else mask
    return cols, valid


def _dense(cols: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                 dict[str, np.ndarray | None]]:
    out = {}
    for k, v in cols.items():
        v = np.asarray(v)
        out[k] = v.astype(_wide(v.dtype), copy=False)
    return out, dict.fromkeys(out)


class ChannelDecoding:
    """How one channel's frames become columns, set up once (its decoder, its byte
    layout, its protobuf record) for any number of batches of its frames: calling it
    with a :class:`RawChannel` gives their :class:`Columns`. DecodeError if the channel's
    schema cannot be used at all; a frame that does not decode is an error row."""

    def __init__(self, ch: ChannelInfo) -> None:
        self.ch = ch
        self.dec = channel_decoder(ch)
        self.registered = has_decoder(ch.encoding)
        self.layout = None if self.registered else channel_layout(ch)

    def __call__(self, raw: RawChannel) -> Columns:
        ch, dec = self.ch, self.dec
        res = Columns(ch.topic, raw.t_ns, raw.seq, raw.row, {}, {}, dict(dec.units))
        n = len(raw.t_ns)
        if raw.frames is not None:
            cols = decode_block(ch.encoding, raw.frames) if self.registered else None
            lay = self.layout
            if cols is None and lay is not None and raw.frames.nbytes == n * lay.size:
                cols = lay.decode(raw.frames)
            if cols is not None:
                res.columns, res.valid = _dense(cols)
                res.fixed = True
                return res
            payloads = [r.tobytes() for r in raw.frames]
        else:
            payloads = raw.payloads or []
            if dec.how == "protobuf":
                cols = _protobuf_fast(ch, payloads)
                if cols is not None:
                    res.columns, res.valid = _dense(cols)
                    res.fixed = True
                    return res
        rows: list[dict[str, object]] = []
        errors: list[str | None] = []
        for p in payloads:
            try:
                rows.append(dict(dec.decode(bytes(p))))
                errors.append(None)
            except DecodeError as exc:
                rows.append({})
                errors.append(str(exc))
        res.columns, res.valid = _from_dicts(rows)
        if any(e is not None for e in errors):
            res.errors = errors
        return res


def decode_channel(ch: ChannelInfo, raw: RawChannel) -> Columns:
    """The columns of one channel's frames (:class:`Columns`, :class:`ChannelDecoding`)."""
    return ChannelDecoding(ch)(raw)
