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

import os
import sys
from collections.abc import Iterator, Sequence

import numpy as np

from hil.framelog.columnar import Columns, decode_channel
from hil.framelog.decoders import DecodeError
from hil.framelog.reader import FrameLogError, FrameLogReader, LogInfo
from hil.output.tables import table

_MAX_META_SHOWN = 60
#: Rows per Parquet row group / per batch of CSV text: bounds the memory of the output
#: (the decoded columns are held whole); smaller costs more calls per group and column.
_SLICE_ROWS = 1 << 17
_CSV_SLICE_ROWS = 1 << 17


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


class _Plan:
    """The decoded channels of an export and the order of their frames: ``order`` indexes
    the concatenated frames of ``chans`` in simulated-time order, ties in file order."""

    def __init__(self, log_path: str | os.PathLike[str], topics: Sequence[str] | None,
                 fields: Sequence[str] | None, info: LogInfo | None) -> None:
        reader = FrameLogReader(log_path)
        if info is None:
            info = reader.info()
        if topics:
            for t in topics:
                info.channel(t)  # FrameLogError naming the topics present
        selected = list(topics) if topics else [c.topic for c in info.channels]
        raws = reader.raw_channels(selected)
        chans: list[Columns] = []
        for c in info.channels:
            if c.topic in selected and c.topic in raws:
                try:
                    chans.append(decode_channel(c, raws.pop(c.topic)))
                except DecodeError as exc:
                    raise FrameLogError(f"{log_path}: {exc}") from None
        if fields:
            chans = [_keep_fields(c, fields) for c in chans]
            present = {k for c in chans if c.n for k in c.columns}
            missing = [f for f in fields if f not in present]
            if missing:
                raise FrameLogError(f"{log_path}: field {missing[0]!r} occurs in no frame "
                                    f"of {', '.join(selected)}")
        # columns in order of first appearance: channels by their first frame
        chans.sort(key=lambda c: (int(c.t_ns[0]), int(c.seq[0])) if c.n else (1 << 64, 0))
        names: dict[str, None] = {}
        units: dict[str, str] = {}
        floats: set[str] = set()
        for c in chans:
            for k, v in c.columns.items():
                names.setdefault(k, None)
                if k in c.units:
                    units.setdefault(k, c.units[k])
                if v.dtype.kind == "f":
                    floats.add(k)
        self.columns = list(fields) if fields else list(names)
        self.units = units
        self.floats = floats
        self.errors = any(c.errors is not None for c in chans)
        self.log_path = log_path
        # Channels with the same columns (every board's register channel, ...) form a
        # group, stored one after the other: a group's columns are single arrays, so a
        # slice of rows is filled a group at a time, not a channel at a time.
        where = {name: j for j, name in enumerate(self.columns)}
        keys: dict[tuple, list[Columns]] = {}
        for c in chans:
            keys.setdefault(tuple(sorted((where[k], v.dtype.kind) for k, v in
                                         c.columns.items() if k in where)), []).append(c)
        self.chans = [c for members in keys.values() for c in members]
        self.groups = []
        start = first = 0
        for key, members in keys.items():
            self.groups.append(_Group(key, members, start, self.columns, first))
            start += sum(c.n for c in members)
            first += len(members)
        self.rows = start
        ts = [c.t_ns for c in self.chans]
        if any(t.dtype == np.uint64 for t in ts):
            ts = [t.astype(np.uint64) for t in ts]
        self.t_ns = np.concatenate(ts) if ts else np.zeros(0, np.int64)
        self.src = np.concatenate([g.which for g in self.groups]) if self.groups \
            else np.zeros(0, np.int32)
        self.group_of = np.repeat(np.arange(len(self.groups), dtype=np.int32),
                                  [g.n for g in self.groups])
        seq = np.concatenate([c.seq for c in self.chans]) if chans else np.zeros(0, np.int64)
        row = np.concatenate([c.row for c in self.chans]) if chans else np.zeros(0, np.int64)
        self.order = np.lexsort((row, seq, self.t_ns))
        for c in chans:  # the groups hold the values now
            c.columns, c.valid, c.errors = {}, {}, None

    def parts(self, size: int) -> Iterator[tuple[np.ndarray, list[np.ndarray],
                                                  list[np.ndarray]]]:
        """Per ``size`` rows in time order: their indexes into the concatenated frames,
        and per group where its rows go in the slice and which of its rows they are."""
        for start in range(0, self.rows, size):
            idx = self.order[start:start + size]
            grp = self.group_of[idx]
            sort = np.argsort(grp, kind="stable")
            bounds = np.searchsorted(grp[sort], np.arange(len(self.groups) + 1))
            pos = [sort[bounds[i]:bounds[i + 1]] for i in range(len(self.groups))]
            yield idx, pos, [idx[p] - g.start for p, g in zip(pos, self.groups, strict=True)]

    def csv_lines(self, size: int = _CSV_SLICE_ROWS) -> Iterator[memoryview]:
        """The CSV rows, a slice at a time, as bytes. Each group's rows are built from its
        columns only (Arrow casts them to text and joins them, a run of commas standing
        for the columns it lacks), then the slice's rows are put in time order: the work
        is in proportion to the values, not to rows x columns."""
        import pyarrow as pa
        import pyarrow.compute as pc

        topics = pa.array([_csv_text(c.topic) for c in self.chans], pa.string())
        for _idx, pos, rows in self.parts(size):
            parts, places = [], []
            for g, p, r in zip(self.groups, pos, rows, strict=True):
                if len(p):
                    parts.append(self._group_lines(g, r, topics, pa, pc))
                    places.append(p)
            lines = pa.chunked_array(parts).take(pa.array(np.argsort(np.concatenate(places))))
            lines = lines.combine_chunks() if lines.num_chunks != 1 else lines.chunk(0)
            offsets = np.frombuffer(lines.buffers()[1], np.int32)
            data = lines.buffers()[2]
            yield memoryview(data)[offsets[lines.offset]:offsets[lines.offset + len(lines)]]

    def _group_lines(self, g: _Group, r: np.ndarray, topics, pa, pc):  # noqa: ANN001
        """CSV lines (with their newline) of the rows ``r`` of group ``g``."""
        width = len(self.columns)
        args: list = [_seconds_text(self.t_ns[g.start + r], pa, pc),
                      topics.take(pa.array(g.which[r]))]
        at = 0
        for j, _kind in g.key:
            name = self.columns[j]
            if j > at:
                args.append(pa.scalar("," * (j - at - 1)))
            ok = g.valid[name]
            args.append(pa.array(g.columns[name][r], mask=None if ok is None else ~ok[r]
                                 ).cast(pa.string()))
            at = j + 1
        if self.errors:
            if width > at:
                args.append(pa.scalar("," * (width - at - 1)))
            errs = [None] * len(r) if g.errors is None else \
                [None if (e := g.errors[k]) is None else _csv_text(e) for k in r.tolist()]
            args.append(pa.array(errs, pa.string()))
            tail = None
        elif width > at:  # the trailing commas and the newline in one
            args.append(pa.scalar("," * (width - at - 1) + "\n"))
            tail = ""
        else:
            tail = None
        line = pc.binary_join_element_wise(*args, ",", null_handling="replace",
                                           null_replacement="")
        return line if tail is not None else pc.binary_join_element_wise(line, "", "\n")

    def slices(self, size: int = _SLICE_ROWS) -> Iterator[tuple[np.ndarray, dict[str, object],
                                                              np.ndarray]]:
        """Per ``size`` rows in time order: their times, ``{column: (values, valid)}``
        (and ``decode_error``: a list of str/None) filled a group at a time, and their
        channel numbers."""
        by_col: dict[str, list[int]] = {}
        for i, g in enumerate(self.groups):
            for k in g.columns:
                by_col.setdefault(k, []).append(i)
        for idx, pos, rows in self.parts(size):
            m = len(idx)
            out: dict[str, object] = {}
            for name in self.columns:
                vals = np.empty(m, np.float64 if name in self.floats else np.int64)
                ok = np.zeros(m, bool)
                for i in by_col.get(name, ()):
                    if len(pos[i]):
                        g = self.groups[i]
                        vals[pos[i]] = g.columns[name][rows[i]]
                        v = g.valid[name]
                        ok[pos[i]] = True if v is None else v[rows[i]]
                out[name] = (vals, ok)
            if self.errors:
                err: list[str | None] = [None] * m
                for g, p, r in zip(self.groups, pos, rows, strict=True):
                    if g.errors is not None:
                        for k, j in zip(p.tolist(), r.tolist(), strict=True):
                            err[k] = g.errors[j]
                out["decode_error"] = err
            yield self.t_ns[idx], out, self.src[idx]

    def topics(self) -> list[str]:
        return [c.topic for c in self.chans]

    def names(self) -> list[str]:
        return [*self.columns] + (["decode_error"] if self.errors else [])


