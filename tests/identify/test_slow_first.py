"""The first stage of the refit below the piston's line (:mod:`hil.identify.slowfirst`): the
pressures, measured and simulated alike, low-passed below the line; every other channel as
it was; a fit's head the same as the whole record's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

FS = 5000.0
N = 10000
T = np.arange(N) / FS
SLOW = np.sin(2 * np.pi * 20.0 * T)
RING = np.sin(2 * np.pi * 1241.0 * T)


class StandIn:
    """A model whose outputs are fixed signals: the pressures a slow part plus the piston's
    ring, the motor speed the ring alone (not a pressure: left as it is)."""

    def __init__(self) -> None:
        self.exp = SimpleNamespace(data=SimpleNamespace(sample_rate_hz=FS),
                                   measured={"p_cyl_a": SLOW + RING, "p_pump_a": SLOW + RING,
                                             "omega_m": RING.copy()})
        self.n_sub = 7

    def outputs(self, theta, z=None, n_stop=None, channels=None):
        n = N if n_stop is None else n_stop
        out = {"p_cyl_a": (SLOW + RING)[:n], "p_pump_a": (SLOW + RING)[:n],
               "omega_m": RING[:n]}
        return out if channels is None else {c: out[c] for c in channels}


def test_the_pressures_are_low_passed_below_the_line():
    from hil.identify.slowfirst import LowPassedPressures

    model = StandIn()
    measured = dict(model.exp.measured)
    lp = LowPassedPressures(model, 0.4 * 1241.0)
    tail = slice(N // 2, None)
    for c in ("p_cyl_a", "p_pump_a"):
        y = lp.exp.measured[c][tail]
        # the ring about 30 dB down, the slow part through within 1 % (its phase moved)
        amp = np.sqrt(2.0 * np.mean((y - np.mean(y)) ** 2))
        assert 0.99 < amp < 1.05
        spec = np.abs(np.fft.rfft(y))
        f = np.fft.rfftfreq(y.size, 1.0 / FS)
        assert spec[np.argmin(np.abs(f - 1241.0))] < 0.05 * spec[np.argmin(np.abs(f - 20.0))]
    # not a pressure: the same signal; the model's own experiment untouched
    np.testing.assert_array_equal(lp.exp.measured["omega_m"], measured["omega_m"])
    for c, y in measured.items():
        assert model.exp.measured[c] is y
    # the model's other attributes read through
    assert lp.n_sub == 7


def test_the_simulated_pressures_take_the_same_filter_and_a_head_is_the_whole_records():
    from hil.identify.slowfirst import LowPassedPressures

    lp = LowPassedPressures(StandIn(), 500.0)
    whole = lp.outputs(None)
    for c in ("p_cyl_a", "p_pump_a"):
        # a model equal to the record leaves no residual through the filter
        np.testing.assert_array_equal(whole[c], lp.exp.measured[c])
        # causal: a fit's head has the whole record's values there
        np.testing.assert_array_equal(lp.outputs(None, n_stop=1234)[c], whole[c][:1234])
    np.testing.assert_array_equal(whole["omega_m"], RING)
    only = lp.outputs(None, channels=frozenset({"p_cyl_a"}))
    assert set(only) == {"p_cyl_a"}
    np.testing.assert_array_equal(only["p_cyl_a"], whole["p_cyl_a"])


def test_a_gap_in_a_pressure_is_refused():
    from hil.identify.slowfirst import pressures_finite

    exp = StandIn().exp
    assert pressures_finite(exp)
    exp.measured["p_cyl_a"] = exp.measured["p_cyl_a"].copy()
    exp.measured["p_cyl_a"][17] = np.nan
    assert not pressures_finite(exp)
    exp.measured["omega_m"][3] = np.nan
    exp.measured["p_cyl_a"][17] = 0.0
    assert pressures_finite(exp)
