"""The time series behind a scenario's metrics, out to CSV, Parquet or MCAP (``run --series``).

A scenario's :attr:`~hil.scenarios.ScenarioResult.series` holds what its metrics were
computed from, in whatever shape suits it: arrays, dicts of arrays, analysis results
(dataclasses such as a Bode result or a T-N curve), lists of such records. This module
flattens it into **tables**: every 1-D numeric array is a column named by its path
(``bode.freq_hz``; a complex frequency response becomes ``<name>.gain_db`` and
``<name>.phase_deg``), a list of records one column per numeric field; columns of one
parent with one length form a table. Numbers that are not arrays (constants such as a
step's target) go to the file's metadata, as do the metrics.

* CSV: ``# key: value`` lines (scenario, title, metrics, constants), then one header row
  ``table,<column [unit]>...`` and the tables' rows one after another (a column a table
  does not have is empty): one ``read_csv(comment="#")``.
* Parquet: the same table, units in the column metadata, the rest in the file metadata.
* MCAP: one protobuf channel per table (``/series/<table>``, one message per row, log time
  the table's time column in ns when it has one, else the row number), metrics and
  constants in a Metadata record; Foxglove plots it.
* Live (``run NAME --foxglove``): the same channels on a Foxglove WebSocket server, sent
  when a client has subscribed (:func:`publish_live`).

Units come from the names' suffixes where they are unambiguous (``_s``, ``_hz``, ``_db``,
``_deg``, ``_n``, ``_a``, ``_w``, ``_pa``, ``_mpa``, ``_m``, ``_m_s``, ``_mm_s``,
``_rad_s``; ``t`` alone is seconds), as the project names its arrays; a short name such as
``t_c`` (time, current-based run) or ``f_c`` states none, and gets none.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SUFFIX_UNITS = (("_mm_s", "mm/s"), ("_m_s", "m/s"), ("_rad_s", "rad/s"), ("_hz", "Hz"),
                ("_db", "dB"), ("_deg", "deg"), ("_mpa", "MPa"), ("_pa", "Pa"), ("_n", "N"),
                ("_a", "A"), ("_w", "W"), ("_m", "m"), ("_s", "s"))
FORMATS = (".csv", ".parquet", ".mcap")


@dataclass
class Table:
    name: str
    columns: dict[str, np.ndarray]

    @property
    def rows(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0


def unit_of(name: str) -> str:
    """The unit a column's name states by its suffix ("" if none)."""
    leaf = name.rsplit(".", 1)[-1].lower()
    if leaf in ("t", "time"):
        return "s"
    for suffix, unit in SUFFIX_UNITS:
        if leaf.endswith(suffix):
            return unit
    return ""


def _numeric_1d(v: object) -> np.ndarray | None:
    if isinstance(v, np.ndarray):
        a = v
    elif isinstance(v, list | tuple) and v and all(
            isinstance(x, int | float | np.number) and not isinstance(x, bool) for x in v):
        a = np.asarray(v)
    else:
        return None
    if a.ndim != 1 or a.dtype.kind not in "iufcb" or not len(a):
        return None
    return a


def _walk(obj: object, path: str, cols: dict[str, np.ndarray], scalars: dict[str, float]
          ) -> None:
    arr = _numeric_1d(obj)
    if arr is not None:
        if arr.dtype.kind == "c":
            cols[f"{path}.gain_db"] = 20.0 * np.log10(np.maximum(np.abs(arr), 1e-300))
            cols[f"{path}.phase_deg"] = np.degrees(np.unwrap(np.angle(arr)))
        else:
            cols[path] = arr.astype(np.float64)
        return
    if isinstance(obj, bool | int | float | np.number) and not isinstance(obj, complex):
        scalars[path] = float(obj)
        return
    pre = f"{path}." if path else ""
    if isinstance(obj, dict):
        for k, v in obj.items():
            _walk(v, f"{pre}{k}", cols, scalars)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            _walk(getattr(obj, f.name), f"{pre}{f.name}", cols, scalars)
    elif isinstance(obj, list | tuple) and obj:
        first = obj[0]
        if dataclasses.is_dataclass(first) and all(type(x) is type(first) for x in obj):
            for f in dataclasses.fields(first):  # a list of records: a column per field
                vals = [getattr(x, f.name) for x in obj]
                if all(isinstance(v, int | float | np.number) for v in vals):
                    cols[f"{pre}{f.name}"] = np.asarray(vals, dtype=np.float64)
        elif isinstance(first, tuple) and first and isinstance(first[0], str):
            for item in obj:  # (name, data, ...) entries
                _walk(list(item[1:]) if len(item) > 2 else item[1], f"{pre}{item[0]}", cols,
                      scalars)
        else:
            for i, v in enumerate(obj):
                _walk(v, f"{pre}{i}", cols, scalars)


