"""Malformed measured-data CSVs: one-line errors naming file, line and column."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify.csvdata import CsvError, MeasuredData, exact_text, read_measured, write_measured

HEADER = "# load: fixed_piston\n# sample_rate_hz: 5000\n"
COLS = "t,iq,p_pump_a,p_pump_b\n"


def _rows(n: int = 20) -> list[str]:
    return [f"{k * 2e-4:.6f},{np.sin(k):.4f},{5e5 + k},{5e5}\n" for k in range(n)]


def _write(tmp_path, text: str):
    p = tmp_path / "data.csv"
    p.write_text(text)
    return p


def test_reads_valid_file(tmp_path):
    d = read_measured(_write(tmp_path, HEADER + COLS + "".join(_rows())))
    assert d.load == "fixed_piston" and d.n == 20 and d.sample_rate_hz == 5000
    assert set(d.columns) == {"iq", "p_pump_a", "p_pump_b"}


def _error(tmp_path, text: str) -> CsvError:
    with pytest.raises(CsvError) as info:
        read_measured(_write(tmp_path, text))
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(tmp_path / "data.csv"))
    return info.value


def test_missing_column(tmp_path):
    e = _error(tmp_path, HEADER + "t,p_pump_a,p_pump_b\n" + "0,1,2\n" * 20)
    assert e.line == 3 and e.column == "iq" and "missing" in str(e)


def test_missing_output_for_load(tmp_path):
    e = _error(tmp_path, HEADER + "t,iq,theta_m\n" + "".join(
        f"{k * 2e-4},0,0\n" for k in range(20)))
    assert e.line == 3 and e.column == "p_pump_a" and "fixed_piston needs" in str(e)


def test_non_numeric_cell(tmp_path):
    rows = _rows()
    rows[5] = "0.001000,abc,500005,500000\n"
    e = _error(tmp_path, HEADER + COLS + "".join(rows))
    assert e.line == 9 and e.column == "iq" and "'abc' is not a number" in str(e)
    assert ":9: column 'iq':" in str(e)


def test_non_finite_cell(tmp_path):
    rows = _rows()
    rows[2] = "0.000400,inf,500005,500000\n"  # (a NaN is a gap: tests/identify/test_inputs.py)
    e = _error(tmp_path, HEADER + COLS + "".join(rows))
    assert e.line == 6 and e.column == "iq"


def test_non_monotonic_time(tmp_path):
    rows = _rows()
    rows[7], rows[8] = rows[8], rows[7]
    e = _error(tmp_path, HEADER + COLS + "".join(rows))
    assert e.column == "t" and e.line == 12 and "does not increase" in str(e)
    assert "np." not in str(e)  # the values as a user wrote them, not numpy's repr


def test_unknown_load(tmp_path):
    e = _error(tmp_path, "# load: hanging\n# sample_rate_hz: 5000\n" + COLS + "".join(_rows()))
    assert e.line == 1 and "unknown load 'hanging'" in str(e)


def test_missing_load_and_rate(tmp_path):
    assert "load" in str(_error(tmp_path, "# sample_rate_hz: 5000\n" + COLS + "".join(_rows())))
    # without a rate the median time step gives it, and a note says so
    d = read_measured(_write(tmp_path, "# load: free_piston\nt,iq,x_piston\n" + "".join(
        f"{k},0,0\n" for k in range(20))))
    assert d.sample_rate_hz == 1.0 and any("inferred" in n for n in d.notes)


def test_wrong_cell_count_and_rate_mismatch(tmp_path):
    rows = _rows()
    rows[3] = "0.0006,1,2\n"
    e = _error(tmp_path, HEADER + COLS + "".join(rows))
    assert e.line == 7 and "expected 4 cells" in str(e)
    bad = "# load: fixed_piston\n# sample_rate_hz: 1000\n" + COLS + "".join(_rows())
    assert "disagrees with sample_rate_hz" in str(_error(tmp_path, bad))


def test_missing_file(tmp_path):
    with pytest.raises(CsvError, match="no such file"):
        read_measured(tmp_path / "nope.csv")


def _awkward(n: int = 400) -> MeasuredData:
    """Values a fixed count of digits does not carry: times ``k/fs``, doubles over the whole
    exponent range with random mantissas, a subnormal, -0.0, integral values."""
    rng = np.random.default_rng(5)
    t = np.arange(n) * (1.0 / 5000.0)
    wide = rng.uniform(1.0, 2.0, n) * 2.0 ** rng.integers(-1070, 1000, n)
    wide[:6] = [5e-324, -0.0, 0.1 + 0.2, 1.0 / 3.0, 5e5, -2.0 ** 60]
    cols = {"iq": rng.standard_normal(n) * np.pi, "p_pump_a": wide,
            "p_pump_b": -wide[::-1].copy(), "f_strain": np.round(rng.standard_normal(n), 3)}
    return MeasuredData("<awkward>", "fixed_piston", 5000.0, t, cols)


def _same_bits(a: MeasuredData, b: MeasuredData) -> None:
    assert a.t.view(np.uint64).tolist() == b.t.view(np.uint64).tolist()
    assert set(a.columns) == set(b.columns)
    for c, v in a.columns.items():
        assert v.view(np.uint64).tolist() == b.columns[c].view(np.uint64).tolist(), c
    assert b.sample_rate_hz == a.sample_rate_hz and b.load == a.load


@pytest.mark.parametrize("comment", [False, True])
def test_a_record_written_and_read_back_is_the_record_bit_for_bit(tmp_path, comment):
    """The file of a record is the record: an identification of the file and of the record
    in memory see the same numbers (a fixed ``%.12g`` moved the time column and the angles by
    an ulp and more, and the fit took another path). Both readers: pandas' parser, and the
    line-by-line one (a comment line sends a chunk there)."""
    d = _awkward()
    p = tmp_path / "r.csv"
    write_measured(p, d)
    if comment:
        lines = p.read_text().splitlines(keepends=True)
        p.write_text("".join(lines[:10] + ["# a note in the middle\n"] + lines[10:]))
    _same_bits(d, read_measured(p))


def test_a_rig_record_survives_the_file(tmp_path):
    """The independent rig's record (what ``identify-check`` identifies in memory, and
    ``identify-synth --realism rig`` writes) reads back bit for bit, its header's sample rate
    included."""
    from hil.identify.rig import generate_rig

    d = generate_rig("free_piston", ["pump_coulomb_friction"], seconds=0.6, seed=1,
                     sample_rate_hz=4999.5).data
    write_measured(tmp_path / "r.csv", d)
    _same_bits(d, read_measured(tmp_path / "r.csv"))


def test_exact_text_is_short_and_exact():
    assert [exact_text(x) for x in (5000.0, -0.0, 0.1, 2e-4 * 3, 1e22)] == [
        "5000", "-0", "0.1", "0.0006000000000000001", "1e+22"]
