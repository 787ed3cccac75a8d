"""Decisions of the identification loop that send a fit to another start: a linear parameter
whose configured value beats the fit's own (the fit sits behind a hump along it), a joint
set whose refit shrank some members to nothing (the rest is tried alone), the first joint
set that passes taken, held parameters freed again and not kept where that made the fit
worse, and a round on an unchanged fit reusing the last round's score tests."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify import candidates, pipeline
from hil.identify.consistency import Consistency, ParameterSplit, PartEstimate
from hil.identify.effects import EFFECTS, library
from hil.identify.experiment import prepare
from hil.identify.fit import FitResult
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def _fit_at(model: FastModel, theta: np.ndarray, free: list[str]) -> FitResult:
    """A fit result at ``theta`` (weights: its own residual rms per channel)."""
    out = model.outputs(theta)
    exp = model.exp
    sigma = {c: float(np.sqrt(np.nanmean((exp.measured[c] - out[c])[exp.est] ** 2)))
             for c in exp.channels}
    return FitResult(theta, free, {}, sigma, out, np.zeros((1, 1)))


@pytest.fixture(scope="module")
def free_piston_loop():
    """A loop on a short free-piston record with the rig's own linear parameters as its
    fit (no baseline fit: only the probes are under test)."""
    rig = generate_rig("free_piston", seconds=0.6, seed=2)
    exp = prepare(rig.data, load_config("hydra_default"), "bl")
    model = FastModel(exp)
    theta = model.start_vector()
    truth = rig.truth["parameters"]
    free = ["gain_n_per_a", "ds", "dc", "ks", "jp", "jc"]
    for name in free:
        theta[IDX[name]] = truth[name]
    loop = object.__new__(pipeline._Loop)
    loop.model, loop.exp, loop.configured = model, exp, model.start_vector()
    return loop, theta, free


def test_configured_value_that_beats_the_fit_is_named(free_piston_loop):
    """At the rig's own parameters no configured value fits better; with J_p moved to 1.6x
    the configured J_p (within 15 % of the rig's) does, and only J_p is named."""
    loop, theta, free = free_piston_loop
    loop.current = _fit_at(loop.model, theta, free)
    assert loop.better_configured() == []
    off = theta.copy()
    off[IDX["jp"]] *= 1.6
    loop.current = _fit_at(loop.model, off, free)
    assert loop.better_configured() == ["jp"]


def test_a_set_with_a_shrunk_member_leaves_the_rest():
    """A pump friction at its size beside a pulsation shrunk to a hundredth of its realistic
    size: the pulsation is the shrunk one; both at their sizes: none is."""
    exp = prepare(generate_rig("free_piston", seconds=0.2, seed=1).data,
                  load_config("hydra_default"), "bl")
    defs = {d.label: d for name in ("pump_coulomb_friction", "pump_pulsation")
            for d in EFFECTS[name].definitions(exp)}
    pair = [defs["pump_coulomb_friction"], defs["pump_pulsation[order=3]"]]
    theta = np.zeros(len(IDX))
    theta[IDX["pc_force_n"]] = 80.0
    theta[IDX["puls3_flow_s"]] = 1e-4
    theta[IDX["puls3_torque_c"]] = -0.5
    fit = FitResult(theta, [], {}, {}, {}, np.zeros((1, 1)))
    assert [d.label for d in pipeline._shrunk(pair, fit)] == ["pump_pulsation[order=3]"]
    theta[IDX["puls3_torque_c"]] = -20.0
    assert pipeline._shrunk(pair, fit) == []


def _stub_loop(sets_pass: dict[tuple[str, ...], float]):
    """A loop whose joint refits are stubs: each set in ``sets_pass`` passes with that
    validation cost, any other is refused; records the sets refitted."""
    loop = object.__new__(pipeline._Loop)
    loop.added, loop.added_labels, loop.excluded = [], set(), set()
    loop.joint_rows, loop.held, loop.say = [], {}, lambda msg: None
    loop.rounds = [[]]
    loop.structure = lambda: ("residual structure", "")
    loop.restart_far = lambda: False
    loop.tests_for_sets = lambda: loop.rounds  # the pool is stubbed below
    loop.freed_at = None
    loop.current = FitResult(np.zeros(len(IDX)), [], {}, {}, {}, np.zeros((1, 1)))
    loop.exp = None
    loop.sigma_ref = {}
    refitted = []

    def refit_set(labels, before):
        refitted.append(tuple(labels))
        cost = sets_pass.get(tuple(labels))
        why = "" if cost is not None else "refit lowered the validation cost by less than 0.5%"
        return loop.current, {}, cost or before, (cost or before) / before - 1.0, why

    added = []
    loop.refit_set = refit_set
    loop.add_set = lambda labels, new, held_now: added.append(tuple(labels))
    return loop, refitted, added


def test_joint_takes_the_first_set_that_passes(monkeypatch):
    """Pairs in the pool's order (best-supported first): the first that passes is added and
    no later set is refitted, even one that would pass with a lower validation cost (the
    choice among near-equal refits hung on their last bits, at a refit per set)."""
    monkeypatch.setattr(pipeline, "_joint_pool", lambda rounds, defs, added: ["a", "b", "c"])
    monkeypatch.setattr(pipeline, "_single_pool", lambda *args: [])
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: 100.0)
    loop, refitted, added = _stub_loop({("a", "b"): 60.0, ("a", "c"): 40.0})
    loop.defs_all = {k: candidates.EffectDef(k, k, (), (), "") for k in "abc"}
    loop.joint(6)
    assert added == [("a", "b")]
    assert refitted == [("a", "b")]
    # the first pair refused: the next one in order is tried and taken
    loop, refitted, added = _stub_loop({("a", "c"): 40.0, ("b", "c"): 30.0})
    loop.defs_all = {k: candidates.EffectDef(k, k, (), (), "") for k in "abc"}
    loop.joint(6)
    assert added == [("a", "c")] and refitted == [("a", "b"), ("a", "c")]