def _seconds_text(t_ns: np.ndarray, pa, pc):  # noqa: ANN001, ANN202 - pyarrow modules
    """``t_ns`` as seconds with 9 decimals ("0.000200000"), exact: the ns as the unscaled
    value of a decimal with scale 9, which Arrow prints (but below 1000 ns in scientific
    notation, "5E-9": those few are written out by hand)."""
    n = len(t_ns)
    raw = np.zeros((n, 2), np.int64)
    if t_ns.dtype == np.uint64:
        raw[:, 0] = t_ns.view(np.int64)  # the low word; high 0: values up to 2^64 - 1
    else:
        raw[:, 0] = t_ns
        raw[:, 1] = t_ns >> 63
    text = pa.Array.from_buffers(pa.decimal128(38, 9), n, [None, pa.py_buffer(raw)]
                                 ).cast(pa.string())
    small = t_ns < 1000
    if not small.any():
        return text
    fix = pa.array([f"0.{int(v):09d}" for v in t_ns[small]], pa.string())
    return pc.replace_with_mask(text, pa.array(small), fix)


class _Group:
    """Channels with the same columns, their values concatenated (channel after channel):
    ``key`` ((column position, dtype kind) pairs), ``start`` (first row in the export's
    concatenation), ``which`` (channel number per row), columns, masks, errors."""

    def __init__(self, key: tuple, members: list[Columns], start: int, names: list[str],
                 first_channel: int) -> None:
        self.key = key
        self.start = start
        self.n = sum(c.n for c in members)
        self.which = np.repeat(np.arange(first_channel, first_channel + len(members),
                                         dtype=np.int32), [c.n for c in members])
        self.columns = {names[j]: np.concatenate([c.columns[names[j]] for c in members])
                        for j, _ in key}
        self.valid: dict[str, np.ndarray | None] = {}
        for j, _ in key:
            masks = [c.valid[names[j]] for c in members]
            self.valid[names[j]] = None if all(m is None for m in masks) else np.concatenate(
                [np.ones(c.n, bool) if m is None else m for c, m in
                 zip(members, masks, strict=True)])
        self.errors = None if all(c.errors is None for c in members) else \
            [e for c in members for e in (c.errors or [None] * c.n)]


