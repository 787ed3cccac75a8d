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

Every mistake raises :class:`CsvError`, whose ``str`` is one line naming the file, the line
and the column, so the command line can print it and exit with code 2.
"""

from __future__ import annotations

import csv
import math
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

#: Output groups that are enough for each load case (any one group suffices).
REQUIRED_OUTPUTS: dict[str, tuple[tuple[str, ...], ...]] = {
    "fixed_piston": (("p_pump_a", "p_pump_b"), ("p_cyl_a", "p_cyl_b"), ("f_strain",)),
    "free_piston": (("x_piston",), ("theta_m",)),
    "conrod_fixed": (("p_pump_a", "p_pump_b"), ("p_cyl_a", "p_cyl_b"), ("f_strain",)),
}


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
    """One identification record: header values, time base and the data columns (SI)."""

    path: str
    load: str
    sample_rate_hz: float
    t: np.ndarray
    columns: dict[str, np.ndarray]
    header: dict[str, str] = field(default_factory=dict)
    ignored: list[str] = field(default_factory=list)

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
                            cols, dict(self.header), list(self.ignored))


def _header_value(path: Path, lineno: int, key: str, raw: str) -> str:
    value = raw.strip()
    if not value:
        raise CsvError(path, lineno, None, f"header '{key}' has no value")
    return value


def read_measured(path: str | Path) -> MeasuredData:
    """Read and validate a measured-data CSV (see the module docstring).

    Raises :class:`CsvError` for a missing file, a missing or unknown ``load``, a missing or
    non-positive ``sample_rate_hz``, a missing required column, a row of the wrong length, a
    non-numeric or non-finite cell, a time column that does not increase, or a time step
    that disagrees with the declared sample rate by more than 1 %.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CsvError(path, None, None, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CsvError(path, None, None, f"cannot read: {exc}") from None
    lines = text.splitlines()
    header: dict[str, str] = {}
    lineno = 0
    names: list[str] | None = None
    header_line = 0
    for lineno, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:]
            if ":" in body:
                key, raw = body.split(":", 1)
                header[key.strip().lower()] = _header_value(path, lineno, key.strip(), raw)
            continue
        names = [c.strip() for c in next(csv.reader([stripped]))]
        header_line = lineno
        break
    if names is None:
        raise CsvError(path, lineno or None, None, "no header row (expected t,iq,...)")
    if "load" not in header:
        raise CsvError(path, 1, None, "missing header line '# load: ...' "
                       f"(one of {', '.join(LOAD_CASES)})")
    load = header["load"]
    if load not in LOAD_CASES:
        line_of = _find_header_line(lines, "load")
        raise CsvError(path, line_of, None,
                       f"unknown load '{load}' (expected one of {', '.join(LOAD_CASES)})")
    if "sample_rate_hz" not in header:
        raise CsvError(path, 1, None, "missing header line '# sample_rate_hz: ...'")
    line_of = _find_header_line(lines, "sample_rate_hz")
    try:
        fs = float(header["sample_rate_hz"])
    except ValueError:
        raise CsvError(path, line_of, None,
                       f"sample_rate_hz '{header['sample_rate_hz']}' is not a number") from None
    if not math.isfinite(fs) or fs <= 0:
        raise CsvError(path, line_of, None, f"sample_rate_hz must be > 0, got {fs}")

    seen: set[str] = set()
    for name in names:
        if not name:
            raise CsvError(path, header_line, None, "empty column name in the header row")
        if name in seen:
            raise CsvError(path, header_line, name, "column appears twice")
        seen.add(name)
    for req in ("t", "iq"):
        if req not in seen:
            raise CsvError(path, header_line, req, "required column missing")
    groups = REQUIRED_OUTPUTS[load]
    if not any(all(c in seen for c in g) for g in groups):
        need = " or ".join("+".join(g) for g in groups)
        first_missing = next(c for c in groups[0] if c not in seen)
        raise CsvError(path, header_line, first_missing,
                       f"required column missing: load {load} needs {need}")

    n_cols = len(names)
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno in range(header_line + 1, len(lines) + 1):
        line = lines[lineno - 1].strip()
        if not line or line.startswith("#"):
            continue
        cells = line.split(",")
        if len(cells) != n_cols:
            raise CsvError(path, lineno, None,
                           f"expected {n_cols} cells, found {len(cells)}")
        values = []
        for j, cell in enumerate(cells):
            try:
                v = float(cell)
            except ValueError:
                raise CsvError(path, lineno, names[j],
                               f"'{cell.strip()}' is not a number") from None
            if not math.isfinite(v):
                raise CsvError(path, lineno, names[j], f"'{cell.strip()}' is not finite")
            values.append(v)
        rows.append(values)
        row_lines.append(lineno)
    if len(rows) < 10:
        raise CsvError(path, header_line, None, f"only {len(rows)} data rows (need >= 10)")
    arr = np.asarray(rows, dtype=float)
    t = arr[:, names.index("t")]
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise CsvError(path, row_lines[k], "t",
                       f"time does not increase ({t[k]!r} after {t[k - 1]!r})")
    step = float(np.median(dt))
    if abs(step * fs - 1.0) > 0.01:
        raise CsvError(path, row_lines[1], "t",
                       f"time step {step:.6g} s disagrees with sample_rate_hz {fs:g}")
    off = np.flatnonzero(np.abs(dt * fs - 1.0) > 0.5)
    if off.size:
        k = int(off[0]) + 1
        raise CsvError(path, row_lines[k], "t",
                       f"gap or jitter in time: step {dt[k - 1]:.6g} s, expected {1 / fs:.6g} s")
    columns = {}
    ignored = []
    for j, name in enumerate(names):
        if name in KNOWN_COLUMNS:
            if name != "t":
                columns[name] = arr[:, j].copy()
        else:
            ignored.append(name)
    return MeasuredData(str(path), load, fs, t.copy(), columns, header, ignored)


def _find_header_line(lines: list[str], key: str) -> int:
    for i, line in enumerate(lines, start=1):
        s = line.strip()
        if s.startswith("#") and ":" in s and s[1:].split(":", 1)[0].strip().lower() == key:
            return i
    return 1


def write_measured(path: str | Path, data: MeasuredData, extra_header: dict | None = None) -> None:
    """Write a record in the CSV format :func:`read_measured` reads (full float precision)."""
    names = ["t"] + [c for c in KNOWN_COLUMNS if c in data.columns and c != "t"]
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(f"# load: {data.load}\n")
        fh.write(f"# sample_rate_hz: {data.sample_rate_hz:g}\n")
        header = dict(extra_header or {})
        if "intersample" in data.header:
            header.setdefault("intersample", data.header["intersample"])
        for k, v in header.items():
            fh.write(f"# {k}: {v}\n")
        fh.write(",".join(names) + "\n")
        mat = np.column_stack([data.t] + [data.columns[c] for c in names[1:]])
        np.savetxt(fh, mat, delimiter=",", fmt="%.12g")


__all__ = ["CsvError", "KNOWN_COLUMNS", "LOAD_CASES", "MeasuredData", "read_measured",
           "write_measured"]
