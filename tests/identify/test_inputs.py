"""Measured data as people have it: pandas files, a byte-order mark, other time names, units,
gaps and NaN rows, load and sample rate from the command line.

Each file is written here as text (pandas is not a dependency: the header row and cells are
what ``DataFrame.to_csv`` writes) and read with :func:`read_measured`; the expected SI values
are computed here from the values put into the file, with the conversion factors written out.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.cli import identify as cli
from hil.cli.args import Parser
from hil.identify.csvdata import CsvError, read_measured

FS = 5000.0
N = 40


def _data(n: int = N) -> dict[str, np.ndarray]:
    k = np.arange(n)
    return {"t": k / FS, "iq": np.sin(0.3 * k), "p_pump_a": 5e5 + 1e3 * k,
            "p_pump_b": 4e5 + 0.5 * k}


def _text(cols: dict[str, np.ndarray], names: list[str] | None = None,
          header: str = "# load: fixed_piston\n# sample_rate_hz: 5000\n",
          index: str | None = None) -> str:
    """CSV text of ``cols`` (header row ``names``), with a pandas-style index column
    ``index`` (its header cell) when given."""
    keys = list(cols)
    names = names or keys
    lines = [((index + ",") if index is not None else "") + ",".join(names)]
    for r in range(len(cols[keys[0]])):
        cells = [repr(float(cols[c][r])) for c in keys]
        lines.append(((str(r) + ",") if index is not None else "") + ",".join(cells))
    return header + "\n".join(lines) + "\n"


def _write(tmp_path, text: str, name: str = "data.csv", bom: bool = False):
    p = tmp_path / name
    p.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
    return p


def _error(path, **kw) -> CsvError:
    with pytest.raises(CsvError) as info:
        read_measured(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    return info.value


def _same(d, cols: dict[str, np.ndarray], rows=slice(None)) -> None:
    np.testing.assert_allclose(d.t, cols["t"][rows], rtol=0, atol=1e-15)
    for c, v in cols.items():
        if c != "t":
            np.testing.assert_allclose(d.col(c), v[rows], rtol=1e-12, err_msg=c)


# --- pandas index column, BOM, time names --------------------------------------------------
@pytest.mark.parametrize("index", ["", "Unnamed: 0", "index"])
def test_pandas_index_column_is_dropped_with_a_note(tmp_path, index):
    cols = _data()
    d = read_measured(_write(tmp_path, _text(cols, index=index)))
    _same(d, cols)
    assert d.ignored == []
    assert any("index column" in n and "dropped" in n for n in d.notes), d.notes


def test_two_index_columns_of_a_file_read_back_and_written_again(tmp_path):
    # read_csv of a to_csv file gives a column 'Unnamed: 0'; to_csv writes its own index too
    cols = _data()
    text = _text(cols, index="")
    body = text.splitlines()
    body[2] = "," + "Unnamed: 0" + body[2]
    body[3:] = [f"{r}," + line for r, line in enumerate(body[3:])]
    d = read_measured(_write(tmp_path, "\n".join(body) + "\n"))
    _same(d, cols)
    assert sum("index column" in n for n in d.notes) == 2


def test_index_name_elsewhere_is_an_ignored_column(tmp_path):
    cols = _data()
    cols = {"t": cols["t"], "index": np.arange(N, dtype=float),
            **{k: v for k, v in cols.items() if k != "t"}}
    d = read_measured(_write(tmp_path, _text(cols)))
    assert d.ignored == ["index"] and not any("index column" in n for n in d.notes)


@pytest.mark.parametrize("name", ["time", "t_s"])
def test_time_aliases(tmp_path, name):
    cols = _data()
    d = read_measured(_write(tmp_path, _text(cols, [name, "iq", "p_pump_a", "p_pump_b"])))
    _same(d, cols)
    assert any(f"'{name}' read as t" in n for n in d.notes)


def test_two_time_columns_are_refused(tmp_path):
    cols = _data()
    cols2 = {"t": cols["t"], "time": cols["t"], **{k: v for k, v in cols.items() if k != "t"}}
    e = _error(_write(tmp_path, _text(cols2)))
    assert e.line == 3 and e.column == "time" and "second time column" in str(e)


def test_byte_order_mark(tmp_path):
    cols = _data()
    _same(read_measured(_write(tmp_path, _text(cols), bom=True)), cols)
    # a BOM right before the header row (no header lines: load and rate from the caller)
    d = read_measured(_write(tmp_path, _text(cols, header=""), "b.csv", bom=True),
                      load="fixed_piston", sample_rate_hz=FS)
    _same(d, cols)


# --- gaps and NaN rows ---------------------------------------------------------------------
def _lines(text: str) -> list[str]:
    return text.splitlines()


def test_nan_and_empty_rows_split_the_record_longest_part_used(tmp_path):
    cols = _data(60)
    lines = _lines(_text(cols))  # header lines 1-2, header row 3, sample r on line r + 4
    lines[12 + 3] = lines[12 + 3].rsplit(",", 1)[0] + ","             # empty cell, line 16
    lines[13 + 3] = ",".join(["nan"] + lines[13 + 3].split(",")[1:])   # NaN time, line 17
    lines[50 + 3] = lines[50 + 3].replace(",", ",NaN,", 1).rsplit(",", 1)[0]  # line 54
    d = read_measured(_write(tmp_path, "\n".join(lines) + "\n"))
    _same(d, cols, slice(14, 50))  # samples 14..49: lines 18-53
    note = next(n for n in d.notes if "gaps" in n)
    assert "lines 16-17" in note and "line 54" in note and "p_pump_b" in note
    assert "lines 18-53 (36 of 60 samples)" in note


def test_time_jump_splits_the_record(tmp_path):
    cols = _data(60)
    keep = np.r_[0:20, 25:60]  # five samples missing after sample 19
    d = read_measured(_write(tmp_path, _text({k: v[keep] for k, v in cols.items()})))
    _same(d, cols, slice(25, 60))
    note = next(n for n in d.notes if "gaps" in n)
    assert "line 24 (t jumps 0.0012 s = 6 sample periods)" in note, note
    assert "lines 24-58 (35 of 55 samples)" in note


def test_small_jitter_is_no_gap_but_half_a_period_is_refused(tmp_path):
    cols = _data()
    cols["t"] = cols["t"].copy()
    cols["t"][10] += 0.4 / FS  # steps of 1.4 and 0.6 periods: accepted
    d = read_measured(_write(tmp_path, _text(cols)))
    assert d.n == N and not d.notes
    cols["t"][10] += 0.2 / FS  # now 1.6 (a gap) then 0.4 periods (jitter)
    e = _error(_write(tmp_path, _text(cols)))
    assert e.line == 15 and e.column == "t" and "jitter" in str(e)


def test_no_stretch_long_enough_is_refused(tmp_path):
    cols = _data(30)
    lines = _lines(_text(cols))
    for r in (8, 17, 26):  # stretches of 8, 8, 8 and 3 samples
        lines[r + 3] = lines[r + 3].rsplit(",", 1)[0] + ",NA"
    e = _error(_write(tmp_path, "\n".join(lines) + "\n"))
    assert e.line == 12 and "no stretch without gaps has 10 samples" in str(e)
    assert "longest is lines 4-11, 8 samples" in str(e)


def test_column_empty_in_every_row_is_left_out(tmp_path):
    cols = _data()
    text = _text({**cols, "p_acc": np.full(N, np.nan)})
    d = read_measured(_write(tmp_path, text))
    assert not d.has("p_acc") and d.n == N
    assert any("empty in every row: p_acc" in n for n in d.notes)
    # ... unless the load needs it
    cols2 = dict(cols, p_pump_b=np.full(N, np.nan))
    e = _error(_write(tmp_path, _text(cols2), "b.csv"))
    assert e.column == "p_pump_b" and "no value in any row" in str(e)


def test_infinite_and_text_cells_are_still_mistakes(tmp_path):
    cols = _data()
    lines = _lines(_text(cols))
    lines[9] = lines[9].replace(lines[9].split(",")[1], "-inf", 1)
    e = _error(_write(tmp_path, "\n".join(lines) + "\n"))
    assert e.line == 10 and e.column == "iq" and "not finite" in str(e)
    lines = _lines(_text(cols))
    lines[9] = lines[9].replace(lines[9].split(",")[2], "1.2.3", 1)
    e = _error(_write(tmp_path, "\n".join(lines) + "\n", "b.csv"))
    assert e.line == 10 and e.column == "p_pump_a" and "not a number" in str(e)


# --- load and sample rate from the caller --------------------------------------------------
def test_load_and_rate_from_the_caller(tmp_path):
    cols = _data()
    bare = _write(tmp_path, _text(cols, header=""))
    d = read_measured(bare, load="fixed_piston", sample_rate_hz=FS)
    _same(d, cols)
    assert d.load == "fixed_piston" and d.sample_rate_hz == FS and not d.notes
    assert "--load" in str(_error(bare, sample_rate_hz=FS))
    # no rate anywhere: the median step gives it, and a note says so
    d = read_measured(bare, load="fixed_piston")
    assert d.sample_rate_hz == FS and any("inferred" in n for n in d.notes)
    e = _error(bare, load="fixed_piston", sample_rate_hz=1000.0)
    assert "disagrees with --sample-rate 1000" in str(e)


def test_caller_disagreeing_with_the_header_is_refused(tmp_path):
    p = _write(tmp_path, _text(_data()))
    d = read_measured(p, load="fixed_piston", sample_rate_hz=5000.0)  # the same: fine
    assert d.load == "fixed_piston"
    e = _error(p, load="free_piston")
    assert e.line == 1 and "'# load: fixed_piston' disagrees with --load free_piston" in str(e)
    e = _error(p, sample_rate_hz=4000.0)
    assert e.line == 2 and "disagrees with --sample-rate 4000" in str(e)


# --- units ---------------------------------------------------------------------------------
@pytest.mark.parametrize("column,unit,value,si", [
    ("p_pump_a", "Pa", 7.0, 7.0),
    ("p_pump_a", "kPa", 7.0, 7e3),
    ("p_pump_a", "bar", 7.0, 7e5),
    ("p_pump_a", "MPa", 7.0, 7e6),
    ("p_pump_a", "psi", 100.0, 689475.7293168361),
    ("iq", "mA", 1500.0, 1.5),
    ("iq", "A", 1.5, 1.5),
    ("x_piston", "mm", 12.5, 0.0125),
    ("x_piston", "um", 12.5, 12.5e-6),
    ("theta_m", "deg", 90.0, math.pi / 2),
    ("theta_m", "rev", 2.0, 4 * math.pi),
    ("f_strain", "kN", 1.2, 1200.0),
    ("temp_c", "K", 300.0, 26.85),
    ("temp_c", "degF", 212.0, 100.0),
    ("temp_c", "degC", 40.0, 40.0),
])
def test_units_line_converts_to_si(tmp_path, column, unit, value, si):
    cols = {**_data(), column: np.full(N, value)}
    key = "p" if column.startswith("p_") else column
    header = f"# load: fixed_piston\n# sample_rate_hz: 5000\n# units: {key}={unit}\n"
    d = read_measured(_write(tmp_path, _text(cols, header=header)))
    np.testing.assert_allclose(d.col(column), si, rtol=1e-12)
    if unit not in ("Pa", "A", "degC"):
        assert any(f"{column} from {unit}" in n for n in d.notes), d.notes
    else:
        assert not d.notes


def test_units_of_the_issue_example(tmp_path):
    k = np.arange(N)
    cols = {"t": k * 0.2, "iq": 100.0 * k, "theta_m": 3.6 * k, "p_pump_a": 50 + 0.1 * k,
            "p_pump_b": 40 + 0.1 * k, "x_piston": 0.5 * k, "f_strain": 0.01 * k,
            "temp_c": 30.0 + 0 * k}
    header = ("# load: fixed_piston\n# sample_rate_hz: 5000\n# units: p=bar, iq=mA, "
              "x_piston=mm, theta_m=deg, temp_c=degC, f_strain=kN, t=ms\n")
    d = read_measured(_write(tmp_path, _text(cols, header=header)))
    np.testing.assert_allclose(d.t, k * 0.2e-3, rtol=1e-12)
    np.testing.assert_allclose(d.col("iq"), 0.1 * k, rtol=1e-12)
    np.testing.assert_allclose(d.col("theta_m"), 3.6 * k * math.pi / 180, rtol=1e-12)
    np.testing.assert_allclose(d.col("p_pump_a"), (50 + 0.1 * k) * 1e5, rtol=1e-12)
    np.testing.assert_allclose(d.col("p_pump_b"), (40 + 0.1 * k) * 1e5, rtol=1e-12)
    np.testing.assert_allclose(d.col("x_piston"), 0.5e-3 * k, rtol=1e-12)
    np.testing.assert_allclose(d.col("f_strain"), 10.0 * k, rtol=1e-12)
    np.testing.assert_allclose(d.col("temp_c"), 30.0)
    assert d.sample_rate_hz == FS  # the rate is checked against the time in seconds


def test_column_unit_beats_the_pressure_group(tmp_path):
    cols = {**_data(), "p_acc": np.full(N, 2.0)}
    header = "# load: fixed_piston\n# sample_rate_hz: 5000\n# units: p=bar, p_acc=MPa\n"
    d = read_measured(_write(tmp_path, _text(cols, header=header)))
    np.testing.assert_allclose(d.col("p_acc"), 2e6)
    np.testing.assert_allclose(d.col("p_pump_a"), cols["p_pump_a"] * 1e5)


@pytest.mark.parametrize("name", ["p_pump_a[bar]", "p_pump_a [bar]", "p_pump_a (bar)"])
def test_units_in_the_header_row(tmp_path, name):
    cols = _data()
    written = {"t": cols["t"] * 1e3, "iq": cols["iq"] * 1e3, "p_pump_a": cols["p_pump_a"] / 1e5,
               "p_pump_b": cols["p_pump_b"]}
    d = read_measured(_write(tmp_path, _text(written, ["time [ms]", "iq(mA)", name,
                                                       "p_pump_b"])))
    np.testing.assert_allclose(d.t, cols["t"], rtol=1e-12, atol=1e-18)
    for c in ("iq", "p_pump_a", "p_pump_b"):
        np.testing.assert_allclose(d.col(c), cols[c], rtol=1e-12, err_msg=c)


@pytest.mark.parametrize("units,column,words", [
    ("p=bars", "p_pump_a", "unit 'bars' is not a known unit"),
    ("iq=bar", "iq", "unit 'bar' is a pressure unit; current units: A, mA"),
    ("p_pumpa=bar", "p_pumpa", "unknown column"),
    ("iq", None, "'iq' is not COLUMN=UNIT"),
    ("iq=mA, iq=A", "iq", "given twice"),
    ("temp_c=", "temp_c", "no unit given"),
])
def test_bad_units_line(tmp_path, units, column, words):
    header = f"# load: fixed_piston\n# units: {units}\n# sample_rate_hz: 5000\n"
    e = _error(_write(tmp_path, _text(_data(), header=header)))
    assert e.line == 2 and e.column == column and words in str(e), str(e)


def test_bad_units_in_the_header_row(tmp_path):
    cols = _data()
    e = _error(_write(tmp_path, _text(cols, ["t", "iq", "p_pump_a[furlong]", "p_pump_b"])))
    assert e.line == 3 and e.column == "p_pump_a" and "'furlong'" in str(e)
    header = "# load: fixed_piston\n# sample_rate_hz: 5000\n# units: p=MPa\n"
    e = _error(_write(tmp_path, _text(cols, ["t", "iq", "p_pump_a[bar]", "p_pump_b"],
                                      header=header), "b.csv"))
    assert e.line == 3 and "disagrees with 'bar'" in str(e)
    e = _error(_write(tmp_path, _text(cols, ["t_s [ms]", "iq", "p_pump_a", "p_pump_b"]),
                      "c.csv"))
    assert e.column == "t_s [ms]" and "in seconds by its name" in str(e)


def test_unknown_column_with_a_unit_is_ignored_not_refused(tmp_path):
    cols = {**_data(), "supply (V)": np.full(N, 48.0)}
    d = read_measured(_write(tmp_path, _text(cols)))
    assert d.ignored == ["supply (V)"]


# --- the command line: flags, one line and exit 2 ------------------------------------------
def _run(capsys, *argv: str) -> tuple[int, str, str]:
    p = Parser(prog="eha-hil identify")
    cli.configure_identify(p)
    try:
        args = p.parse_args(list(argv))
        code = cli.run_identify(args)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("text,extra,words", [
    (_text(_data(), header=""), [], ":1: missing header line '# load: ...'"),
    (_text(_data()), ["--load", "free_piston"], ":1: '# load: fixed_piston' disagrees"),
    (_text(_data()), ["--sample-rate", "4000"], ":2: '# sample_rate_hz: 5000' disagrees"),
    (_text(_data(), header="# load: fixed_piston\n# units: p=bars\n"), [],
     ":2: column 'p_pump_a': unit 'bars' is not a known unit"),
    (_text(_data(), ["t", "time", "p_pump_a", "p_pump_b"]), [],
     ":3: column 'time': a second time column"),
])
def test_cli_bad_input_one_line_exit_2(capsys, tmp_path, text, extra, words):
    path = _write(tmp_path, text)
    code, out, err = _run(capsys, str(path), "--quiet", *extra)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"eha-hil identify: {path}"), err
    assert words in err and "Traceback" not in err


def test_cli_text_that_is_not_utf8_names_its_line(capsys, tmp_path):
    """A record saved in another code page (a Latin-1 degree sign in a comment) is refused
    in one line naming the line and the byte, not with the codec's message."""
    path = _write(tmp_path, _text(_data()))
    lines = path.read_bytes().split(b"\n")
    lines.insert(3, b"# oil at 40 \xb0C")
    path.write_bytes(b"\n".join(lines))
    code, out, err = _run(capsys, str(path), "--quiet")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{path}:4:" in err and "0xb0" in err and "UTF-8" in err and "codec" not in err