def tables(series: dict, name: str) -> tuple[list[Table], dict[str, float]]:
    """The tables and the constants of a scenario's ``series`` (see the module doc)."""
    cols: dict[str, np.ndarray] = {}
    scalars: dict[str, float] = {}
    _walk(series, "", cols, scalars)
    groups: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for path, a in cols.items():
        # one table per top-level entry (a Bode result: its frequencies and both responses)
        parent = path.partition(".")[0] if "." in path else ""
        groups.setdefault((parent, len(a)), {})[path] = a
    out = []
    parents = [p for p, _ in groups]
    for (parent, _), c in groups.items():
        tname = parent or name
        if parents.count(parent) > 1:  # several lengths: name each by its first column
            tname = f"{tname}_{next(iter(c)).rsplit('.', 1)[-1]}"
        out.append(Table(tname, c))
    return out, scalars


def _metrics(res) -> dict[str, str]:  # noqa: ANN001 - ScenarioResult
    return {f"metric {m.name}": f"{m.value:.9g} {m.unit}".strip() for m in res.metrics}


def _meta(res, scalars: dict[str, float]) -> dict[str, str]:  # noqa: ANN001
    return {"scenario": res.name, "title": res.title, **_metrics(res),
            **{k: f"{v:.12g}" for k, v in scalars.items()}}


def _time_ns(t: Table) -> np.ndarray:
    """Log times of a table's rows: its first time column (``t``, ``t_s``, ``t_...``) that
    does not decrease, counted from its first value, in ns; else the row number."""
    for key, a in t.columns.items():
        leaf = key.rsplit(".", 1)[-1]
        if (leaf in ("t", "time") or leaf.startswith("t_")) and a.size and \
                np.all(np.isfinite(a)) and np.all(np.diff(a) >= 0):
            return np.round((a - a[0]) * 1e9).astype(np.int64)
    return np.arange(t.rows, dtype=np.int64)


def _field_name(path: str) -> str:
    s = re.sub(r"\W", "_", path)
    return s if s[:1].isalpha() else f"f_{s}"


