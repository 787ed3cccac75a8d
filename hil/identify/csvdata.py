"""Measured-data CSV for identification (the format of DESIGN.md), read and validated.

::

    # load: fixed_piston
    # sample_rate_hz: 5000
    t,iq,theta_m,p_pump_a,p_pump_b,p_cyl_a,p_cyl_b,p_acc,x_piston,f_strain,temp_c
    0.0,0.0,0.0,500000,500000,...

SI units: ``t`` s, ``iq`` A (q-axis current as logged), ``theta_m`` rad (motor angle,
unwrapped), pressures Pa gauge, ``x_piston`` m, ``f_strain`` N, ``temp_c`` degC. Only ``t``,
``iq`` and the outputs the load case needs are required; every column present is used.
Unknown columns are kept out of the fit and listed in :attr:`MeasuredData.ignored`.

Files as people have them are read too (``docs/identify.md``, section Input):

* a UTF-8 byte-order mark; leading index columns as ``pandas.DataFrame.to_csv`` writes
  them (unnamed, ``Unnamed: 0``, ``index``, ``level_0``): dropped, with a note;
* ``time`` and ``t_s`` as names of the time column (exactly one time column);
* units other than SI: a header line ``# units: p=bar, iq=mA, t=ms`` (``p``: every pressure
  column) or in the header row, ``p_pump_a[bar]`` / ``p_pump_a (bar)``; converted on read
  (:data:`UNITS`);
* ``load`` and ``sample_rate_hz`` from the caller (``--load``, ``--sample-rate``) when the
  file has no such header line; a header line that says otherwise is an error. Without
  either the sample rate is the inverse of the median time step (a note says so);
* gaps: a row with an empty or NaN cell in a used column, or a time step of more than 1.5
  sample periods, splits the record; the longest stretch without a gap is used if it has
  at least :data:`MIN_ROWS` samples (a note names the gaps and the lines used), otherwise
  the file is refused. A column that is empty in every row is left out (a note).

What was done to the file is in :attr:`MeasuredData.notes` (the report shows it).

Every mistake raises :class:`CsvError`, whose ``str`` is one line naming the file, the line
and the column, so the command line can print it and exit with code 2.
"""

from __future__ import annotations

import csv
import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Load cases of the identification CSV and the plant's load kind for each.
LOAD_CASES: dict[str, str] = {
    "fixed_piston": "fixed",
    "free_piston": "free",
    "conrod_fixed": "conrod",
}

#: Known data columns, in the order of DESIGN.md.
KNOWN_COLUMNS: tuple[str, ...] = (
    "t", "iq", "theta_m", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc",
    "x_piston", "f_strain", "temp_c",
)

#: Names of the time column (exactly one of them per file); read as ``t``.
TIME_ALIASES: tuple[str, ...] = ("t", "time", "t_s")

#: The pressure columns (``p`` in a ``# units:`` line means all of them).
PRESSURE_COLUMNS: tuple[str, ...] = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc")

#: Output groups that are enough for each load case (any one group suffices).
REQUIRED_OUTPUTS: dict[str, tuple[tuple[str, ...], ...]] = {
    "fixed_piston": (("p_pump_a", "p_pump_b"), ("p_cyl_a", "p_cyl_b"), ("f_strain",)),
    "free_piston": (("x_piston",), ("theta_m",)),
    "conrod_fixed": (("p_pump_a", "p_pump_b"), ("p_cyl_a", "p_cyl_b"), ("f_strain",)),
}

#: Quantity of each known column.
QUANTITY: dict[str, str] = {
    "t": "time", "iq": "current", "theta_m": "angle", "x_piston": "length",
    "f_strain": "force", "temp_c": "temperature", **dict.fromkeys(PRESSURE_COLUMNS, "pressure"),
}

_PSI_PA = 6894.757293168361
#: Units accepted per quantity: name -> (scale, offset), SI value = scale * value + offset.
#: The first unit of each quantity is the SI one the columns are stored in.
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "time": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "\u00b5s": (1e-6, 0.0),
             "\u03bcs": (1e-6, 0.0)},
    "current": {"A": (1.0, 0.0), "mA": (1e-3, 0.0)},
    "angle": {"rad": (1.0, 0.0), "deg": (math.pi / 180.0, 0.0), "rev": (2.0 * math.pi, 0.0)},
    "pressure": {"Pa": (1.0, 0.0), "kPa": (1e3, 0.0), "bar": (1e5, 0.0), "mbar": (1e2, 0.0),
                 "MPa": (1e6, 0.0), "psi": (_PSI_PA, 0.0)},
    "length": {"m": (1.0, 0.0), "cm": (1e-2, 0.0), "mm": (1e-3, 0.0), "um": (1e-6, 0.0),
               "\u00b5m": (1e-6, 0.0), "\u03bcm": (1e-6, 0.0)},
    "force": {"N": (1.0, 0.0), "kN": (1e3, 0.0)},
    "temperature": {"degC": (1.0, 0.0), "\u00b0C": (1.0, 0.0), "K": (1.0, -273.15),
                    "degF": (5.0 / 9.0, -160.0 / 9.0), "\u00b0F": (5.0 / 9.0, -160.0 / 9.0)},
}

