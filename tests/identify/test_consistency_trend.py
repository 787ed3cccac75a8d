"""The consistency judge's time split (:mod:`hil.identify.consistency`) on a linear stand-in:
one damper seen through a white regressor, its value per sample set by the test, the
residual what a fit at the whole-record value would leave. Milliseconds, no simulation.

The split must flag a damper that drifts over the record and must not flag one that only
scatters between segments (the free piston's slow multisine gives each segment another mix
of stuck and sliding phases), though the scatter is as large and as far beyond the
segments' intervals as the drift."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hil.identify.consistency import ALPHA, MATERIAL_RATIO, N_SEGMENTS, consistency

_DT = 1e-3
_N = 6000  # 6 s: three 2 s segments
_NOISE = 0.3  # with a unit regressor: about 1 % (one sigma) per segment's estimate


def _judge(offset: np.ndarray):
    """``consistency`` of a one-parameter fit (``ds`` at 1.0) to a record whose damper
    differs from the fitted value by the log-offset ``offset`` per sample."""
    rng = np.random.default_rng(7)
    regressor = rng.standard_normal(_N)
    # the fit's Jacobian is that of measured minus model: a larger damper than fitted
    # gives a residual along -J
    residual = -regressor * offset + _NOISE * rng.standard_normal(_N)
    exp = SimpleNamespace(channels=["p_a"], measured={"p_a": residual},
                          data=SimpleNamespace(t=np.arange(_N) * _DT), dt=_DT, load="free")
    fit = SimpleNamespace(jac=regressor[:, None], free=["ds"], theta=None,
                          value=lambda name: 1.0, weights={"p_a": 1.0}, sigma={"p_a": 1.0},
                          outputs={"p_a": np.zeros(_N)})
    return consistency(fit, exp, np.ones(_N, dtype=bool))


def _time_split(offset: np.ndarray):
    c = _judge(offset)
    (s,) = [s for s in c.splits if s.name == "ds" and s.split == "time"]
    return s


def _per_segment(values: list[float]) -> np.ndarray:
    assert len(values) == N_SEGMENTS
    return np.repeat(np.asarray(values), _N // N_SEGMENTS)


def test_a_drifting_damper_is_flagged_falling():
    """-8 % over the record, as the warming oil's dampers: a trend far beyond its interval,
    reported from the higher first segment to the lower last one."""
    s = _time_split(np.linspace(0.04, -0.04, _N))
    assert s.inconsistent, s.describe("d_s")
    assert s.p_value < ALPHA and s.ratio > MATERIAL_RATIO
    assert s.slope_per_s is not None and s.slope_per_s < 0
    low, high = (s.parts[i] for i in s.far)
    assert low is s.parts[-1] and high is s.parts[0]
    assert low.ci_high < high.ci_low
    assert "drifts" in s.describe("d_s")


def test_a_damper_that_scatters_without_drift_is_not_flagged():
    """The middle segment 6 % above the other two (the seed-3 record's shape): the segments
    disagree far beyond their intervals, but there is no line through them; a homogeneity
    test flags this (chi^2 ~ 24 on 2), the trend test does not."""
    s = _time_split(_per_segment([0.0, 0.06, 0.0]))
    assert not s.inconsistent, s.describe("d_s")
    assert s.p_value > 0.05
    # the scatter is real and beyond the intervals: what the homogeneity test would flag
    values = [p.value for p in s.parts]
    assert max(values) / min(values) > MATERIAL_RATIO
    assert s.parts[1].ci_low > max(s.parts[0].ci_high, s.parts[2].ci_high)


def test_a_step_half_way_is_a_trend():
    """A damper that steps down 6 % half-way (air coming out of the oil) is flagged too."""
    offset = np.where(np.arange(_N) < _N // 2, 0.03, -0.03)
    s = _time_split(offset)
    assert s.inconsistent, s.describe("d_s")


@pytest.mark.parametrize("scale", [0.0, 1.0])
def test_a_constant_damper_is_not_flagged(scale):
    """The fitted value itself, or 5 % off it over the whole record (the whole-record fit's
    step moves every segment alike: no trend, no disagreement)."""
    s = _time_split(np.full(_N, 0.05 * scale))
    assert not s.inconsistent, s.describe("d_s")