def write_series(res, path: str | Path) -> int:  # noqa: ANN001 - ScenarioResult
    """Write ``res.series`` to ``path`` (.csv, .parquet or .mcap); the number of rows.
    ValueError (one line) for another suffix or a scenario without series."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"--series {path}: give a .csv, .parquet or .mcap file")
    tabs, scalars = tables(res.series, res.name)
    if not tabs:
        raise ValueError(f"{res.name}: the scenario has no time series to write")
    meta = _meta(res, scalars)
    if suffix == ".mcap":
        return _write_mcap(tabs, meta, p)
    names: dict[str, None] = {}
    for t in tabs:
        names.update(dict.fromkeys(t.columns))
    cols = list(names)
    if suffix == ".csv":
        lines = [f"# {k}: {v}" for k, v in meta.items()]
        lines.append(",".join(["table"] + [f"{c} [{unit_of(c)}]" if unit_of(c) else c
                                           for c in cols]))
        for t in tabs:
            data = [t.columns.get(c) for c in cols]
            for i in range(t.rows):
                lines.append(",".join([t.name] + ["" if d is None else f"{d[i]:.12g}"
                                                  for d in data]))
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    else:
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrays = [pa.array([t.name for t in tabs for _ in range(t.rows)]).dictionary_encode()]
        fields = [pa.field("table", arrays[0].type)]
        for c in cols:
            vals = np.concatenate([t.columns[c] if c in t.columns else
                                   np.full(t.rows, np.nan) for t in tabs])
            mask = np.concatenate([np.full(t.rows, c not in t.columns) for t in tabs])
            arrays.append(pa.array(vals, pa.float64(), mask=mask))
            fields.append(pa.field(c, pa.float64(),
                                   metadata={"unit": unit_of(c)} if unit_of(c) else None))
        pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(
            fields, metadata={f"eha-hil.{k}": v for k, v in meta.items()})), p)
    return sum(t.rows for t in tabs)


@dataclass
class SeriesChannel:
    """One table as a protobuf channel: topic, message type, log times (ns), messages."""

    topic: str
    message: object  # hil.framelog.protobuf.MessageType
    t_ns: np.ndarray
    payloads: list[bytes]


def channels(tabs: list[Table]) -> list[SeriesChannel]:
    """The tables as protobuf channels ``/series/<table>`` (one message per row)."""
    from hil.framelog.protobuf import Field, MessageType

    out = []
    used: set[str] = set()
    for t in tabs:
        fields, seen = [], set()
        for c in t.columns:
            f = _field_name(c)
            while f in seen:
                f += "_"
            seen.add(f)
            fields.append(Field(f, "double", unit_of(c), c))
        mname = _field_name(t.name).replace("_", " ").title().replace(" ", "")
        while mname in used:
            mname += "X"
        used.add(mname)
        msg = MessageType(f"eha_hil.series.{mname}", fields)
        cols = {f.name: a for f, a in zip(fields, t.columns.values(), strict=True)}
        out.append(SeriesChannel(f"/series/{t.name}", msg, _time_ns(t),
                                 msg.encode(cols, t.rows)))
    return out


def _write_mcap(tabs: list[Table], meta: dict[str, str], p: Path) -> int:
    from hil.framelog.writer import FrameLogWriter

    with FrameLogWriter(p, level="bus", metadata={"content": "scenario series"}) as w:
        w.add_metadata("eha-hil.series", meta)
        for c in channels(tabs):
            w.write_messages(w.add_protobuf_channel(c.topic, c.message), c.t_ns, c.payloads)
    return sum(t.rows for t in tabs)


def publish_live(res, live, wait_s: float | None = None, linger_s: float = 2.0,  # noqa: ANN001
                 poll_s: float = 0.1) -> bool:
    """Offer a scenario's series on the live view ``live`` (:class:`hil.framelog.live.FoxgloveLive`)
    and send them once a client has subscribed to one of them (waiting ``wait_s`` seconds,
    None: until interrupted), then keep serving ``linger_s``. A live view only delivers
    what is sent after a client subscribes, hence the wait. True if they were sent."""
    import time

    tabs, _ = tables(res.series, res.name)
    chans = channels(tabs)
    handles = [live.add(c.topic, c.message) for c in chans]
    deadline = None if wait_s is None else time.monotonic() + wait_s
    while not any(live.subscribed(c.topic) for c in chans):
        if deadline is not None and time.monotonic() > deadline:
            return False
        time.sleep(poll_s)
    time.sleep(min(0.5, linger_s))  # let the client subscribe to the rest too
    for h, c in zip(handles, chans, strict=True):
        live.log(h, c.t_ns, c.payloads)
    time.sleep(linger_s)
    return True


def describe(tabs: list[Table]) -> str:
    """One line per table: name, rows, columns."""
    return "\n".join(f"{t.name}: {t.rows} rows, {', '.join(t.columns)}" for t in tabs)


__all__ = ["FORMATS", "SeriesChannel", "Table", "channels", "describe", "publish_live", "tables",
           "unit_of", "write_series"]
