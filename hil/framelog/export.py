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

from hil.framelog.export_plan import Group, Plan, Replan, Window
from hil.framelog.reader import LogInfo
from hil.output.tables import table

_MAX_META_SHOWN = 60
#: Rows per Parquet row group / per batch of CSV text: bounds the memory of the output;
#: smaller costs more calls per group and column.
_SLICE_ROWS = 1 << 15
#: Rows per Parquet row group: the writer's work per column chunk is paid per group
_PARQUET_ROWS = 1 << 16


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


def _csv_lines(plan: Plan, win: Window, topics, size: int = _SLICE_ROWS  # noqa: ANN001
               ) -> Iterator[memoryview]:
    """The CSV rows of ``win``, a slice at a time, as bytes. Each group's rows are built
    from its columns only (Arrow casts them to text and joins them, a run of commas
    standing for the columns it lacks), then the slice's rows are put in time order: the
    work is in proportion to the values, not to rows x columns."""
    import pyarrow as pa

    for _idx, pos, rows in win.parts(size):
        parts, places = [], []
        for g, p, r in zip(win.groups, pos, rows, strict=True):
            if len(p):
                parts.append(_group_lines(plan, win, g, r, topics))
                places.append(p)
        lines = pa.chunked_array(parts).take(pa.array(np.argsort(np.concatenate(places))))
        lines = lines.combine_chunks() if lines.num_chunks != 1 else lines.chunk(0)
        offsets = np.frombuffer(lines.buffers()[1], np.int32)
        data = lines.buffers()[2]
        yield memoryview(data)[offsets[lines.offset]:offsets[lines.offset + len(lines)]]


def _group_lines(plan: Plan, win: Window, g: Group, r: np.ndarray, topics):  # noqa: ANN001, ANN202
    """CSV lines (with their newline) of the rows ``r`` of group ``g``."""
    import pyarrow as pa
    import pyarrow.compute as pc

    width = len(plan.columns)
    args: list = [_seconds_text(win.t_ns[g.start + r], pa, pc),
                  topics.take(pa.array(g.which[r]))]
    at = 0
    for j, _kind in g.key:
        name = plan.columns[j]
        if j > at:
            args.append(pa.scalar("," * (j - at - 1)))
        ok = g.valid[name]
        args.append(pa.array(g.columns[name][r], mask=None if ok is None else ~ok[r]
                             ).cast(pa.string()))
        at = j + 1
    if plan.errors:
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


def _parquet_batches(plan: Plan, win: Window, schema, topics,  # noqa: ANN001, ANN202
                     scratch: np.ndarray | None = None, size: int = _PARQUET_ROWS):
    """The Parquet record batches of ``win``, a slice of rows each, each to be written
    before the next is asked for. A column is built from the groups that have it, straight
    into Arrow's buffers: its values scattered into a row of ``scratch`` ((columns, size)
    int64, reused from slice to slice: fresh memory each time costs a page fault per 4
    kB), its validity a bitmap shared by the columns of the same groups."""
    import pyarrow as pa

    by_col: dict[str, list[int]] = {}
    for i, g in enumerate(win.groups):
        for k in g.columns:
            by_col.setdefault(k, []).append(i)
    if scratch is None or scratch.shape[1] < size:
        scratch = np.empty((len(plan.columns), size), np.int64)
    for idx, pos, rows in win.parts(size):
        m = len(idx)
        t_ns = win.t_ns[idx]
        arrays = [pa.array(t_ns, pa.uint64() if t_ns.dtype == np.uint64 else pa.int64()),
                  pa.array(t_ns.astype(np.float64) / 1e9, pa.float64()),
                  pa.DictionaryArray.from_arrays(pa.array(win.src[idx], pa.int32()), topics)]
        bitmaps: dict[tuple[int, ...], tuple[object, int]] = {}
        for j, name in enumerate(plan.columns):
            have = tuple(i for i in by_col.get(name, ()) if len(pos[i]))
            floating, single = name in plan.floats, name in plan.singles
            typ = _arrow_type(plan, name)
            if not have:
                arrays.append(pa.nulls(m, typ))
                continue
            # a row of the scratch buffer: the writer has encoded the last slice when
            # this one is filled; what stays under a null is never read
            vals = scratch[j].view(np.float32)[:m] if single else \
                scratch[j, :m].view(np.float64) if floating else scratch[j, :m]
            own = any(win.groups[i].valid[name] is not None for i in have)
            ok = np.zeros(m, bool) if own else None
            for i in have:
                g = win.groups[i]
                vals[pos[i]] = g.columns[name][rows[i]]
                if ok is not None:
                    v = g.valid[name]
                    ok[pos[i]] = True if v is None else v[rows[i]]
            if ok is None:
                if have not in bitmaps:
                    okg = np.zeros(m, bool)
                    for i in have:
                        okg[pos[i]] = True
                    bitmaps[have] = _bitmap(okg)
                bits, nulls = bitmaps[have]
            else:
                bits, nulls = _bitmap(ok)
            arrays.append(pa.Array.from_buffers(typ, m, [bits, pa.py_buffer(vals)], nulls))
        if plan.errors:
            err: list[str | None] = [None] * m
            for g, p, r in zip(win.groups, pos, rows, strict=True):
                if g.errors is not None:
                    for k, j in zip(p.tolist(), r.tolist(), strict=True):
                        err[k] = g.errors[j]
            arrays.append(pa.array(err, pa.string()))
        yield pa.RecordBatch.from_arrays(arrays, schema=schema)


