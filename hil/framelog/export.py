"""Summaries and CSV export of frame logs (``eha-hil log info`` / ``eha-hil log export``).

CSV layout (one file): one row per frame in simulated-time order, columns ``t_s`` (seconds
of simulated time, 9 decimals, i.e. exact ns), ``topic``, then the decoded fields of the
selected topics in order of first appearance (a field a frame does not have is empty).
Frames whose encoding has no decoder get a ``length`` field (bytes); a frame that does not
decode leaves its fields empty and says why in a last ``decode_error`` column (present only
if some frame failed). One file rather than a file per topic because it keeps the
interleaving of the links visible (which frame came before which) and plots with one
``read_csv``; select topics or fields to keep it narrow.
"""

from __future__ import annotations

import csv
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from hil.framelog.channel_decode import channel_decoder
from hil.framelog.decoders import DecodeError
from hil.framelog.reader import FrameLogError, FrameLogReader, LogInfo
from hil.output.tables import table

_MAX_META_SHOWN = 60


def _fmt_s(t_ns: int | None) -> str:
    return "-" if t_ns is None else f"{t_ns / 1e9:.6f}"


def _fmt_size(n: int) -> str:
    if n < 1000:
        return f"{n} B"
    for unit in ("kB", "MB", "GB"):
        n /= 1000  # type: ignore[assignment]
        if n < 1000 or unit == "GB":
            break
    return f"{n:.1f} {unit}"


def _fmt_meta(value: str) -> str:
    if "\n" in value or len(value) > _MAX_META_SHOWN:
        return f"<{len(value)} characters, {value.count(chr(10)) + 1} lines>"
    return value


def summary_text(info: LogInfo) -> str:
    """The text of ``eha-hil log info``: file, state, time range, metadata, one row per
    channel (times in seconds of simulated time)."""
    lines = [
        f"log: {info.path} ({_fmt_size(info.size)}), profile {info.profile or '-'}, "
        f"level {info.level or '-'}, written by {info.library or '-'}",
    ]
    if info.complete:
        lines.append("state: complete")
    else:
        lines.append(f"state: TRUNCATED ({info.stop_reason}); readable up to "
                     f"t = {_fmt_s(info.readable_until_ns)} s")
    lines.append(f"time: {_fmt_s(info.start_ns)} .. {_fmt_s(info.end_ns)} s simulated; "
                 f"{info.message_count} messages, {info.frame_count} frames, "
                 f"{info.chunk_count} chunks")
    for name, meta in info.metadata.items():
        items = ", ".join(f"{k}={_fmt_meta(v)}" for k, v in meta.items())
        lines.append(f"metadata {name}: {items or '-'}")
    rows = [(c.topic, c.encoding, c.framing if c.dtype is None else
             f"block {c.width} x {c.dtype}", c.message_count, c.frame_count,
             _fmt_s(c.first_ns), _fmt_s(c.last_ns)) for c in info.channels]
    if rows:
        lines.append("")
        lines.append(table(("topic", "encoding", "framing", "messages", "frames",
                            "first [s]", "last [s]"), rows))
    else:
        lines.append("no channels")
    return "\n".join(lines)


def _cell(v: object) -> object:
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    return v


@dataclass
class _Table:
    """Decoded frames in simulated-time order: ``rows`` (t_ns, topic, values), the field
    columns in order, the unit of each column that has one, whether a frame failed."""

    rows: list[tuple[int, str, dict[str, object]]]
    columns: list[str]
    units: dict[str, str]
    errors: bool