def test_joint_ranks_its_sets_by_the_tests_at_the_robust_start(monkeypatch):
    """The pool is ranked from :meth:`~hil.identify.pipeline._Loop.tests_for_sets`, not from
    the rounds alone: a candidate the rounds found not excited and the test at the robust
    start found significant is in the first pair (free piston, both frictions under the
    multisine, rig seed 1: the pump friction never entered a set)."""
    from hil.identify.candidates import CandidateTest

    def test(label, status, p=1.0, share=0.0):
        return CandidateTest(label=label, name=label, params=[], status=status, p_holm=p,
                             share_val=share)

    monkeypatch.setattr(pipeline, "_single_pool", lambda *args: [])
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: 100.0)
    loop, refitted, added = _stub_loop({("a", "b"): 60.0})
    loop.defs_all = {k: candidates.EffectDef(k, k, (), (), "") for k in "abc"}
    loop.rounds = [[test("a", "tested", 1e-8, 0.2), test("b", "not_excited"),
                    test("c", "tested", 1.0, 1e-4)]]
    loop.tests_for_sets = lambda: [*loop.rounds, [test("b", "tested", 1e-6, 0.1)]]
    loop.joint(6)
    assert refitted[0] == ("a", "b") and added == [("a", "b")]


def _split(name: str, bad: bool) -> ParameterSplit:
    parts = [PartEstimate("low", 1.0, 0.9, 1.1), PartEstimate("high", 1.3, 1.2, 1.4)]
    return ParameterSplit(name, "frequency", parts, 30.0, 1, 1e-7, 1e-7 if bad else 0.5,
                          (0, 1), 1.3)


