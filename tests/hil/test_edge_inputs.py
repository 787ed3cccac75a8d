"""Edge values and odd inputs get one true line, never a hang or a confident answer:
settings that would make the work unbounded, misspelt tables, fault windows outside the
run, options of another transport, cut input files (every reader the same way), wrong
diagnoses, and big inputs (streamed, bounded, with progress).
"""

from __future__ import annotations

import argparse
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hil.cli.args import walk
from hil.cli.root import build_parser, main
from tests.hil.test_outputs import _run  # eha-hil ARGV in this process: code, out, err


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and "\r" not in ln
             and not re.match(r"^\S+ ?\S*: simulating|^bench \w+: simulating", ln)]
    assert "Traceback" not in err
    assert len(lines) == 1, err
    return lines[0]


# --- settings that control work --------------------------------------------------------------
#: Verbs that take -c/--set but never step the plant with it (the firmware alone, the fit's
#: start values, a replay of logged inputs, the echo boxes of the bus benchmark, a listing).
NO_PLANT = {"eha-hil config show", "eha-hil replay", "eha-hil verify mcu",
            "eha-hil verify current-loop", "eha-hil bench bus", "eha-hil bench identify",
            "eha-hil identify"}
CHEAP = {
    "eha-hil plant bode": ["--points", "2"], "eha-hil plant tn-curve": ["--points", "3"],
    "eha-hil bench plant": ["--seconds", "0.01"],
    "eha-hil bench fpga": ["--seconds", "0.01", "--bit-seconds", "0.001"],
    "eha-hil bench stack": ["--seconds", "0.01"], "eha-hil bench robot": ["--seconds", "0.01"],
    "eha-hil bench ethercat": ["--cycles", "10"],
    "eha-hil bench sweep": ["--points", "2", "--scenario", "current-step"],
    "eha-hil bus run": ["--seconds", "0.01"],
    "eha-hil serve": ["--port", "pty", "--seconds", "0.01", "-q"],
    "eha-hil identify-synth": ["{tmp}/y.csv", "--seconds", "1.01"],
    "eha-hil sweep": ["current-step", "--seeds", "0..1", "--workers", "1"],
    "eha-hil run": ["current-step"],
}


def _plant_verbs() -> list[str]:
    verbs = []
    for p in walk(build_parser()):
        if any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
            continue
        if any("--set" in a.option_strings for a in p._actions) and p.prog not in NO_PLANT:
            verbs.append(p.prog)
    return verbs


@pytest.mark.parametrize("verb", _plant_verbs())
def test_substeps_bounded_on_every_verb(verb, tmp_path):
    """--set hydraulics.jp_kg=1e-9 needs ~1.7e9 RK4 sub-steps per tick: refused at once,
    naming the setting, instead of a run that never ends."""
    extra = [a.format(tmp=tmp_path) for a in CHEAP.get(verb, [])]
    code, out, err = _run([*verb.split()[1:], *extra, "--set", "hydraulics.jp_kg=1e-9"])
    line = _one_line(err)
    assert code == 2 and "RK4 sub-steps" in line and "hydraulics.jp_kg" in line, err
    assert "at most 1000" in line


def test_substep_bound_is_the_schema_bound():
    from plant.config import RANGES
    from plant.model import MAX_SUBSTEPS

    assert RANGES["sim.substeps"].hi == MAX_SUBSTEPS