def _decode_all(log_path: str | os.PathLike[str], topics: Sequence[str] | None,
                fields: Sequence[str] | None, info: LogInfo | None) -> _Table:
    reader = FrameLogReader(log_path)
    if info is None:
        info = reader.info()
    if topics:
        for t in topics:
            info.channel(t)  # FrameLogError naming the topics present
    selected = list(topics) if topics else [c.topic for c in info.channels]
    decoders = {}
    for c in info.channels:
        if c.topic in selected:
            try:
                decoders[c.topic] = channel_decoder(c)
            except DecodeError as exc:
                raise FrameLogError(f"{log_path}: {exc}") from None
    rows: list[tuple[int, str, dict[str, object]]] = []
    columns: dict[str, None] = {}  # insertion-ordered set
    units: dict[str, str] = {}
    errors = False
    for topic, t_ns, data in reader.frames(selected):
        dec = decoders[topic]
        values: dict[str, object]
        try:
            values = dict(dec.decode(data))
        except DecodeError as exc:
            values = {"decode_error": str(exc)}
        if fields:
            if not any(f in values for f in fields):
                continue
        else:
            for k in values:
                if k != "decode_error" and k not in columns:
                    columns[k] = None
                    if k in dec.units:
                        units.setdefault(k, dec.units[k])
        errors = errors or "decode_error" in values
        rows.append((t_ns, topic, values))
    if fields:
        present = {k for _, _, v in rows for k in v}
        missing = [f for f in fields if f not in present]
        if missing:
            raise FrameLogError(f"{log_path}: field {missing[0]!r} occurs in no frame of "
                                f"{', '.join(selected)}")
        cols = list(fields)
        for f in fields:
            for d in decoders.values():
                if f in d.units:
                    units.setdefault(f, d.units[f])
    else:
        cols = list(columns)
    return _Table(rows, cols, units, errors)


def export_csv(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
               topics: Sequence[str] | None = None,
               fields: Sequence[str] | None = None, info: LogInfo | None = None) -> int:
    """Write the decoded frames of ``log_path`` to the CSV ``out_path`` ("-": stdout).

    ``topics``: only these (default all); FrameLogError for a topic not in the log.
    ``fields``: only these decoded fields as columns, in this order, and only frames that
    have at least one of them (so frames that fail to decode are left out too);
    FrameLogError if a field occurs in no selected frame. A column whose field has an SI
    unit is headed ``field [unit]``. Each channel is decoded as
    :func:`hil.framelog.channel_decode.channel_decoder` says (its schema first).
    Returns the number of data rows written. A truncated log exports what is readable.
    ``info``: the log's :meth:`FrameLogReader.info` if the caller has it already (saves a
    pass over the file).
    """
    tab = _decode_all(log_path, topics, fields, info)
    names = [*tab.columns] + (["decode_error"] if tab.errors else [])
    header = ["t_s", "topic"] + [f"{c} [{tab.units[c]}]" if c in tab.units else c
                                 for c in names]
    out = sys.stdout if str(out_path) == "-" else open(out_path, "w", newline="")  # noqa: SIM115
    try:
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        for t_ns, topic, values in tab.rows:
            w.writerow([f"{t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d}", topic,
                        *(_cell(values.get(c, "")) for c in names)])
    finally:
        if out is not sys.stdout:
            out.close()
    return len(tab.rows)


def export_parquet(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
                   topics: Sequence[str] | None = None,
                   fields: Sequence[str] | None = None, info: LogInfo | None = None) -> int:
    """As :func:`export_csv`, to a Parquet file (pyarrow): columns ``t_ns`` (int64, exact),
    ``t_s`` (float64), ``topic``, then one per field (int64 or float64, null where a frame
    has no such field); each field's unit in its column metadata (``unit``), the log's
    path in the file metadata (``eha-hil.source``). Returns the number of rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    tab = _decode_all(log_path, topics, fields, info)
    t_ns = [r[0] for r in tab.rows]
    arrays = [pa.array(t_ns, pa.int64()), pa.array([t / 1e9 for t in t_ns], pa.float64()),
              pa.array([r[1] for r in tab.rows], pa.string()).dictionary_encode()]
    schema_fields = [pa.field("t_ns", pa.int64(), metadata={"unit": "ns"}),
                     pa.field("t_s", pa.float64(), metadata={"unit": "s"}),
                     pa.field("topic", arrays[2].type)]
    names = [*tab.columns] + (["decode_error"] if tab.errors else [])
    for c in names:
        col = [r[2].get(c) for r in tab.rows]
        if c == "decode_error":
            arr = pa.array(col, pa.string())
        else:
            kinds = {type(v) for v in col if v is not None}
            arr = pa.array(col, pa.int64() if kinds <= {int} and kinds else pa.float64())
        arrays.append(arr)
        meta = {"unit": tab.units[c]} if c in tab.units else None
        schema_fields.append(pa.field(c, arr.type, metadata=meta))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(
        schema_fields, metadata={"eha-hil.source": str(log_path)}))
    pq.write_table(table, out_path)
    return len(tab.rows)