#: Fewest samples of a record (or of the stretch used when the record has gaps).
MIN_ROWS = 10
#: A time step of more than this many sample periods is a gap (the record is split there).
GAP_PERIODS = 1.5
#: Cells read as missing (besides an empty cell and anything ``float`` reads as NaN).
NA_TOKENS = frozenset({"na", "n/a", "#n/a", "null", "none", "nan", "-nan", "+nan"})
#: Leading header cells taken for pandas index columns: empty, ``Unnamed: N``, ``index``,
#: ``level_0`` (what ``to_csv`` writes for an unnamed index, or for one read back and
#: written again).
_INDEX_NAME = re.compile(r"^(|unnamed: ?\d+|index|level_\d+)$", re.IGNORECASE)
_UNIT_IN_NAME = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))$")
_MAX_GAPS_SHOWN = 5


class CsvError(Exception):
    """A malformed measured-data file; ``str(err)`` is one line: file, line, column, why."""

    def __init__(self, path: str | Path, line: int | None, column: str | None, why: str):
        self.path = str(path)
        self.line = line
        self.column = column
        self.why = why
        where = self.path
        if line is not None:
            where += f":{line}"
        if column is not None:
            where += f": column '{column}'"
        super().__init__(f"{where}: {why}")


@dataclass
class MeasuredData:
    """One identification record: header values, time base and the data columns (SI).

    ``notes``: what reading did to the file (index column dropped, units converted, sample
    rate inferred, split at gaps), one sentence each, for the report."""

    path: str
    load: str
    sample_rate_hz: float
    t: np.ndarray
    columns: dict[str, np.ndarray]
    header: dict[str, str] = field(default_factory=dict)
    ignored: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: why the file ends early (its last line cut), None if whole (hil.cli.cutfiles)
    cut: str | None = None

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.sample_rate_hz

    def has(self, name: str) -> bool:
        """True when the column is present."""
        return name in self.columns

    def col(self, name: str) -> np.ndarray:
        """A data column by name (KeyError when absent)."""
        return self.columns[name]

    def slice(self, start: int, stop: int) -> MeasuredData:
        """The samples ``start:stop`` as a new record (same header)."""
        cols = {k: v[start:stop] for k, v in self.columns.items()}
        return MeasuredData(self.path, self.load, self.sample_rate_hz, self.t[start:stop],
                            cols, dict(self.header), list(self.ignored), list(self.notes))


def _header_value(path: Path, lineno: int, key: str, raw: str) -> str:
    value = raw.strip()
    if not value:
        raise CsvError(path, lineno, None, f"header '{key}' has no value")
    return value


def _split(line: str) -> list[str]:
    """The cells of one CSV line (quotes as the csv module reads them)."""
    if '"' not in line:
        return line.split(",")
    return next(csv.reader([line]))


def _cell(path: Path, line: int, column: str, text: str) -> float:
    """One cell that ``float`` refused: NaN for an empty or NA cell, else CsvError."""
    cell = text.strip()
    if not cell or cell.lower() in NA_TOKENS:
        return math.nan
    try:
        return float(cell)
    except ValueError:
        raise CsvError(path, line, column, f"'{cell}' is not a number") from None


def _unit(path: Path, line: int, column: str, unit: str) -> tuple[float, float]:
    """(scale, offset) of ``unit`` for ``column``; CsvError naming both if it does not fit."""
    qty = QUANTITY[column]
    table = UNITS[qty]
    if unit in table:
        return table[unit]
    other = next((q for q, u in UNITS.items() if unit in u), None)
    why = f"is a {other} unit" if other else "is not a known unit"
    raise CsvError(path, line, column, f"unit '{unit}' {why}; {qty} units: "
                   f"{', '.join(u for u in table if u.isascii())}")