def test_freed_parameters_kept_only_where_they_explain_the_record(monkeypatch,
                                                                   free_piston_loop):
    """The fit with held parameters freed again is not kept where its validation cost is
    higher, where its residual still has structure, or where a parameter disagrees between
    parts of the record; it is kept where it costs no more and explains the record."""
    loop, theta, free = free_piston_loop
    before = _fit_at(loop.model, theta, free)
    off = theta.copy()
    off[IDX["ks"]] *= 3.0
    worse = _fit_at(loop.model, off, free)
    loop.sigma_ref = before.sigma
    loop.est_mask = loop.exp.est
    loop.noisy_model = None
    loop.current = worse
    assert "validation cost rises" in loop.worse_than(before)
    structure = {"left": True}
    monkeypatch.setattr(pipeline, "_verdict", lambda analysis: (
        structure["left"], "residual structure no candidate explains: p_cyl_a-p_cyl_b"))
    splits = {"ks": [_split("ks", True)]}
    monkeypatch.setattr(pipeline, "consistency",
                        lambda fit, exp, mask: Consistency(splits["ks"]))
    loop.current = before
    assert loop.worse_than(worse).startswith("it still leaves residual structure")
    structure["left"] = False
    loop._analyses = loop._agreements = ()  # the judges changed under the same fit
    assert loop.worse_than(worse).startswith("it still leaves parameters disagree")
    splits["ks"] = [_split("ks", False)]
    loop._analyses = loop._agreements = ()
    assert loop.worse_than(worse) == ""


def test_a_round_on_an_unchanged_fit_reuses_the_tests():
    """The score tests of a round whose fit is the last round's (its candidate refused at
    the refit) are the last round's for the candidates left, Holm's correction redone over
    those: the same as testing them again, bit for bit."""
    rig = generate_rig("fixed_piston", ["pump_pulsation", "pump_coulomb_friction"],
                       seconds=0.5, seed=1)
    exp = prepare(rig.data, load_config("hydra_default"), "bl")
    model = FastModel(exp)
    theta = model.start_vector()
    free = ["ds", "dp", "ks"]
    fit = _fit_at(model, theta, free)
    mask = pipeline.OutputErrorFit(model).fit_mask()
    residual = {c: exp.measured[c] - fit.outputs[c] for c in exp.channels}
    defs = library(exp)

    def fresh(ds_):
        return candidates.test_candidates(ds_, model.outputs, theta, IDX, exp, fit.sigma,
                                          residual, mask, exp.val, free, states=model.states)

    first = fresh(defs)
    best = candidates.rank(first)[0]
    best.selected = True
    rest = [d for d in defs if d.label != best.label]
    again = candidates.retested(first, rest)
    ref = fresh(rest)
    assert sum(t.status == "tested" for t in ref) >= 3
    assert [(t.label, t.status, t.p_holm, t.share_val, t.selected) for t in again] == [
        (t.label, t.status, t.p_holm, t.share_val, t.selected) for t in ref]
    # Holm's correction is the subset's, not the round's it came from
    moved = [t for t in again if t.status == "tested"]
    assert any(t.p_holm != next(u for u in first if u.label == t.label).p_holm
               for t in moved)