def test_advance_in_chunks_is_bit_identical(monkeypatch):
    """A long advance runs in chunks (Ctrl-C is seen between two); the chunks give the same
    state, outputs and recorded rows, bit for bit, as one call."""
    import plant.model as pm
    from plant.config import load_config

    cfg = load_config(None)

    def run(chunk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        monkeypatch.setattr(pm, "CHUNK_SUBSTEPS", chunk)
        p = pm.Plant(cfg)
        p.set_current(10.0)
        rec = np.zeros((40, p.y.size))
        p.advance(397, rec, every=10)
        return p.x.copy(), p.y.copy(), rec

    whole = run(10**9)
    for chunk in (1, 50, 1000):
        parts = run(chunk)
        for a, b in zip(whole, parts, strict=True):
            assert np.array_equal(a.view(np.int64), b.view(np.int64))


# --- configuration files: unknown tables and keys --------------------------------------------
@pytest.mark.parametrize(("text", "match"), [
    ("[[faults]]\nlink = 'fieldbus.down'\nkind = 'drop'\n", r"unknown table \[\[faults\]\]"),
    ("seed = 3\n", r"no \[\[fault\]\] table"),
    ("[[fault]]\nlink = 'fieldbus.down'\nkind = 'drop'\nstart = 0.1\n", r"key 'start'"),
    ("[[fault]]\nlink = 'fieldbus.down'\nkind = 'drop'\nstart_s = 5.0\n",
     r"not inside the run \(1 s\)"),
    ("[[fault]]\nlink = 'fieldbus.down'\nkind = 'drop'\nstart_s = 1.0\n",
     r"not inside the run"),  # the last cycle of a 1 s run starts at 0.999 s
])
def test_fault_file_mistakes(text, match, tmp_path):
    f = tmp_path / "faults.toml"
    f.write_text(text)
    code, _, err = _run(["bus", "run", "--seconds", "1", "--faults", str(f)])
    line = _one_line(err)
    assert code == 2 and str(f) in line and re.search(match, line), line


def test_fault_inside_the_run_is_taken(tmp_path):
    f = tmp_path / "faults.toml"
    f.write_text("[[fault]]\nlink = 'fieldbus.down'\nkind = 'drop'\nstart_s = 0.005\n"
                 "end_s = 0.007\n")
    code, out, err = _run(["bus", "run", "--seconds", "0.01", "--faults", str(f), "--json"])
    assert code == 0, err
    assert '"fault_counts"' in out


@pytest.mark.parametrize(("text", "match"), [
    ("[hydraulics]\njp_kgg = 1.0\n", r"unknown key 'hydraulics.jp_kgg' \(known here: .*jp_kg"),
    ("[hydraulic]\njp_kg = 1.0\n", r"unknown section 'hydraulic'"),
    ("[effects]\npulsation = 3\n", r"'effects.pulsation' is a section.*effects.pulsation.order"),
])
def test_config_file_unknown_keys(text, match, tmp_path):
    f = tmp_path / "c.toml"
    f.write_text(text)
    code, _, err = _run(["config", "show", "-c", str(f)])
    line = _one_line(err)
    assert code == 2 and str(f) in line and re.search(match, line), line


def test_set_on_a_section_lists_its_keys():
    code, _, err = _run(["config", "show", "--set", "effects.pulsation=3"])
    line = _one_line(err)
    assert code == 2 and "known here: )" not in line
    assert "effects.pulsation.amplitude" in line and "section" in line


@pytest.mark.parametrize(("text", "match"), [
    ("name = 'x'\nboxes = 1\n[[box]]\nslots = ['a']\n", r"unknown key\(s\) boxes"),
    ("[[box]]\nslots = ['a']\nslot = 1\n", r"box #0: unknown key\(s\) slot"),
])
def test_topology_file_unknown_keys(text, match, tmp_path):
    f = tmp_path / "t.toml"
    f.write_text(text)
    code, _, err = _run(["bus", "run", "--seconds", "0.01", "--topology", str(f)])
    line = _one_line(err)
    assert code == 2 and str(f) in line and re.search(match, line), line


# --- options of another transport ------------------------------------------------------------
def _scoped() -> list[tuple[str, str, str, tuple[str, ...]]]:
    out = []
    for p in walk(build_parser()):
        for a in p._actions:
            scope = getattr(a, "only_with", None)
            if scope:
                out.append((p.prog, a.option_strings[-1], scope[0], scope[1]))
    return out


VALUES = {"--baudrate": "9600", "--host": "0.0.0.0", "--port": "pty", "--interface": "lo",
          "--stack-box": "0", "--capture": "c.pcapng", "--foxglove": "127.0.0.1:1",
          "--dc-drift-ppm": "50", "--dc-hop-ns": "500"}


#: Values of the options that only one side of a switch reads (refused before any work).
SWITCHED = {"--model": "echo", "--seconds": "2", "--bring-ups": "3", "--busy-cpu": "0",
            "--cycles": "100"}


def test_serve_options_are_scoped():
    names = {o for _, o, _, _ in _scoped()}
    assert {"--baudrate", "--stack-box", "--host", "--interface"} <= names
    # the SOEM-on-a-wire options, and the in-process rows' cycle count, each on its side
    assert {o for p, o, d, _ in _scoped() if d == "wire"} == set(SWITCHED)


@pytest.mark.parametrize("case", _scoped(), ids=lambda c: f"{c[0][8:]} {c[1]}")
def test_option_of_another_transport_refused(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    prog, opt, dest, allowed = case
    if allowed in ((True,), (False,)):  # an option of a switch's side (bench ethercat --wire)
        switch = [] if allowed == (True,) else [f"--{dest.replace('_', '-')}"]
        code, out, err = _run([*prog.split()[1:], *switch, f"{opt}={SWITCHED[opt]}"])
        line = _one_line(err)
        side = "only with" if allowed == (True,) else "not with"
        assert code == 2 and opt in line and f"{side} --{dest}" in line, line
        assert out == ""
        return
    choices = next(a.choices for p in walk(build_parser()) if p.prog == prog
                   for a in p._actions if a.dest == dest)
    for other in [c for c in choices if c not in allowed]:
        code, out, err = _run([*prog.split()[1:], f"--{dest}", other, f"{opt}={VALUES[opt]}",
                               "--seconds", "0.01"])
        line = _one_line(err)
        assert code == 2 and opt in line and f"only with --{dest}" in line, line
        assert out == ""


# --mcu-image only where an MCU law runs: elsewhere it would be accepted and ignored
NO_MCU = [["plant", "bode"], ["plant", "tn-curve"], ["bench", "plant"], ["bench", "fpga"],
          ["verify", "current-loop", "--against", "rtl"], ["identify", "DATA"],
          ["identify-check"]]


@pytest.mark.parametrize("argv", NO_MCU, ids=" ".join)
def test_mcu_image_refused_where_no_mcu_runs(argv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "DATA").write_text("t,iq\n0,0\n")  # a file, so only the option is wrong
    code, out, err = _run([*argv, "--mcu-image", "law.elf"])
    line = _one_line(err)
    assert code == 2 and "--mcu-image" in line and "not an option" in line, line
    assert out == ""


def test_mcu_image_offered_where_the_mcu_runs():
    with_mcu = {p.prog for p in walk(build_parser())
                if any("--mcu-image" in a.option_strings for a in p._actions)}
    assert {"eha-hil run", "eha-hil bench stack", "eha-hil sweep",
            "eha-hil verify mcu"} <= with_mcu
    assert not with_mcu & {"eha-hil " + " ".join(a[:2] if a[0] != "identify" else a[:1])
                           for a in NO_MCU}


def test_unknown_option_is_named_not_its_value(tmp_path):
    code, _, err = _run(["log", "info", "-c", "x", str(tmp_path / "run.mcap")])
    line = _one_line(err)
    assert code == 2 and "argument -c:" in line and "run.mcap" not in line, line


# --- cut inputs: every reader the same way ---------------------------------------------------
CUT = re.compile(r"^eha-hil (log|replay|identify): (\S+): truncated: (.+); "
                 r"(read|replayed) up to (t = \d+\.\d{6} s|nothing)$")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("logs")
    # 0.5 s: two whole blocks of the frame log and a partial one (record.FLUSH_CYCLES), so
    # that the chunks before the cut hold whole MCU cycles to replay
    assert main(["bus", "run", "--seconds", "0.5", "--log", str(d / "r.mcap"),
                 "--capture", str(d / "r.pcapng")]) == 0
    for suffix in (".blf", ".asc", ".log"):
        assert main(["bus", "run", "--seconds", "0.3", "--transport", "can",
                     "--can-log", str(d / f"r{suffix}")]) == 0
    return {p.suffix: p for p in d.iterdir()}


@pytest.mark.parametrize("suffix", [".mcap", ".pcapng", ".blf", ".asc", ".log"])
@pytest.mark.parametrize("verb", ["log info", "replay"])
def test_cut_file_reported_the_same_way(verb, suffix, logs, tmp_path):
    whole = logs[suffix]
    code, _, err = _run([*verb.split(), str(whole)])
    assert code == 0 and not err.strip(), err
    cut = tmp_path / f"cut{suffix}"
    data = whole.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 5 + 3])  # inside a record, a block, a line
    side = Path(f"{whole}.eha-hil.json")  # a CAN log's metadata travels with it
    if side.is_file():
        Path(f"{cut}.eha-hil.json").write_bytes(side.read_bytes())
    code, out, err = _run([*verb.split(), str(cut)])
    line = _one_line(err)
    m = CUT.match(line)
    assert m and m.group(2) == str(cut), line
    assert code == 1, (code, line)
    assert out.strip()  # what was read is still reported