def _arrow_type(plan: Plan, column: str):  # noqa: ANN202 - a pyarrow type
    """The Parquet type of an export column: float32, float64 or int64 (:class:`Plan`)."""
    import pyarrow as pa

    return pa.float32() if column in plan.singles else \
        pa.float64() if column in plan.floats else pa.int64()


def _bitmap(ok: np.ndarray) -> tuple[object, int]:
    """Arrow validity bitmap of ``ok`` (None if all valid) and the null count."""
    import pyarrow as pa

    nulls = len(ok) - int(np.count_nonzero(ok))
    return (None if not nulls else pa.py_buffer(np.packbits(ok, bitorder="little"))), nulls


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



def export_csv(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
               topics: Sequence[str] | None = None,
               fields: Sequence[str] | None = None, info: LogInfo | None = None,
               summary: list[LogInfo] | None = None) -> int:
    """Write the decoded frames of ``log_path`` to the CSV ``out_path`` ("-": stdout).

    ``topics``: only these (default all); FrameLogError for a topic not in the log.
    ``fields``: only these decoded fields as columns, in this order, and only frames that
    have at least one of them (so frames that fail to decode are left out too);
    FrameLogError if a field occurs in no selected frame. A column whose field has an SI
    unit is headed ``field [unit]``. Each channel is decoded as
    :func:`hil.framelog.channel_decode.channel_decoder` says (its schema first), by
    columns (:mod:`hil.framelog.columnar`), a batch of frames at a time, and the rows go
    out in time order a window at a time (:mod:`hil.framelog.export_plan`: memory bounded
    whatever the log's length). Returns the number of data rows written. A truncated log
    exports what is readable. ``info``: the log's :meth:`FrameLogReader.info` if the
    caller has it; else the planning pass gives it, appended to ``summary`` if given.
    """
    import pyarrow as pa

    to_stdout = str(out_path) == "-"
    plan = Plan(log_path, topics, fields, info, thorough=to_stdout)  # stdout cannot rewind
    if summary is not None:
        summary.append(plan.info)
    while True:
        header = ["t_s", "topic"] + [f"{c} [{plan.units[c]}]" if c in plan.units else c
                                     for c in plan.names()]
        line = ",".join(_csv_text(h) for h in header) + "\n"
        names = pa.array([_csv_text(t) for t in plan.topics], pa.string())
        rows = 0
        try:
            if to_stdout:
                # stdout takes text (it may be a wrapper without a byte buffer)
                raw = getattr(sys.stdout, "buffer", None)
                sys.stdout.write(line)
                if raw is not None:
                    sys.stdout.flush()
                for win in plan.windows():
                    for chunk in _csv_lines(plan, win, names):
                        if raw is not None:
                            raw.write(chunk)
                        else:
                            sys.stdout.write(bytes(chunk).decode())
                    rows += win.rows
                return rows
            with open(out_path, "wb") as out:
                out.write(line.encode())
                for win in plan.windows():
                    for chunk in _csv_lines(plan, win, names):
                        out.write(chunk)
                    rows += win.rows
            return rows
        except Replan:
            plan = Plan(log_path, topics, fields, info, thorough=True)


def _csv_text(s: str) -> str:
    """``s`` as one CSV cell (quoted if it holds a comma, quote or line break)."""
    return f'"{s.replace(chr(34), chr(34) * 2)}"' if set(s) & set(',"\n\r') else s


def export_parquet(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
                   topics: Sequence[str] | None = None,
                   fields: Sequence[str] | None = None, info: LogInfo | None = None,
                   summary: list[LogInfo] | None = None) -> int:
    """As :func:`export_csv`, to a Parquet file (pyarrow): columns ``t_ns`` (int64, exact),
    ``t_s`` (float64), ``topic`` (dictionary), then one per field (int64, float64, or
    float32 where every channel with the field stores it as float32; null where a frame
    has no such field); each field's unit in its column metadata (``unit``),
    the log's path in the file metadata (``eha-hil.source``). One row group per slice of
    rows; Snappy-compressed pages, dictionary encoding for ``topic`` only (the fields' values
    rarely repeat enough to pay for it), statistics for the time and topic columns only
    (what a reader filters row groups by). Returns the number of rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    plan = Plan(log_path, topics, fields, info)
    if summary is not None:
        summary.append(plan.info)
    while True:
        t_type = pa.uint64() if plan.big else pa.int64()
        fields_ = [pa.field("t_ns", t_type, metadata={"unit": "ns"}),
                   pa.field("t_s", pa.float64(), metadata={"unit": "s"}),
                   pa.field("topic", pa.dictionary(pa.int32(), pa.string()))]
        for c in plan.columns:
            fields_.append(pa.field(c, _arrow_type(plan, c),
                                    metadata={"unit": plan.units[c]} if c in plan.units
                                    else None))
        if plan.errors:
            fields_.append(pa.field("decode_error", pa.string()))
        schema = pa.schema(fields_, metadata={"eha-hil.source": str(log_path)})
        names = pa.array(plan.topics, pa.string())
        rows = 0
        try:
            scratch = np.empty((len(plan.columns), _PARQUET_ROWS), np.int64)
            with pq.ParquetWriter(out_path, schema, compression="snappy",
                                  use_dictionary=["topic"],
                                  write_statistics=["t_ns", "t_s", "topic"]) as w:
                for win in plan.windows():
                    for batch in _parquet_batches(plan, win, schema, names, scratch):
                        w.write_batch(batch)
                    rows += win.rows
                if not rows:
                    w.write_table(schema.empty_table())
            return rows
        except Replan:
            plan = Plan(log_path, topics, fields, info, thorough=True)
