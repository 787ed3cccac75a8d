"""``eha-hil identify-check --json``: each row carries what the table shows and why a
verdict is ``unexplained``. The identification is stubbed (a report object with the fields
the judge reads), so the rows go through the real judge and the real command in well under
a second."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

import hil.identify.pipeline as pipeline
import hil.identify.rigcheck as rigcheck
from hil.cli import main
from hil.identify.rigcheck import Case, identify_and_judge

DETAIL = "p_pump_a: residual not white, 50.0 Hz line left (3.1 % of the output)"


def _report(unexplained: bool) -> SimpleNamespace:
    """The parts of an :class:`~hil.identify.pipeline.IdentifyReport` the judge reads."""
    return SimpleNamespace(effects_added=[], final={}, held={}, unexplained=unexplained,
                           unexplained_detail=DETAIL if unexplained else "white residual")


def _judged(case: Case, unexplained: bool, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(pipeline, "identify", lambda data, cfg: _report(unexplained))
    monkeypatch.setattr(rigcheck, "report_digest", lambda rep: "0" * 16)
    rig = SimpleNamespace(data=None, truth={"effects": {e: {} for e in case.effects},
                                            "parameters": {}})
    return identify_and_judge(case, 1, rig, cfg=None, t0=0.0, c0=0.0)


def test_an_unexplained_row_says_why(monkeypatch):
    row = _judged(Case("conrod_fixed", ("mains_hum",)), True, monkeypatch).as_dict()
    assert row["verdict"] == "unexplained" and row["right"]
    assert row["unexplained_detail"] == DETAIL


def test_an_explained_row_has_no_reason(monkeypatch):
    row = _judged(Case("fixed_piston"), False, monkeypatch).as_dict()
    assert row["verdict"] == "explained" and row["unexplained_detail"] == ""


def test_json_rows_carry_the_tables_columns_and_the_reason(monkeypatch, capsys):
    """Through the command: the printed JSON row of an unexplained case has the verdict
    column of the table and the report's reason, not empty."""

    def judged_matrix(cases, seeds, jobs=1, progress=None):
        return [_judged(c, True, monkeypatch) for c in cases for _ in seeds]

    monkeypatch.setattr(rigcheck, "run_matrix", judged_matrix)
    code = main(["identify-check", "--case", "conrod_fixed: mains_hum", "--seeds", "1",
                 "--json"])
    rows = json.loads(capsys.readouterr().out)
    assert code == 0, rows
    (row,) = rows
    assert row["case"] == "conrod_fixed: mains_hum" and row["verdict"] == "unexplained"
    assert row["unexplained_detail"] == DETAIL
