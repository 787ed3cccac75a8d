"""``eha-hil sweep``: one line and exit 2 for a mistake, the table and summary of a run,
exit 1 for a failing point, Ctrl-C then --resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil import scenarios
from hil.cli import main
from hil.scenarios import Metric, ScenarioResult
from hil.sweep import table
from hil.sweep.backends import BackendError, DaskCluster

ROOT = Path(__file__).resolve().parents[2]


def _code(argv: list[str]) -> int:
    """Exit code of ``eha-hil ARGV`` run in this process (argparse exits, verbs return)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


@pytest.mark.parametrize("argv, words", [
    (["f3", "--param", "mcu.kp_force=1:2"], ["--param", "START:STOP:COUNT"]),
    (["f3", "--param", "mcu.kp_forc=1,2"], ["--param mcu.kp_forc", "unknown key"]),
    (["f3", "--param", "mcu.kp_force=-1,2"], ["--param mcu.kp_force", "negative"]),
    (["f3", "--tolerance", "hydraulics.jp_kg=10%"], ["--samples"]),
    (["f3", "--seeds", "0..3", "--resume"], ["--resume", "--out"]),
    (["f3"], ["nothing to vary"]),
    # sizes refused before any value is made or checked (a count of 1e8 used to hang)
    (["f3", "--param", "mcu.kp_force=1:2:100000000"], ["COUNT 100000000", "points"]),
    (["f3", "--seeds", "0..100000000"], ["100000001 seeds", "points"]),
    (["f3", "--param", "mcu.kp_force=1:2:1001", "--seeds", "0..999"], ["1001000 points"]),
    (["thesis", "--seeds", "1,2"], ["one scenario"]),
    (["f33", "--seeds", "1,2"], ["unknown scenario"]),
    (["f3", "--seeds", "1,2", "--out", "x.txt"], ["--out", ".parquet"]),
    (["f3", "--seeds", "1,2", "--dask", "tcp://10.0.0.1:8786", "--workers", "2"],
     ["--workers", "its own workers"]),
])
def test_mistakes_are_one_line_and_exit_2(capsys, argv, words):
    code = _code(["sweep", *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    for w in words:
        assert w in err
    assert "Traceback" not in err


@pytest.mark.slow
def test_a_scheduler_that_does_not_answer_is_one_line():
    with pytest.raises(BackendError) as err:
        DaskCluster("tcp://127.0.0.1:9", timeout_s=0.5)
    assert str(err.value).startswith("--dask tcp://127.0.0.1:9: cannot connect")
    assert "\n" not in str(err.value)


@pytest.fixture
def fragile(monkeypatch):
    def run(cfg, progress=None):
        kp = cfg.get("mcu.kp_force")
        if kp >= 3.0:
            raise ValueError("unstable")
        return ScenarioResult("fragile", "test", [Metric("gain", kp, "N/N", "<= 1.5",
                                                         kp <= 1.5)])

    monkeypatch.setitem(scenarios.SCENARIOS, "fragile",
                        scenarios.Scenario("fragile", "raises at kp 3", run))


def test_a_run_writes_the_table_and_a_summary_from_it(tmp_path, capsys, fragile):
    out = tmp_path / "s.csv"
    code = main(["sweep", "fragile", "--param", "mcu.kp_force=1:2:3", "--workers", "1",
                 "--out", str(out), "--json"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    df = table.read(out)
    gain = data["summary"]["metrics"][0]
    assert gain["min"] == df["gain [N/N]"].min() == 1.0
    assert gain["max"] == df["gain [N/N]"].max() == 2.0
    assert gain["passed"] == int(df["gain: pass"].sum()) == 2
    assert gain["yield"] == pytest.approx(2 / 3)


@pytest.mark.slow
@pytest.mark.parametrize("options", [
    ["--param", "mcu.kp_force=1:2:3"],
    ["--param", "mcu.kp_force=1:2:3", "--param", "mcu.kd_force_s=0.001,0.002"],
    ["--tolerance", "mcu.kp_force=10%", "--samples", "6"],
    ["--param", "mcu.kd_force_s=0.001,0.002", "--tolerance", "mcu.kp_force=10%",
     "--samples", "3", "--seeds", "1,2"],
])
def test_plots_one_figure_per_metric_for_each_kind_of_sweep(tmp_path, capsys, fragile,
                                                            options):
    code = main(["sweep", "fragile", *options, "--workers", "1", "--json",
                 "--plot-dir", str(tmp_path)])
    assert code == 0
    assert [Path(p).name for p in json.loads(capsys.readouterr().out)["plots"]] == [
        "gain.png"]


def test_a_failing_point_exits_1_and_is_in_the_table(tmp_path, capsys, fragile):
    out = tmp_path / "s.parquet"
    code = main(["sweep", "fragile", "--param", "mcu.kp_force=1:3:3", "--workers", "1",
                 "--out", str(out)])
    assert code == 1
    text = capsys.readouterr().out
    assert "point 2 failed: ValueError: unstable" in text
    assert table.read(out)["error"].tolist() == ["", "", "ValueError: unstable"]


def test_min_yield_makes_a_missed_requirement_exit_1(capsys, fragile):
    argv = ["sweep", "fragile", "--param", "mcu.kp_force=1:2:3", "--workers", "1"]
    assert main([*argv, "--min-yield", "0.6"]) == 0   # 2 of 3 meet <= 1.5
    assert main([*argv, "--min-yield", "0.7"]) == 1
    assert "yield below 0.7: gain" in capsys.readouterr().out


@pytest.fixture
def slow_points(monkeypatch):
    """A scenario taking 20 ms a point (registered for the test)."""

    interrupted = []

    def run(cfg, progress=None):
        if cfg.get("sim.seed") == 5 and not interrupted:  # Ctrl-C in the sixth point, once
            interrupted.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.02)
        return ScenarioResult("slow", "test", [Metric("seed", cfg.get("sim.seed"), "")])

    monkeypatch.setitem(scenarios.SCENARIOS, "slow",
                        scenarios.Scenario("slow", "20 ms a point", run))


@pytest.mark.slow
def test_ctrl_c_then_resume_computes_the_rest(tmp_path, capsys, slow_points):
    out = tmp_path / "s.csv"
    argv = ["sweep", "slow", "--seeds", "0..59", "--workers", "1", "--out", str(out)]
    assert main(argv) == 130
    err = capsys.readouterr().err.strip().split("\n")[-1]
    assert err.startswith("eha-hil sweep: interrupted at ")
    assert f"journal {out}.points.jsonl closed and readable" in err
    journal = out.with_name(out.name + ".points.jsonl")
    done = len(journal.read_text().splitlines()) - 1
    assert done == 5
    assert main([*argv, "--resume", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["resumed"], data["computed"]) == (done, 60 - done)
    df = table.read(out)
    assert df["sim.seed"].tolist() == df["seed"].tolist() == list(range(60))


def _group_alive(pgid: int, wait_s: float) -> bool:
    """Whether a process of group ``pgid`` still runs after ``wait_s`` (zombies waiting for
    init to reap them do not count)."""
    import psutil

    deadline = time.monotonic() + wait_s
    while True:
        alive = [p for p in psutil.process_iter(["status"])
                 if _pgid(p.pid) == pgid and p.info["status"] != psutil.STATUS_ZOMBIE]
        if not alive or time.monotonic() > deadline:
            return bool(alive)
        time.sleep(0.1)


def _pgid(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except OSError:
        return None


@pytest.mark.slow
def test_ctrl_c_stops_the_pool_with_one_line(tmp_path):
    """SIGINT to the whole process group, as a terminal sends it: the workers ignore it,
    the sweep ends them, prints one line and exits 130."""
    out = tmp_path / "f3.parquet"
    cmd = [sys.executable, "-m", "hil.cli", "sweep", "f3", "--param",
           "mcu.kp_force=1.5:3.0:60", "--workers", "2", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
                            start_new_session=True)
    seen = ""
    while "sweep f3: 3/60" not in seen:  # a few points finished
        ch = proc.stderr.read(1)
        assert ch, seen
        seen += ch
    os.killpg(proc.pid, signal.SIGINT)
    err = seen + proc.stderr.read()
    assert proc.wait(timeout=60) == 130
    last = err.strip().split("\n")[-1]
    assert last.startswith("eha-hil sweep: interrupted at ")
    assert "Traceback" not in err
    assert not _group_alive(proc.pid, 10.0), "a worker outlived the sweep"
    done = len(out.with_name(out.name + ".points.jsonl").read_text().splitlines()) - 1
    assert 3 <= done < 60