def test_cli_sample_rate_must_be_positive(capsys, tmp_path):
    path = _write(tmp_path, _text(_data()))
    code, _, err = _run(capsys, str(path), "--sample-rate", "-5")
    assert code == 2 and "--sample-rate" in err and err.count("\n") == 1


@pytest.mark.slow
def test_cli_identifies_a_pandas_file_with_units_and_a_gap(capsys, tmp_path):
    """A synthetic record rewritten the way a pandas user would have it (index column, BOM,
    'time', bar and mA, no header lines, a NaN row): same effect found, the notes say what
    reading did."""
    from hil.identify.synth import generate

    res = generate("fixed_piston", {"pump_coulomb_friction": {"force_n": 60.0}}, seconds=4.0,
                   seed=1)
    d = res.data
    gap = d.n - 700  # the short part after the NaN row is left out
    lines = [",time,iq[mA],p_pump_a[bar],p_pump_b[bar],f_strain"]
    for r in range(d.n):
        vals = [d.t[r], d.col("iq")[r] * 1e3, d.col("p_pump_a")[r] / 1e5,
                d.col("p_pump_b")[r] / 1e5, d.col("f_strain")[r]]
        cells = ["" for _ in vals] if r == gap else [repr(float(v)) for v in vals]
        lines.append(f"{r}," + ",".join(cells))
    path = _write(tmp_path, "\n".join(lines) + "\n", bom=True)
    code, out, err = _run(capsys, str(path), "--load", "fixed_piston", "--json", "--quiet")
    assert code == 0, err
    rep = json.loads(out)
    assert [e["name"] for e in rep["effects_added"]] == ["pump_coulomb_friction"]
    notes = " | ".join(rep["notes"])
    assert "index column" in notes and "inferred" in notes and "iq[mA] from mA" in notes
    assert f"line {gap + 2}" in notes and f"lines 2-{gap + 1} ({gap} of {d.n} samples)" in notes