def _units_line(path: Path, line: int, text: str, present: set[str]) -> dict[str, str]:
    """Column -> unit of a ``# units:`` line (``p`` for every pressure column; a column's
    own entry beats ``p``). CsvError for a malformed item, an unknown column or unit."""
    group: str | None = None
    own: dict[str, str] = {}
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise CsvError(path, line, None, f"units: '{item}' is not COLUMN=UNIT "
                           "(e.g. '# units: p=bar, iq=mA')")
        key, unit = (s.strip() for s in item.split("=", 1))
        if key in TIME_ALIASES:
            key = "t"
        if key != "p" and key not in QUANTITY:
            raise CsvError(path, line, key, "units: unknown column (known: p, "
                           f"{', '.join(KNOWN_COLUMNS)}, time, t_s)")
        if not unit:
            raise CsvError(path, line, key, "units: no unit given")
        if (key == "p" and group is not None) or key in own:
            raise CsvError(path, line, key, "units: given twice")
        _unit(path, line, PRESSURE_COLUMNS[0] if key == "p" else key, unit)
        if key == "p":
            group = unit
        else:
            own[key] = unit
    out = {c: group for c in PRESSURE_COLUMNS if group is not None and c in present}
    out.update({c: u for c, u in own.items() if c in present})
    return out


def _lines_text(a: int, b: int) -> str:
    return f"line {a}" if a == b else f"lines {a}-{b}"


def read_measured(path: str | Path, load: str | None = None,
                  sample_rate_hz: float | None = None, max_rows: int | None = None,
                  progress: Callable[[str], None] | None = None) -> MeasuredData:
    """Read and validate a measured-data CSV (see the module docstring).

    ``load`` and ``sample_rate_hz`` (the command line's ``--load``, ``--sample-rate``) stand
    in for the header lines; given both ways they must agree.

    Raises :class:`CsvError` for a missing file, a missing or unknown ``load``, a
    non-positive sample rate, a missing required column, two time columns, an unknown unit
    or column in the units, a row of the wrong length, a non-numeric or infinite cell, a
    time column that does not increase, a time step that disagrees with the sample rate by
    more than 1 % (median) or is under half a period (jitter), or a record whose longest
    stretch without a gap is shorter than :data:`MIN_ROWS`.
    """
    path = Path(path)
    try:
        # a byte-order mark is dropped; the file is read as a stream (chunks of rows), so a
        # long record never sits in memory as text
        fh = open(path, encoding="utf-8-sig")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise CsvError(path, None, None, "no such file") from None
    except OSError as exc:
        raise CsvError(path, None, None, f"cannot read: {exc}") from None
    try:
        with fh:
            return _read_open(path, fh, load, sample_rate_hz, max_rows, progress)
    except UnicodeDecodeError:
        line, byte = _first_undecodable(path)
        raise CsvError(path, line, None, f"not UTF-8 text (byte 0x{byte:02x}): save the "
                       "record as UTF-8 (or ASCII) CSV") from None


def _first_undecodable(path: Path) -> tuple[int | None, int]:
    """(line number from 1, the byte) of the first byte of ``path`` that UTF-8 cannot
    decode: the streamed read's error knows only its place in a chunk. Read again line by
    line, and only on that error."""
    with open(path, "rb") as fh:
        for number, raw in enumerate(fh, start=1):
            try:
                raw.decode("utf-8-sig" if number == 1 else "utf-8")
            except UnicodeDecodeError as exc:
                return number, raw[exc.start]
    return None, 0  # (the file changed since: say so without a line)