def _keep_fields(c: Columns, fields: Sequence[str]) -> Columns:
    """Only the frames of ``c`` that have one of ``fields``, and only those columns."""
    keep = np.zeros(c.n, bool)
    for f in fields:
        if f in c.columns:
            v = c.valid[f]
            keep |= True if v is None else v
    cols = {f: c.columns[f][keep] for f in fields if f in c.columns}
    valid = {f: (None if c.valid[f] is None else c.valid[f][keep]) for f in cols}
    return Columns(c.topic, c.t_ns[keep], c.seq[keep], c.row[keep], cols, valid, c.units,
                   None)


def _arrays(plan: _Plan, t_ns: np.ndarray, cols: dict[str, object], src: np.ndarray) -> list:
    """The Parquet columns of one slice."""
    import pyarrow as pa

    topic = pa.DictionaryArray.from_arrays(pa.array(src, pa.int32()),
                                           pa.array(plan.topics(), pa.string()))
    arrays = [pa.array(t_ns, pa.uint64() if t_ns.dtype == np.uint64 else pa.int64()),
              pa.array(t_ns.astype(np.float64) / 1e9, pa.float64()), topic]
    for name in plan.columns:
        vals, ok = cols[name]  # type: ignore[misc]
        arrays.append(pa.array(vals, pa.float64() if name in plan.floats else pa.int64(),
                               mask=None if ok.all() else ~ok))
    if plan.errors:
        arrays.append(pa.array(cols["decode_error"], pa.string()))
    return arrays