def test_cut_csv_reported_the_same_way(tmp_path):
    from hil.identify.csvdata import read_measured

    f = tmp_path / "d.csv"
    assert main(["identify-synth", str(f), "--seconds", "2"]) == 0
    text = f.read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(text[: len(text) - len(text.splitlines()[-1]) // 2 - 1])
    data = read_measured(cut)
    assert data.cut and "is cut" in data.cut
    assert data.n == read_measured(f).n - 1  # the partial row left out, nothing else
    assert read_measured(f).cut is None


# --- wrong diagnoses -------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".pcapng", ".blf"])
def test_replay_against_another_topology_names_the_mismatch(suffix, logs):
    code, out, err = _run(["replay", str(logs[suffix]), "--topology", "hydra_full"])
    line = _one_line(err)
    assert code == 2 and "divergence" not in out + err, (out, err)
    assert "is not that of topology hydra_full" in line and "LRW lad 0 len" in line
    if suffix == ".pcapng":  # its metadata names the run's topology
        assert "--topology bench_one_box" in line


# --- big inputs ------------------------------------------------------------------------------
def test_chunked_csv_reader_equals_the_line_by_line_one(tmp_path, monkeypatch):
    """The fast path (pandas per chunk) and the careful one give the same bits, also across
    chunk boundaries, blank lines, comments, empty and NA cells."""
    import hil.identify.csvdata as cd

    f = tmp_path / "d.csv"
    assert main(["identify-synth", str(f), "--seconds", "2"]) == 0
    lines = f.read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln.startswith("t,")][0]
    lines.insert(head + 500, "")
    lines.insert(head + 900, "# a comment among the rows")
    cells = lines[head + 3000].split(",")
    cells[1] = "NA"
    lines[head + 3000] = ",".join(cells)
    f.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(cd, "CHUNK_ROWS", 777)
    fast = cd.read_measured(f)
    monkeypatch.setattr(cd._DataRows, "_fast", lambda self, *a: None)
    slow = cd.read_measured(f)
    assert fast.n == slow.n and fast.notes == slow.notes
    assert np.array_equal(fast.t.view(np.int64), slow.t.view(np.int64))
    for k in slow.columns:
        assert np.array_equal(fast.columns[k].view(np.int64), slow.columns[k].view(np.int64))


def test_csv_mistake_still_named_by_line_and_cell(tmp_path, monkeypatch):
    import hil.identify.csvdata as cd

    f = tmp_path / "d.csv"
    assert main(["identify-synth", str(f), "--seconds", "2"]) == 0
    lines = f.read_text().splitlines()
    cells = lines[2000].split(",")
    cells[2] = "1.2.3"
    lines[2000] = ",".join(cells)
    f.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(cd, "CHUNK_ROWS", 500)
    with pytest.raises(cd.CsvError, match=r":2001: column '\w+': '1\.2\.3' is not a number"):
        cd.read_measured(f)


def test_long_csv_uses_the_first_rows_and_says_so(tmp_path):
    from hil.identify.csvdata import estimate_rows, read_measured

    f = tmp_path / "d.csv"
    assert main(["identify-synth", str(f), "--seconds", "4"]) == 0  # 20000 rows
    said: list[str] = []
    data = read_measured(f, max_rows=5000, progress=said.append)
    assert data.n == 5000
    assert any("used the first 5,000 of about" in n for n in data.notes), data.notes
    assert any("--max-rows limit" in s for s in said), said
    assert 19_000 < estimate_rows(f) < 21_000
    assert read_measured(f).n == 20000 and not read_measured(f).notes


def test_identify_refuses_up_front_what_cannot_fit(tmp_path, monkeypatch):
    """The size check: rows by the file's size, memory by the measured cost per row; too
    much for this machine is one line before the file is read."""
    import hil.cli.identify as icli

    f = tmp_path / "d.csv"
    assert main(["identify-synth", str(f), "--seconds", "2"]) == 0
    monkeypatch.setattr(icli, "BYTES_PER_ROW", 10**12)
    code, out, err = _run(["identify", str(f)])
    line = _one_line(err)
    assert code == 2 and "needs about" in line and "--max-rows" in line, line


def test_read_rss_is_bounded_by_max_rows(tmp_path):
    """Reading a file 20x longer than --max-rows holds only --max-rows rows (peak RSS of a
    child process, /usr/bin/time's measure, close to that of the short file)."""
    import shutil

    if not shutil.which("true"):
        pytest.skip("no coreutils")
    src = tmp_path / "d.csv"
    assert main(["identify-synth", str(src), "--seconds", "2"]) == 0  # 10000 rows
    lines = src.read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln.startswith("t,")][0] + 1
    body = [ln.split(",", 1)[1] for ln in lines[head:]]
    big = tmp_path / "big.csv"
    with big.open("w") as fh:
        fh.write("\n".join(lines[:head]) + "\n")
        for b in range(40):
            fh.write("".join(f"{(b * len(body) + i) / 5000:.12g},{r}\n"
                             for i, r in enumerate(body)))

    def peak_kb(path: Path) -> int:
        code = ("import resource, sys; from hil.identify.csvdata import read_measured; "
                f"d = read_measured({str(path)!r}, max_rows=10000); "
                "print(d.n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)")
        import sys

        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True).stdout.split()
        assert out[0] == "10000"
        return int(out[1])

    small, large = peak_kb(src), peak_kb(big)
    # the whole big file as Python floats would be ~ 400000 rows x 11 x 24 B = 100 MB more
    assert large < small + 40_000, (small, large)