def _read_open(path: Path, fh, load: str | None, sample_rate_hz: float | None,  # noqa: ANN001
               max_rows: int | None, progress: Callable[[str], None] | None
               ) -> MeasuredData:
    header, header_at, names, header_line = _preamble(path, fh)
    notes: list[str] = []
    load = _load_case(path, header, header_at, load)
    fs, fs_source = _sample_rate(path, header, header_at, sample_rate_hz)
    cols = _header_row(path, names, header_line, load, notes)
    convert = _units(path, header, header_at, header_line, cols, notes)
    seen, groups = cols.seen, cols.groups

    # --- data rows ----------------------------------------------------------------------
    used = [(j, c) for j, c in enumerate(cols.canon) if c is not None]
    used_names = [c for _, c in used]
    idx = [j for j, _ in used]
    rows = _DataRows(path, fh, header_line, names, idx, max_rows, progress)
    arr, row_lines = rows.arr, rows.lines.tolist()  # line numbers as ints, for messages
    n_rows = len(arr)
    notes += rows.notes
    if len(arr) < MIN_ROWS:
        raise CsvError(path, header_line, None,
                       f"only {len(arr)} data rows (need >= {MIN_ROWS})")
    inf = np.argwhere(np.isinf(arr))
    if inf.size:
        r, k = (int(x) for x in inf[0])
        cell = _split(_line_at(path, int(row_lines[r])).strip())[idx[k]].strip()
        raise CsvError(path, int(row_lines[r]), names[idx[k]], f"'{cell}' is not finite")
    for col, (scale, offset) in convert.items():
        k = used_names.index(col)
        arr[:, k] = arr[:, k] * scale + offset

    # --- columns empty in every row are left out ------------------------------------------
    missing = np.isnan(arr)
    empty = [c for k, c in enumerate(used_names) if missing[:, k].all()]
    if "t" in empty:
        raise CsvError(path, header_line, seen["t"], "no value in any row")
    if empty:
        if "iq" in empty:
            raise CsvError(path, header_line, seen["iq"], "no value in any row")
        left = [c for c in used_names if c not in empty]
        if not any(all(c in left for c in g) for g in groups):
            first = next(c for g in groups for c in g if c in empty)
            raise CsvError(path, header_line, seen[first], f"no value in any row (load {load} "
                           f"needs {' or '.join('+'.join(g) for g in groups)})")
        notes.append("left out, empty in every row: " + ", ".join(seen[c] for c in empty))
        keep = [k for k, c in enumerate(used_names) if c not in empty]
        arr, missing = arr[:, keep], missing[:, keep]
        used_names = left
    ti = used_names.index("t")

    fs, sel = _time_base(path, arr[:, ti], missing, used_names, row_lines, seen, fs,
                         fs_source, n_rows, notes)
    if sel is not None:
        arr = arr[sel]
    columns = {c: arr[:, k].copy() for k, c in enumerate(used_names) if c != "t"}
    return MeasuredData(str(path), load, fs, arr[:, ti].copy(), columns, header,
                        cols.ignored, notes, rows.cut)


def _preamble(path: Path, fh) -> tuple[dict[str, str], dict[str, int], list[str], int]:  # noqa: ANN001
    """The '# key: value' header lines (value, line of each) and the header row (its names,
    its line), read up to the header row."""
    header: dict[str, str] = {}
    header_at: dict[str, int] = {}
    lineno = 0
    for lineno, line in enumerate(fh, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:]
            if ":" in body:
                key, raw = body.split(":", 1)
                k = key.strip().lower()
                value = _header_value(path, lineno, key.strip(), raw)
                if k in ("load", "sample_rate_hz", "units") and k in header \
                        and header[k] != value:
                    raise CsvError(path, lineno, None, f"header '{k}' given twice, differently "
                                   f"(line {header_at[k]}: '{header[k]}')")
                header.setdefault(k, value)
                header_at.setdefault(k, lineno)
            continue
        return header, header_at, [c.strip() for c in _split(stripped)], lineno
    raise CsvError(path, lineno or None, None, "no header row (expected t,iq,...)")


def _load_case(path: Path, header: dict[str, str], header_at: dict[str, int],
               load: str | None) -> str:
    """The load case: header line or the caller's --load (both: they must agree)."""
    if "load" in header:
        if header["load"] not in LOAD_CASES:
            raise CsvError(path, header_at["load"], None, f"unknown load '{header['load']}' "
                           f"(expected one of {', '.join(LOAD_CASES)})")
        if load is not None and load != header["load"]:
            raise CsvError(path, header_at["load"], None, f"'# load: {header['load']}' "
                           f"disagrees with --load {load}")
        return header["load"]
    if load is None:
        raise CsvError(path, 1, None, "missing header line '# load: ...' "
                       f"(one of {', '.join(LOAD_CASES)}), or pass --load")
    if load not in LOAD_CASES:
        raise CsvError(path, None, None, f"--load {load}: unknown load (expected one of "
                       f"{', '.join(LOAD_CASES)})")
    return load


