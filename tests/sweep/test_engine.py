"""A sweep's run: resume after an interruption, a failing point, the journal."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from hil import scenarios
from hil.scenarios import Metric, ScenarioResult
from hil.sweep import table
from hil.sweep.backends import Serial
from hil.sweep.engine import lost_record, run_sweep
from hil.sweep.journal import Journal, JournalError
from hil.sweep.point import evaluate
from hil.sweep.space import build_plan, parse_param
from hil.sweep.summary import summarise
from plant.config import load_config

SCENARIO = "f3"  # ~50 ms a point on the full stack


@pytest.fixture(scope="module")
def thesis_cfg():
    return load_config("hydra_thesis")


@pytest.fixture(scope="module")
def plan(thesis_cfg):
    return build_plan(thesis_cfg, [parse_param("mcu.kp_force=1.5:3.0:3"),
                                   parse_param("mcu.kd_force_s=0.004,0.0055")])


@pytest.fixture(scope="module")
def uninterrupted(thesis_cfg, plan):
    out = run_sweep(SCENARIO, thesis_cfg, plan, Serial())
    return table.frame(plan, out.records)


def test_resume_computes_only_the_rest_and_gives_the_same_table(tmp_path, thesis_cfg, plan,
                                                                uninterrupted):
    path = tmp_path / "f3.points.jsonl"
    k = 2

    def stop_after_k(record, prog):
        if prog.computed == k:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(SCENARIO, thesis_cfg, plan, Serial(), Journal(path), on_point=stop_after_k)
    assert len(path.read_text().splitlines()) == 1 + k  # header + the finished points
    with path.open("a") as f:
        f.write('{"point": 5, "metrics": [')  # a line the stop cut short
    out = run_sweep(SCENARIO, thesis_cfg, plan, Serial(), Journal(path), resume=True)
    assert (out.resumed, out.computed) == (k, len(plan.points) - k)
    resumed = table.frame(plan, out.records)
    pd.testing.assert_frame_equal(resumed, uninterrupted)
    # Resuming a finished sweep computes nothing and still gives the table.
    again = run_sweep(SCENARIO, thesis_cfg, plan, Serial(), Journal(path), resume=True)
    assert again.computed == 0
    pd.testing.assert_frame_equal(table.frame(plan, again.records), uninterrupted)


def test_a_journal_of_another_sweep_is_refused(tmp_path, thesis_cfg, plan):
    path = tmp_path / "j.points.jsonl"
    other = build_plan(thesis_cfg, [parse_param("mcu.kp_force=1,2")])
    j = Journal(path)
    j.start(other.fingerprint(SCENARIO, thesis_cfg), SCENARIO, 2, resume=False)
    j.close()
    with pytest.raises(JournalError, match="another sweep"):
        run_sweep(SCENARIO, thesis_cfg, plan, Serial(), Journal(path), resume=True)


def test_tables_write_and_read_back_equal(tmp_path, uninterrupted):
    for name in ("t.parquet", "t.csv"):
        table.write(uninterrupted, tmp_path / name)
        back = table.read(tmp_path / name)
        pd.testing.assert_frame_equal(back, uninterrupted, check_dtype=False)


@pytest.fixture
def fragile(monkeypatch):
    """A scenario that raises when the force gain is above 2 (registered for the test)."""

    def run(cfg, progress=None):
        kp = cfg.get("mcu.kp_force")
        if kp > 2.0:
            raise FloatingPointError(f"gain {kp} diverged")
        return ScenarioResult("fragile", "test", [
            Metric("gain", kp, "N/N", "<= 1.5", kp <= 1.5), Metric("twice", 2 * kp, "")])

    monkeypatch.setitem(scenarios.SCENARIOS, "fragile",
                        scenarios.Scenario("fragile", "raises above kp 2", run))
    return "fragile"


def test_a_failing_point_is_recorded_and_the_sweep_finishes(tmp_path, default_cfg, fragile):
    plan = build_plan(default_cfg, [parse_param("mcu.kp_force=1,1.5,2,2.5,3")])
    path = tmp_path / "j.points.jsonl"
    out = run_sweep(fragile, default_cfg, plan, Serial(), Journal(path))
    df = table.frame(plan, out.records)
    assert list(df["error"] != "") == [False, False, False, True, True]
    assert df.loc[3, "error"] == "FloatingPointError: gain 2.5 diverged"
    assert df["gain [N/N]"].isna().tolist() == [False, False, False, True, True]
    assert df["gain: pass"].tolist() == [True, True, False, pd.NA, pd.NA]
    s = summarise(df, out.records)
    assert s.errors == 2
    gain = s.metrics[0]
    assert (gain.min, gain.max, gain.passed) == (1.0, 2.0, 2)
    assert gain.yield_ == pytest.approx(2 / 5)  # failed points count against the yield
    # The journal holds the failures too: a resume does not run them again.
    recs = [json.loads(x) for x in path.read_text().splitlines()[1:]]
    assert sorted(r["point"] for r in recs if r["error"]) == [3, 4]


def test_a_point_the_backend_lost_is_run_again_on_resume(tmp_path, default_cfg, fragile):
    plan = build_plan(default_cfg, [parse_param("mcu.kp_force=1,1.5,2")])
    path = tmp_path / "j.points.jsonl"

    def loses_point_1(task):  # as a backend reports a worker that died
        return lost_record(task, "worker process died") if task.point.index == 1 \
            else evaluate(task)

    first = run_sweep(fragile, default_cfg, plan, Serial(), Journal(path), fn=loses_point_1)
    assert first.records[1]["error"] == "lost: worker process died"
    again = run_sweep(fragile, default_cfg, plan, Serial(), Journal(path), resume=True)
    assert (again.resumed, again.computed) == (2, 1)
    assert [r["error"] for r in again.records] == ["", "", ""]


def test_a_grid_with_repeats_has_a_yield_per_grid_point(default_cfg, monkeypatch):
    def run(cfg, progress=None):
        x = cfg.get("mcu.kp_force") + 0.1 * cfg.get("sim.seed")
        return ScenarioResult("noisy", "test", [Metric("x", x, "", "<= 1.15", x <= 1.15)])

    monkeypatch.setitem(scenarios.SCENARIOS, "noisy", scenarios.Scenario("noisy", "", run))
    plan = build_plan(default_cfg, [parse_param("mcu.kp_force=1,2")], seeds=(0, 1, 2, 3))
    out = run_sweep("noisy", default_cfg, plan, Serial())
    df = table.frame(plan, out.records)
    s = summarise(df, out.records, ["mcu.kp_force"])
    assert [c.values for c in s.cells] == [{"mcu.kp_force": 1.0}, {"mcu.kp_force": 2.0}]
    assert [(c.points, c.passed) for c in s.cells] == [(4, 2), (4, 0)]
    lo, med, hi = s.cells[0].spread["x"]
    assert (lo, hi) == (1.0, pytest.approx(1.3)) and med == pytest.approx(1.15)
    assert summarise(df, out.records).cells == []  # without the grid's keys: none
