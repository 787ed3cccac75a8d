"""The run-on of the refit that frees held parameters: made only where its short part took a
material share of the residual structure off (a descent on its way), not where it moved the
freed parameters without touching it; and the measure of that structure itself."""

from __future__ import annotations

import numpy as np

from hil.identify import pipeline
from hil.identify.fit import FitResult
from hil.identify.residuals import ChannelResidual, ResidualAnalysis


def _channel(name: str, white: bool, predictable: float = 0.0, floor: float = 0.0,
             judged: bool = True) -> ChannelResidual:
    e = np.zeros(1)
    return ChannelResidual(name, 1.0, e, 0, 0.0, 1.0, e, 0, judged, white=white,
                           floor_ratio=floor, predictable_share=predictable)


def _analysis(*channels: ChannelResidual) -> ResidualAnalysis:
    return ResidualAnalysis({c.channel: c for c in channels}, False, 100, 0.1)


def _fit() -> FitResult:
    return FitResult(np.zeros(3), [], {}, {}, {}, np.zeros((1, 1)))


def test_excess_is_the_worst_judged_channel_in_units_of_the_verdicts_limits():
    a = _analysis(_channel("p_cyl_a-p_cyl_b", False, predictable=0.30),
                  _channel("v_piston", False, floor=15.6),
                  _channel("p_pump_a", False, predictable=0.99, judged=False),
                  _channel("omega_m", True, predictable=0.3, floor=0.99))
    assert pipeline.structure_excess(a) == 30.0  # 30 % over the 1 % limit beats 15.6 floors
    a = _analysis(_channel("v_piston", False, floor=15.6),
                  _channel("p_cyl_a-p_cyl_b", False, predictable=0.005))  # below the limit
    assert pipeline.structure_excess(a) == 15.6
    assert pipeline.structure_excess(_analysis(_channel("f_strain", True, 0.5))) == 0.0


def _loop(before_excess: float, short_excess: float, monkeypatch) -> tuple[list, object]:
    """A loop whose fit before the freeing and short refit leave the given structures; the
    run-on (guarded_fit) recorded, not made."""
    before, short = _fit(), _fit()
    judged = {id(before): _analysis(_channel("p_cyl_a-p_cyl_b", False, before_excess / 100)),
              id(short): _analysis(_channel("p_cyl_a-p_cyl_b", False, short_excess / 100))}
    loop = object.__new__(pipeline._Loop)
    loop.current = short
    loop.say = lambda msg: None
    loop.configured = None
    loop.judged = lambda fit: (judged[id(fit)], None)
    loop.structure_left = lambda: "residual structure"
    runs = []

    def run_on(*args, **kwargs):
        runs.append(args)
        raise StopIteration  # the run-on was asked for: the test ends here

    monkeypatch.setattr(pipeline, "guarded_fit", run_on)
    return runs, (loop, before)


def test_run_on_only_where_the_short_refit_took_structure_off(monkeypatch):
    # the bench's free piston with both frictions: 78 % -> 76 % predictable, no run-on
    runs, (loop, before) = _loop(78.0, 76.0, monkeypatch)
    loop.finish_freed(None, before)
    assert runs == []
    # a descent on its way (the piston encoder 18.5 -> 15.6 floors): run on
    runs, (loop, before) = _loop(18.5, 15.6, monkeypatch)
    try:
        loop.finish_freed(None, before)
    except StopIteration:
        pass
    assert len(runs) == 1
    # a structure that grew: no run-on either
    runs, (loop, before) = _loop(50.0, 60.0, monkeypatch)
    loop.finish_freed(None, before)
    assert runs == []


def _freeing_loop(costs: dict[int, float], monkeypatch) -> tuple[object, FitResult, list]:
    """A loop whose fit holds ``c_rod``; the short refit that frees it is ``again``, the
    validation costs are ``costs[id(fit)]``; the run-on's and the judge's calls recorded."""
    before = FitResult(np.zeros(3), ["ds"], {}, {}, {}, np.zeros((1, 1)))
    again = FitResult(np.ones(3), ["ds", "c_rod"], {}, {}, {}, np.zeros((1, 1)))
    costs = {id(before): costs["before"], id(again): costs["again"]}
    calls = []

    class Fitter:
        def fit(self, *args, **kwargs):
            return again

        def offenders(self, fit):
            return []

    loop = object.__new__(pipeline._Loop)
    loop.current, loop.held = before, {"c_rod": "held at the baseline"}
    loop.rejected = []
    loop.exp, loop.sigma_ref = None, {}
    loop.say = lambda msg: None
    loop.refitter = Fitter
    loop.model = type("M", (), {"start_vector": lambda self: None})()
    loop.added = [type("E", (), {"label": "x"})()]
    loop.defs_all = {"x": type("D", (), {"refit_extra": ()})()}
    loop.finish_freed = lambda fitter, fit: calls.append("run-on")
    loop.structure_left = lambda: calls.append("judged") or ""
    monkeypatch.setattr(pipeline, "pinned", lambda fitter, fit, free, retry: retry)
    monkeypatch.setattr(pipeline, "guarded_fit", lambda *args, **kwargs: (again, {}))
    monkeypatch.setattr(pipeline, "_val_cost", lambda exp, out, sigma: costs[id(
        before if out is before.outputs else again)])
    return loop, before, calls


def test_a_freeing_that_raises_the_validation_cost_is_refused_unjudged(monkeypatch):
    # the conrod's two frictions, rig seed 2: c_rod freed at the end, 668.612 vs 668.054
    loop, before, calls = _freeing_loop({"before": 668.054, "again": 668.612}, monkeypatch)
    assert loop._free_held_again() is False
    assert calls == []  # neither run on nor judged
    assert loop.current is before and "c_rod" in loop.held
    assert loop.rejected == ["c_rod freed again: not kept (the validation cost rises, "
                             "668.612 vs 668.054)"]
    # a freeing that costs no more is run on and judged, and kept where it explains
    loop, before, calls = _freeing_loop({"before": 668.612, "again": 668.054}, monkeypatch)
    assert loop._free_held_again() is True
    assert calls == ["run-on", "judged"]
    assert loop.current is not before and "c_rod" not in loop.held