def _sample_rate(path: Path, header: dict[str, str], header_at: dict[str, int],
                 sample_rate_hz: float | None) -> tuple[float | None, str]:
    """The sample rate (Hz) and where it came from: header line, the caller's
    --sample-rate, else None (inferred from the time column in :func:`_time_base`)."""
    if "sample_rate_hz" in header:
        line_of = header_at["sample_rate_hz"]
        try:
            fs = float(header["sample_rate_hz"])
        except ValueError:
            raise CsvError(path, line_of, None, f"sample_rate_hz '{header['sample_rate_hz']}' "
                           "is not a number") from None
        if not math.isfinite(fs) or fs <= 0:
            raise CsvError(path, line_of, None, f"sample_rate_hz must be > 0, got {fs}")
        if sample_rate_hz is not None and abs(sample_rate_hz - fs) > 1e-9 * fs:
            raise CsvError(path, line_of, None, f"'# sample_rate_hz: {header['sample_rate_hz']}'"
                           f" disagrees with --sample-rate {sample_rate_hz:g}")
        return fs, "sample_rate_hz"
    if sample_rate_hz is not None:
        if not math.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
            raise CsvError(path, None, None, f"--sample-rate must be > 0, got {sample_rate_hz}")
        return float(sample_rate_hz), "--sample-rate"
    return None, "sample_rate_hz"


@dataclass
class _HeaderRow:
    """What the header row says: the known column each position is read as (None: not
    read), units given in the names, read-as name -> name as written, the columns not read,
    the time column's alias, and the load's groups of output columns."""

    canon: list[str | None]
    unit_in_name: dict[str, str]
    seen: dict[str, str]
    ignored: list[str]
    time_alias: str
    groups: tuple[tuple[str, ...], ...]


def _header_row(path: Path, names: list[str], header_line: int, load: str,
                notes: list[str]) -> _HeaderRow:
    """The header row: index column, time aliases, units in the names; the required
    columns present."""
    canon: list[str | None] = []
    unit_in_name: dict[str, str] = {}
    seen: dict[str, str] = {}
    ignored: list[str] = []
    raw_seen: set[str] = set()
    time_alias = "t"
    leading = True
    for j, name in enumerate(names):
        if leading and _INDEX_NAME.match(name) and j < len(names) - 1:
            canon.append(None)
            shown = f"'{name}'" if name else "with an empty name"
            notes.append(f"column {j + 1} {shown} taken for an index column (as pandas "
                         "writes it) and dropped")
            continue
        leading = False
        if not name:
            raise CsvError(path, header_line, None, "empty column name in the header row")
        if name in raw_seen:
            raise CsvError(path, header_line, name, "column appears twice")
        raw_seen.add(name)
        base, unit = name, None
        m = _UNIT_IN_NAME.match(name)
        if m:
            cand = m.group("name").strip()
            if cand in QUANTITY or cand in TIME_ALIASES:
                base, unit = cand, (m.group("u1") if m.group("u1") is not None
                                    else m.group("u2")).strip()
        key = "t" if base in TIME_ALIASES else base
        if key not in QUANTITY:
            canon.append(None)
            ignored.append(name)
            continue
        if key in seen:
            if key == "t":
                raise CsvError(path, header_line, name, f"a second time column (besides "
                               f"'{seen[key]}'; use one of {', '.join(TIME_ALIASES)})")
            raise CsvError(path, header_line, name, f"column appears twice (also '{seen[key]}')")
        seen[key] = name
        if key == "t":
            time_alias = base
        canon.append(key)
        if unit is not None:
            if not unit:
                raise CsvError(path, header_line, name, "empty unit in the column name")
            _unit(path, header_line, key, unit)
            unit_in_name[key] = unit
    for req in ("t", "iq"):
        if req not in seen:
            raise CsvError(path, header_line, req, "required column missing" + (
                f" (one of {', '.join(TIME_ALIASES)})" if req == "t" else ""))
    groups = REQUIRED_OUTPUTS[load]
    if not any(all(c in seen for c in g) for g in groups):
        need = " or ".join("+".join(g) for g in groups)
        first_missing = next(c for c in groups[0] if c not in seen)
        raise CsvError(path, header_line, first_missing,
                       f"required column missing: load {load} needs {need}")
    return _HeaderRow(canon, unit_in_name, seen, ignored, time_alias, groups)


