"""The loop keeps a fit's consistency and residual analysis once computed: the baseline's
holds compute the consistency of the fit they end in (hil.identify.fit.hold_unsupported,
through the loop's ``judge``), and the loop judges that fit again (free piston, both
frictions: 0.4 s of consistency and 0.5 s of noise draws a record, the report the same to
its bits). Only what the loop itself asks for is kept: another mask is computed afresh."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hil.identify import pipeline
from hil.identify.consistency import Consistency
from hil.identify.fit import FitResult


def _fit() -> FitResult:
    return FitResult(np.zeros(3), ["ks"], {}, {}, {}, np.zeros((1, 1)))


def _loop(monkeypatch, agreed: list, analysed: list) -> SimpleNamespace:
    def counted(fit, exp, mask):  # noqa: ANN001, ANN202 - consistency's own arguments
        agreed.append(fit)
        return Consistency()

    def analyse(exp, residual, val, noise):  # noqa: ANN001, ANN202 - analyse's own
        analysed.append(residual)
        return object()

    monkeypatch.setattr(pipeline, "consistency", counted)
    monkeypatch.setattr(pipeline, "analyse", analyse)
    loop = SimpleNamespace(exp=SimpleNamespace(channels=[], measured={}, val=None),
                           est_mask=np.array([True, True, False]), JUDGED_KEPT=3,
                           _analyses=(), _agreements=(), noise_part=lambda theta: None)
    for name in ("agreement_of", "analysis_of", "judged"):
        setattr(loop, name, getattr(pipeline._Loop, name).__get__(loop))
    return loop


def test_the_consistency_the_holds_computed_is_the_one_judged(monkeypatch):
    agreed: list = []
    loop = _loop(monkeypatch, agreed, [])
    base, other = _fit(), _fit()
    # as hold_unsupported calls it: the fitter's record and an equal mask of its own
    first = loop.agreement_of(base, loop.exp, loop.est_mask.copy())
    assert loop.judged(base)[1] is first
    assert loop.agreement_of(base) is first
    assert agreed == [base]
    # an equal fit is another fit; another mask is computed and not kept
    loop.agreement_of(other)
    loop.agreement_of(base, loop.exp, np.array([True, False, False]))
    loop.agreement_of(base)
    assert agreed == [base, other, base]


def test_the_analysis_is_kept_for_the_last_fits(monkeypatch):
    analysed: list = []
    loop = _loop(monkeypatch, [], analysed)
    fits = [_fit() for _ in range(4)]
    first = loop.analysis_of(fits[0])
    assert loop.judged(fits[0])[0] is first
    for f in fits[1:]:
        loop.analysis_of(f)
    assert len(analysed) == 4
    loop.analysis_of(fits[0])  # the oldest of four, no longer kept
    assert len(analysed) == 5
