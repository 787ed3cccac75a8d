"""``--require``: the user's bound on a metric replaces the scenario's judgement."""

from __future__ import annotations

import argparse
import json

import pytest

from hil import scenarios
from hil.cli import main
from hil.scenarios import Metric, ScenarioResult
from hil.sweep import table
from hil.sweep.requirements import apply, parse_requirement


def test_parse():
    r = parse_requirement("-3 dB bandwidth >= 80")
    assert (r.metric, r.op, r.bound) == ("-3 dB bandwidth", ">=", 80.0)
    assert parse_requirement("RMS error, strain feedback<2.5").op == "<"
    for bad in ("bandwidth", "bandwidth>=x", "bandwidth=80", ">=80", "bw>=nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_requirement(bad)


def _record(value: float, ok: bool) -> dict:
    return {"point": 0, "metrics": [
        {"name": "bw", "value": value, "unit": "Hz", "requirement": "100 +/- 25", "ok": ok},
        {"name": "gain", "value": 1.0, "unit": "", "requirement": "", "ok": None}],
        "ok": ok, "error": ""}


def test_a_bound_replaces_the_scenarios_judgement():
    recs = [_record(150.0, False), _record(70.0, False), _record(float("nan"), False)]
    out = apply(recs, [parse_requirement("bw>=80"), parse_requirement("bw<=160")])
    assert [r["metrics"][0]["ok"] for r in out] == [True, False, False]
    assert [r["ok"] for r in out] == [True, False, False]
    assert out[0]["metrics"][0]["requirement"] == ">= 80 and <= 160 (--require)"
    assert recs[0]["metrics"][0]["ok"] is False  # the records themselves are left alone
    # A metric the scenario left unjudged can be judged.
    assert apply(recs, [parse_requirement("gain>1")])[0]["metrics"][1]["ok"] is False
    with pytest.raises(ValueError, match="no such metric"):
        apply(recs, [parse_requirement("bandwidth>=80")])


def test_a_finished_sweep_is_judged_again_without_computing(tmp_path, capsys, monkeypatch):
    def run(cfg, progress=None):
        kp = cfg.get("mcu.kp_force")
        return ScenarioResult("gains", "test", [Metric("gain", kp, "N/N", "<= 1.5",
                                                       kp <= 1.5)])

    monkeypatch.setitem(scenarios.SCENARIOS, "gains", scenarios.Scenario("gains", "", run))
    argv = ["sweep", "gains", "--param", "mcu.kp_force=1:3:5", "--workers", "1", "--out",
            str(tmp_path / "g.parquet"), "--json"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)["summary"]["metrics"][0]
    assert first["passed"] == 2
    assert main([*argv, "--resume", "--require", "gain>=2"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["computed"] == 0
    assert data["summary"]["metrics"][0]["passed"] == 3
    df = table.read(tmp_path / "g.parquet")
    assert df["gain: pass"].tolist() == [v >= 2 for v in df["gain [N/N]"]]