def _units(path: Path, header: dict[str, str], header_at: dict[str, int], header_line: int,
           cols: _HeaderRow, notes: list[str]) -> dict[str, tuple[float, float]]:
    """Units from the '# units:' line and the names (they must agree): the (scale, offset)
    to SI of each column not already in SI."""
    seen, unit_in_name = cols.seen, cols.unit_in_name
    units = dict(unit_in_name)
    if "units" in header:
        line_of = header_at["units"]
        for col, unit in _units_line(path, line_of, header["units"], set(seen)).items():
            if col in unit_in_name and unit_in_name[col] != unit:
                raise CsvError(path, line_of, seen[col], f"unit '{unit}' disagrees with "
                               f"'{unit_in_name[col]}' in the header row")
            units[col] = unit
    if cols.time_alias == "t_s" and units.get("t", "s") != "s":
        raise CsvError(path, header_line, seen["t"], f"is in seconds by its name, not "
                       f"'{units['t']}' (call the column t or time)")
    convert: dict[str, tuple[float, float]] = {}
    for col, unit in units.items():
        scale_offset = UNITS[QUANTITY[col]][unit]
        if scale_offset != (1.0, 0.0):
            convert[col] = scale_offset
    if convert:
        notes.append("converted to SI: " + ", ".join(
            f"{seen[c]} from {units[c]}" for c in KNOWN_COLUMNS if c in convert))
    if seen["t"] != "t":
        notes.append(f"time column '{seen['t']}' read as t")
    return convert


def _time_base(path: Path, t_all: np.ndarray, missing: np.ndarray, used_names: list[str],
               row_lines: list[int], seen: dict[str, str], fs: float | None, fs_source: str,
               n_rows: int, notes: list[str]) -> tuple[float, np.ndarray | None]:
    """The time base and the gaps: the sample rate (checked, or inferred from the median
    step) and the rows of the longest stretch without gaps (None: no gap, every row)."""
    tcol = seen["t"]
    hole = missing.any(axis=1)
    good = np.flatnonzero(~hole)
    if good.size >= 2:
        dtg = np.diff(t_all[good])
        bad = np.flatnonzero(dtg <= 0)
        if bad.size:
            a, b = good[bad[0]], good[bad[0] + 1]
            raise CsvError(path, row_lines[b], tcol, "time does not increase "
                           f"({float(t_all[b])!r} after {float(t_all[a])!r})")
        adjacent = np.diff(good) == 1
        steps = dtg[adjacent] if adjacent.any() else dtg
        step = float(np.median(steps))
        if fs is None:
            fs = float(f"{1.0 / step:.6g}")
            notes.append(f"sample rate {fs:g} Hz inferred from the median time step "
                         f"{step:.6g} s (no '# sample_rate_hz:' line, no --sample-rate)")
        elif abs(step * fs - 1.0) > 0.01:
            raise CsvError(path, row_lines[good[1]], tcol, f"time step {step:.6g} s disagrees "
                           f"with {fs_source} {fs:g}")
        ratio = dtg * fs
        short = np.flatnonzero(ratio < 0.5)
        if short.size:
            k = int(short[0])
            raise CsvError(path, row_lines[good[k + 1]], tcol,
                           f"jitter in time: step {dtg[k]:.6g} s, expected {1 / fs:.6g} s")
        jump = ratio > GAP_PERIODS
    else:
        dtg = ratio = np.zeros(0)
        jump = np.zeros(0, dtype=bool)
        adjacent = np.zeros(0, dtype=bool)
        if fs is None:
            fs = 1.0  # no segment will be long enough: refused below
    gaps: list[tuple[int, str]] = []  # (first line, description)
    hk = np.flatnonzero(hole)
    if hk.size:
        starts = hk[np.r_[True, np.diff(hk) > 1]]
        ends = hk[np.r_[np.diff(hk) > 1, True]]
        for a, b in zip(starts, ends, strict=True):
            first = used_names[int(np.flatnonzero(missing[a])[0])]
            gaps.append((row_lines[a], f"{_lines_text(row_lines[a], row_lines[b])} "
                         f"(empty or NaN cell, column '{seen[first]}')"))
    for k in np.flatnonzero(jump & adjacent):
        b = int(good[k + 1])
        gaps.append((row_lines[b], f"line {row_lines[b]} ({tcol} jumps {dtg[k]:.6g} s = "
                     f"{ratio[k]:.3g} sample periods)"))
    gaps.sort()
    if not gaps:
        return fs, None
    # stretches of good rows without a hole or a jump inside
    cut = np.r_[False, jump | ~adjacent] if good.size else np.zeros(0, dtype=bool)
    seg_id = np.cumsum(cut)
    counts = np.bincount(seg_id) if good.size else np.zeros(1, dtype=int)
    best = int(np.argmax(counts))
    sel = good[seg_id == best] if good.size else good
    shown = "; ".join(g for _, g in gaps[:_MAX_GAPS_SHOWN])
    if len(gaps) > _MAX_GAPS_SHOWN:
        shown += f"; and {len(gaps) - _MAX_GAPS_SHOWN} more"
    if sel.size < MIN_ROWS:
        worst = int(np.argmax(missing.sum(axis=0)))
        hint = (f"; column '{seen[used_names[worst]]}' is empty or NaN in "
                f"{int(missing[:, worst].sum())} of {n_rows} rows"
                if missing[:, worst].any() else "")
        where = (f"longest is {_lines_text(row_lines[sel[0]], row_lines[sel[-1]])}, "
                 f"{sel.size} samples" if sel.size else "no complete row")
        raise CsvError(path, gaps[0][0], None, f"no stretch without gaps has {MIN_ROWS} "
                       f"samples ({where}); gaps at {shown}{hint}")
    notes.append(f"gaps in the data at {shown}: using the longest stretch without gaps, "
                 f"{_lines_text(row_lines[sel[0]], row_lines[sel[-1]])} ({sel.size} of "
                 f"{n_rows} samples)")
    return fs, sel


