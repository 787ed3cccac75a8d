"""The judge of ``eha-hil identify-check`` (hil.identify.rigcheck): what counts as right."""

from __future__ import annotations

import pytest

from hil.identify.rigcheck import Case, CaseResult, default_cases, judge, markdown

COULOMB = Case("fixed_piston", ("pump_coulomb_friction",))
TRUTH = {"pump_coulomb_friction": {"force_n": 80.0, "eps_m_per_s": 3e-4}}


@pytest.mark.parametrize("found,unexplained,right,why", [
    ({"pump_coulomb_friction": {"force_n": 79.0}}, False, True, "ok"),
    ({"pump_coulomb_friction": {"force_n": 70.0}}, False, False, "-12 %"),  # beyond 10 %
    ({}, False, False, "missed pump_coulomb_friction"),
    ({"pump_coulomb_friction": {"force_n": 80.0}, "input_delay": {"delay_s": 1e-4}}, False,
     False, "added input_delay"),
    ({"pump_coulomb_friction": {"force_n": 80.0}}, True, False, "verdict unexplained"),
    ({"pump_coulomb_friction": {"force_n": float("nan")}}, False, False, "nan"),
])
def test_library_effect_judged(found, unexplained, right, why):
    ok, text, mags = judge(COULOMB, TRUTH, found, unexplained)
    assert ok is right and why in text
    assert mags[0][:2] == ("pump_coulomb_friction.force_n", 80.0)


def test_amplitudes_get_twenty_percent():
    case = Case("fixed_piston", ("pump_pulsation",))
    truth = {"pump_pulsation": {"amplitude": 0.02, "torque_n": 150.0}}
    ok, _, _ = judge(case, truth, {"pump_pulsation": {"amplitude": 0.0235,
                                                      "torque_n": 125.0}}, False)
    assert ok  # +17.5 % and -17 %: inside the amplitude tolerance
    ok, why, _ = judge(case, truth, {"pump_pulsation": {"amplitude": 0.025,
                                                        "torque_n": 150.0}}, False)
    assert not ok and "amplitude" in why


def test_outside_effect_must_be_unexplained_with_nothing_added():
    case = Case("fixed_piston", ("hose_viscoelastic",))
    assert judge(case, {}, {}, True)[0]
    assert not judge(case, {}, {}, False)[0]
    assert not judge(case, {}, {"pump_coulomb_friction": {"force_n": 5.0}}, True)[0]


def test_matrix_covers_what_must_be_shown():
    cases = default_cases()
    from hil.identify.rig import LIBRARY_EFFECTS, OUTSIDE_EFFECTS

    alone = {c.effects[0] for c in cases if len(c.effects) == 1}
    assert set(LIBRARY_EFFECTS) <= alone  # each library effect alone
    assert alone & set(OUTSIDE_EFFECTS)  # an effect outside the library
    assert any(len(c.effects) == 2 for c in cases)  # two at once
    assert {c.load for c in cases if not c.effects} == {"fixed_piston", "free_piston",
                                                         "conrod_fixed"}  # null on each load
    loads = {"fixed_piston", "free_piston", "conrod_fixed"}
    for n in (2, 3):  # two and three effects at once on each load
        assert {c.load for c in cases if len(c.effects) == n} == loads, n
    # rigs 0.25x-4x off the preset on each load, with and without a library effect
    for with_effect in (False, True):
        assert {c.load for c in cases if c.scale and bool(c.effects) == with_effect} == loads
    assert {f for c in cases for _, f in c.scale} >= {0.25, 4.0}
    # Maxwell corners from 0.5 to 30 Hz (30 Hz: the rig's default)
    corners = {dict((k, v) for _, k, v in c.magnitudes).get("corner_hz", 30.0)
               for c in cases if c.effects == ("hose_viscoelastic",)}
    assert min(corners) <= 0.5 and max(corners) >= 30.0


def test_markdown_table_rows_and_tally():
    rows = [CaseResult(COULOMB, 1, True, "ok", ["pump_coulomb_friction"],
                       ["pump_coulomb_friction"], False,
                       magnitudes=[("pump_coulomb_friction.force_n", 80.0, 79.9)]),
            CaseResult(Case("fixed_piston"), 2, False, "added input_delay", [],
                       ["input_delay"], False)]
    rows[1].cpu_s = 12.6
    text = markdown(rows)
    lines = text.splitlines()
    assert lines[2].startswith("| fixed_piston: pump_coulomb_friction | 1 | force_n 80 / 79.9")
    assert "**no**: added input_delay" in lines[3] and lines[3].endswith("| 13 |")
    assert lines[-1].startswith("1 of 2 right")


def test_an_absorbed_maxwell_branch_is_judged_by_the_equivalent_spring():
    """A Maxwell branch with its corner below the band is a stiffer spring wherever the data
    pin k_s: right is `explained` with k_s at k_s + k_m, not a free pass."""
    low = [c for c in default_cases() if c.absorbed]
    assert low and all(c.effects == ("hose_viscoelastic",) for c in low)
    assert all(dict((k, v) for _, k, v in c.magnitudes)["corner_hz"] < 1.0 for c in low)
    # the corners of 3 Hz and up keep the strict rule
    assert any(c.effects == ("hose_viscoelastic",) and not c.absorbed for c in default_cases())
    from hil.identify.rigcheck import equivalent_parameters

    case = low[0]
    truth = {"hose_viscoelastic": {"k_m_n_per_m": 1.0e7, "corner_hz": 0.5}}
    eq = equivalent_parameters(case, truth, {"ks": 2.0e7})
    assert eq == {"ks": 3.0e7}
    assert judge(case, truth, {}, False, eq, {"ks": 3.05e7})[0]
    ok, why, _ = judge(case, truth, {}, False, eq, {"ks": 2.0e7})  # the branch not absorbed
    assert not ok and "equivalent" in why
    ok, why, _ = judge(case, truth, {}, True, eq, {"ks": 3.0e7})
    assert not ok and "unexplained" in why
    assert not judge(case, truth, {}, False, eq, {})[0]  # k_s held: nothing to compare
    assert not judge(case, truth, {"pump_coulomb_friction": {"force_n": 5.0}}, False, eq,
                     {"ks": 3.0e7})[0]


def test_rows_file_holds_each_case_as_it_is_judged(tmp_path, monkeypatch, capsys):
    """``--rows``: a JSON line per case written when the case is judged, so a run stopped
    part way keeps its rows; here the run stops after the first of two."""
    import json

    import hil.identify.rigcheck as rigcheck
    from hil.cli import main

    def two_then_stop(cases, seeds, jobs=1, progress=None):
        res = CaseResult(cases[0], seeds[0], True, "ok", [], [], False, cpu_s=2.5)
        progress(res, 1, 2)
        raise KeyboardInterrupt

    monkeypatch.setattr(rigcheck, "run_matrix", two_then_stop)
    out = tmp_path / "rows.jsonl"
    code = main(["identify-check", "--case", "fixed_piston: null", "--seeds", "3",
                 "--rows", str(out)])
    assert code != 0
    lines = out.read_text(encoding="utf-8").splitlines()
    assert [json.loads(x)["case"] for x in lines] == ["fixed_piston: null"]
    assert json.loads(lines[0])["seed"] == 3 and json.loads(lines[0])["cpu_s"] == 2.5
