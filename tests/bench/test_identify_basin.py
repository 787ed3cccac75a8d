"""The basin probe's pieces: the rig's truth in the fit's units, the cost along a line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.bench.identify_basin import diagnosis, line_costs, partial_truth, truth_vector
from hil.identify.model import IDX, N_PARAMS, _friction_sign

TRUTH = {"parameters": {"dc": 383.8, "jc": 0.3065, "c_rod": 56.9, "precharge_pa": 6.4e5},
         "effects": {"pump_coulomb_friction": {"force_n": 80.0, "eps_m_per_s": 3e-4},
                     "seal_friction": {"coulomb_n": 20.0, "static_n": 35.0,
                                       "stribeck_m_per_s": 4e-3, "eps_m_per_s": 1e-3}}}


def test_the_fits_sign_law_at_the_put_in_eps_is_the_rigs():
    # against the rig's own law as its kernel writes it, (2/pi) atan(v/eps)
    th, _ = truth_vector(np.zeros(N_PARAMS), IDX, TRUTH)
    for key, rig_eps in (("pc", 3e-4), ("sf", 1e-3)):
        eps = th[IDX[f"{key}_eps_m_per_s"]]
        shape = th[IDX[f"{key}_shape"]]
        for v in (-7e-3, -1e-3, -2e-4, 5e-5, 3e-4, 2e-3, 0.05):
            fit_law, _ = _friction_sign.py_func(v / eps, shape)
            assert math.isclose(fit_law, 2 / math.pi * math.atan(v / rig_eps), rel_tol=1e-12)


def test_truth_vector_sets_what_the_rig_has_and_leaves_the_rest():
    theta = np.full(N_PARAMS, 7.0)
    th, names = truth_vector(theta, IDX, TRUTH)
    assert th[IDX["dc"]] == 383.8 and th[IDX["sf_static_n"]] == 35.0
    assert th[IDX["ks"]] == 7.0 and th[IDX["puls1_flow_s"]] == 7.0  # not in the truth
    assert "precharge_pa" not in names and set(names) >= {"jc", "c_rod", "pc_force_n"}
    assert theta[IDX["dc"]] == 7.0  # the given vector is not changed


def test_line_costs_ends_and_geometric_steps():
    a, b = np.array([1.0, 0.0]), np.array([100.0, 4.0])
    seen = []
    costs = line_costs(lambda th: seen.append(th.copy()) or float(th[1] ** 2), a, b, {0},
                       points=3)
    assert costs == [0.0, 4.0, 16.0]
    assert seen[1][0] == 10.0  # the log-parameter halfway is the geometric mean
    # a ridge between two minima shows as a rise and fall on the line
    ridge = line_costs(lambda th: float(np.sin(np.pi * th[1] / 4)), a, b, set(), points=5)
    assert ridge[2] > ridge[0] and ridge[2] > ridge[-1]


def test_diagnosis_names_the_search_only_where_the_truth_is_lower():
    assert diagnosis(100.0, 40.0, False, False) == ("the search: the truth's basin is 2.50x "
                                                     "lower, and explained")
    assert "still leaves parameters disagreeing" in diagnosis(100.0, 40.0, False, True)
    assert diagnosis(100.0, 100.0, True, False).startswith("the model")


def test_partial_truth_puts_in_one_group_and_keeps_the_loops_values_elsewhere():
    loop_theta = np.full(N_PARAMS, 7.0)
    whole, names = truth_vector(loop_theta, IDX, TRUTH)
    fr, put_fr = partial_truth(loop_theta, whole, names, IDX, "frictions")
    assert fr[IDX["sf_static_n"]] == 35.0 and fr[IDX["pc_force_n"]] == 80.0
    assert fr[IDX["dc"]] == 7.0 and fr[IDX["jc"]] == 7.0  # linear: the loop's
    lin, put_lin = partial_truth(loop_theta, whole, names, IDX, "linear")
    assert lin[IDX["dc"]] == 383.8 and lin[IDX["c_rod"]] == 56.9
    assert lin[IDX["sf_static_n"]] == 7.0
    assert sorted(put_fr + put_lin) == sorted(names)
    every, _ = partial_truth(loop_theta, whole, names, IDX, "all")
    assert np.array_equal(every, whole)
    with pytest.raises(ValueError, match="truth group"):
        partial_truth(loop_theta, whole, names, IDX, "some")