def export_csv(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
               topics: Sequence[str] | None = None,
               fields: Sequence[str] | None = None, info: LogInfo | None = None) -> int:
    """Write the decoded frames of ``log_path`` to the CSV ``out_path`` ("-": stdout).

    ``topics``: only these (default all); FrameLogError for a topic not in the log.
    ``fields``: only these decoded fields as columns, in this order, and only frames that
    have at least one of them (so frames that fail to decode are left out too);
    FrameLogError if a field occurs in no selected frame. A column whose field has an SI
    unit is headed ``field [unit]``. Each channel is decoded as
    :func:`hil.framelog.channel_decode.channel_decoder` says (its schema first), by
    columns (:mod:`hil.framelog.columnar`), and written with pyarrow's CSV writer in
    slices of rows. Returns the number of data rows written. A truncated log exports what
    is readable. ``info``: the log's :meth:`FrameLogReader.info` if the caller has it
    already (saves a pass over the file).
    """
    plan = _Plan(log_path, topics, fields, info)
    header = ["t_s", "topic"] + [f"{c} [{plan.units[c]}]" if c in plan.units else c
                                 for c in plan.names()]
    line = ",".join(_csv_text(h) for h in header) + "\n"
    if str(out_path) == "-":
        # stdout takes text (it may be a wrapper without a byte buffer)
        sys.stdout.write(line)
        for chunk in plan.csv_lines():
            sys.stdout.write(bytes(chunk).decode())
        return plan.rows
    with open(out_path, "wb") as out:
        out.write(line.encode())
        for chunk in plan.csv_lines():
            out.write(chunk)
    return plan.rows


def _csv_text(s: str) -> str:
    """``s`` as one CSV cell (quoted if it holds a comma, quote or line break)."""
    return f'"{s.replace(chr(34), chr(34) * 2)}"' if set(s) & set(',"\n\r') else s


def export_parquet(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
                   topics: Sequence[str] | None = None,
                   fields: Sequence[str] | None = None, info: LogInfo | None = None) -> int:
    """As :func:`export_csv`, to a Parquet file (pyarrow): columns ``t_ns`` (int64, exact),
    ``t_s`` (float64), ``topic`` (dictionary), then one per field (int64 or float64, null
    where a frame has no such field); each field's unit in its column metadata (``unit``),
    the log's path in the file metadata (``eha-hil.source``). One row group per slice of
    rows. Returns the number of rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    plan = _Plan(log_path, topics, fields, info)
    t_type = pa.uint64() if plan.t_ns.dtype == np.uint64 else pa.int64()
    fields_ = [pa.field("t_ns", t_type, metadata={"unit": "ns"}),
               pa.field("t_s", pa.float64(), metadata={"unit": "s"}),
               pa.field("topic", pa.dictionary(pa.int32(), pa.string()))]
    for c in plan.columns:
        fields_.append(pa.field(c, pa.float64() if c in plan.floats else pa.int64(),
                                metadata={"unit": plan.units[c]} if c in plan.units else None))
    if plan.errors:
        fields_.append(pa.field("decode_error", pa.string()))
    schema = pa.schema(fields_, metadata={"eha-hil.source": str(log_path)})
    with pq.ParquetWriter(out_path, schema) as w:
        for t_ns, cols, src in plan.slices():
            w.write_batch(pa.RecordBatch.from_arrays(_arrays(plan, t_ns, cols, src),
                                                     schema=schema))
        if not plan.rows:
            w.write_table(schema.empty_table())
    return plan.rows
