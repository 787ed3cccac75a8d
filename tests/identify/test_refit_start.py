"""The start of a refit with an effect added (:func:`hil.identify.fit.configured_start`):
the parameters the fit without the effect moved far from their configured values go back
there together, when the cost says that start is the better one."""

from __future__ import annotations

import numpy as np

from hil.identify.fit import PROFILE_FACTOR, configured_start
from hil.identify.model import IDX, N_PARAMS


class _Cost:
    """A fitter whose cost is a given function of theta; counts the simulations."""

    def __init__(self, fn) -> None:
        self.fn = fn
        self.calls = 0

    def cost(self, theta: np.ndarray, sigma: dict[str, float]) -> float:
        self.calls += 1
        return float(self.fn(theta))


def _vectors() -> tuple[np.ndarray, np.ndarray]:
    configured = np.zeros(N_PARAMS)
    for n, v in {"dc": 413.0, "c_rod": 50.0, "ks": 2.24e7, "k_rod": 1.5e6}.items():
        configured[IDX[n]] = v
    start = configured.copy()
    start[IDX["c_rod"]] *= 49.0  # the dampers of a fit without the seal's friction
    start[IDX["dc"]] *= 2.7
    start[IDX["ks"]] *= 1.2  # within the factor: stays
    return start, configured


FREE = ["dc", "c_rod", "ks", "k_rod", "sf_coulomb_n"]


def _valley(theta: np.ndarray, configured: np.ndarray) -> float:
    """Lowest at the configured dampers together; either one alone far is worse than both."""
    far = [abs(np.log(theta[IDX[n]] / configured[IDX[n]])) > np.log(PROFILE_FACTOR)
           for n in ("dc", "c_rod")]
    return {(False, False): 1.0, (True, True): 2.0}.get(tuple(far), 3.0)


def test_the_far_parameters_go_back_together_when_that_start_costs_less():
    start, configured = _vectors()
    fitter = _Cost(lambda t: _valley(t, configured))
    theta, back = configured_start(fitter, start, FREE, configured, {})
    assert sorted(back) == ["c_rod", "dc"]
    assert theta[IDX["c_rod"]] == configured[IDX["c_rod"]]
    assert theta[IDX["dc"]] == configured[IDX["dc"]]
    assert theta[IDX["ks"]] == start[IDX["ks"]]  # within the factor: the fit's own
    assert fitter.calls == 2


def test_a_far_start_that_fits_better_is_kept():
    start, configured = _vectors()
    fitter = _Cost(lambda t: -_valley(t, configured))  # the data ask for the far dampers
    theta, back = configured_start(fitter, start, FREE, configured, {})
    assert back == [] and np.array_equal(theta, start)


def test_nothing_far_costs_no_simulation():
    start, configured = _vectors()
    start[IDX["c_rod"]] = configured[IDX["c_rod"]]
    start[IDX["dc"]] = configured[IDX["dc"]]
    fitter = _Cost(lambda t: 0.0)
    theta, back = configured_start(fitter, start, FREE, configured, {})
    assert back == [] and theta is start and fitter.calls == 0


def test_held_parameters_are_not_moved():
    start, configured = _vectors()
    fitter = _Cost(lambda t: _valley(t, configured))
    theta, back = configured_start(fitter, start, ["dc", "ks"], configured, {})
    # c_rod is not free (held): it stays where it is, and dc alone is no better a start
    assert back == [] and theta[IDX["c_rod"]] == start[IDX["c_rod"]]