def test_joint_search_runs_only_where_the_verdict_finds_structure(monkeypatch,
                                                                  free_piston_loop):
    """The joint search is gated by the verdict's own judge on the fit as it stands: where
    the residual is white and the parameters agree between parts of the record no set is
    refitted and the report says why; where the judge finds structure (in the residual, or
    as a parameter that disagrees between parts) the sets are refitted and the report names
    the structure (free piston, seal friction and pulsation under slide, rig seed 3: both
    effects in, explained, and 45 s of CPU went to refused pairs and the triple)."""
    loop, theta, free = free_piston_loop
    monkeypatch.setattr(pipeline, "_joint_pool", lambda rounds, defs, added: ["a", "b"])
    monkeypatch.setattr(pipeline, "_single_pool", lambda *args: [])
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: 100.0)
    monkeypatch.setattr(pipeline, "analyse", lambda *args: None)
    verdict = {"left": False}
    monkeypatch.setattr(pipeline, "_verdict", lambda analysis: (
        (True, "residual structure no candidate explains: p_cyl_a") if verdict["left"]
        else (False, "")))
    splits = {"ks": []}
    monkeypatch.setattr(pipeline, "consistency",
                        lambda fit, exp, mask: Consistency(splits["ks"]))

    def run():
        stub, refitted, added = _stub_loop({})
        del stub.structure  # the loop's own judge, not the stub's
        stub.model, stub.exp, stub.est_mask = loop.model, loop.exp, loop.exp.est
        stub.noisy_model = None
        stub.current = _fit_at(loop.model, theta, free)
        stub.defs_all = {k: candidates.EffectDef(k, k, (), (), "") for k in "ab"}
        stub.joint(6)
        return stub.joint_why, refitted

    why, refitted = run()
    assert refitted == [] and why.startswith("not run: the fit explains the record")
    verdict["left"] = True
    why, refitted = run()
    assert refitted == [("a", "b")] and "p_cyl_a" in why
    verdict["left"] = False
    splits["ks"] = [_split("ks", True)]
    why, refitted = run()
    assert refitted == [("a", "b")] and "parameters disagree" in why


def test_held_parameters_are_freed_before_the_joint_search(monkeypatch):
    """Structure left (in the residual, or as parameters that disagree between parts of the
    record): the held parameters are freed first, and where that explains the record no set
    is refitted (free piston, seal friction and pulsation under slide, rig seed 3: 45 s of
    refused sets before the freed refit that explained it). Freed and not kept: the sets are
    refitted, and the same fit is not freed again at the end."""
    monkeypatch.setattr(pipeline, "_joint_pool", lambda rounds, defs, added: ["a", "b"])
    monkeypatch.setattr(pipeline, "_single_pool", lambda *args: [])
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: 100.0)

    def run(left: tuple[str, str], explains: bool):
        loop, refitted, added = _stub_loop({})
        loop.defs_all = {k: candidates.EffectDef(k, k, (), (), "") for k in "ab"}
        loop.structure = lambda: left
        tried = []

        def free():
            tried.append(loop.current)
            return explains

        loop._free_held_again = free
        loop.joint(6)
        loop.free_held_again()  # the last step of the loop
        return loop.joint_why, refitted, len(tried)

    for left in [("", "parameters disagree between parts of the record: J_c"),
                 ("residual structure no candidate explains: omega_m", "")]:
        why, refitted, tried = run(left, explains=True)
        assert refitted == [] and tried == 1 and "freed again explains" in why
        why, refitted, tried = run(left, explains=False)
        assert refitted == [("a", "b")] and tried == 1 and left[0] + left[1] in why
    # nothing left: neither the sets nor (in the joint step) the freeing
    why, refitted, tried = run(("", ""), explains=True)
    assert refitted == [] and why.startswith("not run: the fit explains")


def test_a_fit_is_judged_once(monkeypatch, free_piston_loop):
    """The residual analysis and the consistency of a fit are computed once however many
    steps ask (the freed refit's run-on, its keeping, the report), and again for another
    fit."""
    loop, theta, free = free_piston_loop
    calls = []
    monkeypatch.setattr(pipeline, "analyse", lambda *args: calls.append("analyse"))
    monkeypatch.setattr(pipeline, "_verdict", lambda analysis: (False, ""))
    monkeypatch.setattr(pipeline, "consistency",
                        lambda fit, exp, mask: calls.append("consistency") or Consistency([]))
    loop.noisy_model, loop.est_mask = None, loop.exp.est
    loop._analyses = loop._agreements = ()
    loop.current = _fit_at(loop.model, theta, free)
    assert loop.structure_left() == "" and loop.structure_left() == ""
    assert calls == ["analyse", "consistency"]
    first = loop.current
    loop.current = _fit_at(loop.model, theta, free)
    loop.structure()
    assert calls == ["analyse", "consistency"] * 2
    loop.current = first  # a fit judged before, as the report does where freeing was not kept
    loop.structure()
    assert calls == ["analyse", "consistency"] * 2