@functools.cache
def _exact_floats() -> dict:
    """pandas' parser option for Python's own float bits: the default since pandas 3
    (tested), ``float_precision="round_trip"`` before (deprecated in 3)."""
    import pandas as pd

    major = int(pd.__version__.split(".", 1)[0])
    return {} if major >= 3 else {"float_precision": "round_trip"}


def estimate_rows(path: str | Path) -> int:
    """About how many data rows the file holds, from its size and its first 64 KiB (for
    the size check before reading: a long file is never read just to learn its length)."""
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(1 << 16)
    rows = [ln for ln in head.split(b"\n")[:-1] if ln.strip() and not ln.startswith(b"#")]
    if len(rows) < 2:
        return len(rows)
    data = rows[1:]  # the first is the header row
    per_row = sum(len(r) + 1 for r in data) / len(data)
    return max(len(data), int(size / per_row))


#: Rows parsed at a time: a few tens of MB of text (pandas' C parser per chunk).
CHUNK_ROWS = 200_000


def _line_at(path: Path, lineno: int) -> str:
    """Line ``lineno`` (1-based) of the file, read again for an error message."""
    with open(path, encoding="utf-8-sig") as fh:
        for k, line in enumerate(fh, start=1):
            if k == lineno:
                return line
    return ""


class _DataRows:
    """The data rows after the header row, parsed in chunks of CHUNK_ROWS lines.

    A chunk of plain numbers goes through pandas' C parser (its default, exact since pandas
    3: the same bits
    as Python's ``float``); a chunk it refuses, or one with quotes or comments, is parsed
    line by line, which names the line and cell of a mistake. ``max_rows``: stop after
    that many rows (``notes`` says how many of about how many were used). A last line
    without its newline and with too few cells is a cut file: left out, said in ``cut``."""

    def __init__(self, path: Path, fh, header_line: int, names: list[str],  # noqa: ANN001
                 idx: list[int], max_rows: int | None,
                 progress: Callable[[str], None] | None) -> None:
        import itertools

        self.path, self.names, self.idx = path, names, idx
        self.n_cols = len(names)
        self.notes: list[str] = []
        self.cut: str | None = None
        size = path.stat().st_size
        blocks: list[np.ndarray] = []
        line_blocks: list[np.ndarray] = []
        n = 0
        lineno = header_line
        read_bytes = 0
        more = False
        while True:
            want = CHUNK_ROWS if max_rows is None else min(CHUNK_ROWS, max_rows - n + 1)
            chunk = list(itertools.islice(fh, want))
            if not chunk:
                break
            if chunk[-1] and not chunk[-1].endswith("\n"):
                last = chunk[-1].strip()
                if last and not last.startswith("#") and \
                        len(_split(last)) < self.n_cols:
                    self.cut = (f"the last line ({lineno + len(chunk)}) is cut: "
                                f"{len(_split(last))} of {self.n_cols} cells")
                    chunk = chunk[:-1]
            read_bytes += sum(len(x) for x in chunk)
            vals, lines = self._parse(chunk, lineno)
            lineno += len(chunk)
            if max_rows is not None and n + len(vals) > max_rows:
                vals, lines = vals[:max_rows - n], lines[:max_rows - n]
                more = True
            blocks.append(vals)
            line_blocks.append(lines)
            n += len(vals)
            if max_rows is not None and n >= max_rows and not more:
                more = any(x.strip() and not x.lstrip().startswith("#") for x in fh)
            if progress is not None and (more or n >= CHUNK_ROWS):
                progress(f"reading {path.name}: {n:,} rows ({read_bytes / size:.0%} of "
                         f"{size / 1e6:,.0f} MB)" if not more else
                         f"reading {path.name}: {n:,} rows, the --max-rows limit")
            if more:
                break
        if more:
            per_row = read_bytes / max(lineno - header_line, 1)
            about = int(size / per_row) if per_row else n
            self.notes.append(f"used the first {n:,} of about {about:,} rows (by the file's "
                              f"size): --max-rows {max_rows:,} bounds time and memory")
            self.cut = None  # the rest was not read: its end is not known
        self.arr = (np.concatenate(blocks) if blocks else
                    np.zeros((0, len(idx))))
        self.lines = (np.concatenate(line_blocks) if line_blocks else
                      np.zeros(0, dtype=np.int64))

    def _parse(self, chunk: list[str], line0: int) -> tuple[np.ndarray, np.ndarray]:
        text = "".join(chunk)
        if '"' not in text and "#" not in text:
            fast = self._fast(chunk, text, line0)
            if fast is not None:
                return fast
        return self._slow(chunk, line0)

    def _fast(self, chunk: list[str], text: str, line0: int
              ) -> tuple[np.ndarray, np.ndarray] | None:
        import io

        import pandas as pd

        keep = [k for k, line in enumerate(chunk) if line.strip()]
        if len(keep) != len(chunk):
            return None  # blank lines: the careful path numbers them right
        want = self.n_cols - 1
        if any(line.count(",") != want for line in chunk):
            return None  # a row of the wrong length: the careful path names it
        na = sorted(NA_TOKENS | {t.upper() for t in NA_TOKENS} | {"NaN", "N/A", "#N/A",
                                                                 "Null", "None", ""})
        try:
            df = pd.read_csv(io.StringIO(text), header=None, usecols=self.idx,
                             dtype=np.float64, na_values=na, keep_default_na=False,
                             engine="c", **_exact_floats())
        except (ValueError, pd.errors.ParserError):
            return None
        if df.shape != (len(chunk), len(self.idx)):
            return None
        vals = df[self.idx].to_numpy(dtype=np.float64)
        return vals, np.arange(line0 + 1, line0 + 1 + len(chunk), dtype=np.int64)

    def _slow(self, chunk: list[str], line0: int) -> tuple[np.ndarray, np.ndarray]:
        rows: list[list[float]] = []
        row_lines: list[int] = []
        for k, raw in enumerate(chunk):
            lineno = line0 + 1 + k
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            cells = _split(line)
            if len(cells) != self.n_cols:
                raise CsvError(self.path, lineno, None,
                               f"expected {self.n_cols} cells, found {len(cells)}")
            try:
                values = [float(cells[j]) for j in self.idx]
            except ValueError:  # an empty or NA cell, or a mistake: cell by cell
                values = [_cell(self.path, lineno, self.names[j], cells[j])
                          for j in self.idx]
            rows.append(values)
            row_lines.append(lineno)
        return (np.asarray(rows, dtype=float).reshape(len(rows), len(self.idx)),
                np.asarray(row_lines, dtype=np.int64))


def exact_text(x: float) -> str:
    """``x`` as the shortest decimal that reads back as the same float (Python's ``repr``;
    ``5000`` for an integral value): a record written and read back is the record, bit for
    bit. A fixed number of digits is not: ``%.12g`` moved the time column, the angles, the
    piston position and the strain by up to an ulp or more, and a fit of the file read back
    took another path than the fit of the record in memory."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def write_measured(path: str | Path, data: MeasuredData, extra_header: dict | None = None) -> None:
    """Write a record in the CSV format :func:`read_measured` reads; every value as the
    shortest text that reads back to the same bits (:func:`exact_text`), so reading the
    file gives the record written."""
    names = ["t"] + [c for c in KNOWN_COLUMNS if c in data.columns and c != "t"]
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(f"# load: {data.load}\n")
        fh.write(f"# sample_rate_hz: {exact_text(data.sample_rate_hz)}\n")
        header = dict(extra_header or {})
        if "intersample" in data.header:
            header.setdefault("intersample", data.header["intersample"])
        for k, v in header.items():
            fh.write(f"# {k}: {v}\n")
        fh.write(",".join(names) + "\n")
        mat = np.column_stack([data.t] + [data.columns[c] for c in names[1:]])
        step = 4096  # rows formatted at a time: the text of a long record never whole
        for start in range(0, len(mat), step):
            fh.write("".join(",".join(map(exact_text, row)) + "\n"
                             for row in mat[start:start + step].tolist()))


__all__ = ["CsvError", "KNOWN_COLUMNS", "LOAD_CASES", "MeasuredData", "UNITS", "estimate_rows",
           "exact_text",
           "read_measured",
           "write_measured"]
