"""Data with an undeclared effect: each library effect in turn, switched on in the plant (or
around it), at a realistic magnitude, with sensor noise and quantisation. The tool must name
it, recover its parameter within the stated tolerance and lower the validation error."""

from __future__ import annotations

import numpy as np
import pytest

# whole identifications of several-second records: the full lane only
pytestmark = pytest.mark.slow

# effect -> (load case, {parameter: (truth key, relative tolerance)}, largest allowed
# NRMSE ratio after/before on the channel the effect shows most on, excitation profile,
# seconds). The viscosity effect is small (the oil warms ~2 degC in 6 s): it lowers the
# motor-speed error by a few %, and in 6 s records it is found on most noise realisations,
# not all (7 of 8 seeds); 8 s of warming make it stand out. Seal friction is run with the
# "slide" profile (constant piston speed, quick reversals): under the default multisine
# the Stribeck dip drives a stick-slip limit cycle whose phase no output-error simulation
# can follow (docs).
CASES = {
    "viscosity_temperature": ("fixed_piston", {"coeff_per_c": ("coeff_per_c", 0.20)}, 0.98,
                              "multisine", 8.0),
    "seal_friction": ("free_piston", {"coulomb_n": ("coulomb_n", 0.10),
                                      "static_n": ("static_n", 0.10)}, 0.2, "slide", 4.0),
}
# Pump pulsation and Coulomb friction, strain drift, input delay and the pressure clip are
# tested on the independent rig's data (test_measured_data.py, and every load and seed in
# the matrix of eha-hil identify-check), which the fit's model did not make.


@pytest.mark.parametrize("effect", list(CASES))
def test_effect_named_recovered_and_error_drops(identified, effect):
    load, tolerances, max_ratio, profile, seconds = CASES[effect]
    syn, rep = identified(load, (effect,), seconds=seconds, profile=profile)
    names = [e.name for e in rep.effects_added]
    assert names and names[0] == effect, (names, rep.unexplained_detail)
    # nothing from outside the truth is added
    assert set(names) == {effect}, names
    e = rep.effects_added[0]
    truth = syn.truth[effect]
    for param, (key, tol) in tolerances.items():
        got = e.params[param].value
        want = truth[key]
        assert abs(got - want) <= tol * abs(want), (param, got, want)
        lo, hi = e.params[param].ci_low, e.params[param].ci_high
        assert lo <= got <= hi
    if effect == "pump_pulsation":
        assert e.params["order"].value == truth["order"]
    before = np.array([c.nrmse_before for c in rep.channels])
    after = np.array([c.nrmse_after for c in rep.channels])
    assert after.mean() < before.mean() and np.all(after <= before * 1.01), (before, after)
    assert np.min(after / before) < max_ratio, after / before
    assert not rep.residual_before.white  # the effect leaves structure in the linear fit
    assert not rep.unexplained, rep.unexplained_detail


def test_selected_candidate_is_significant_and_ranked_first(identified):
    _, rep = identified("fixed_piston", ("pump_coulomb_friction",))
    rows = {r["label"]: r for r in rep.candidate_table()}
    sel = rows["pump_coulomb_friction"]
    assert sel["selected"] and sel["p_holm"] < 0.01 and sel["share_val"] > 0.5
    others = [r for r in rows.values() if not r["selected"]]
    assert all(r["p_holm"] >= 0.01 or r["round"] > 0 for r in others)


def test_unexcited_and_collinear_candidates_refused(identified):
    """Piston fixed: the seal never slides; the position never changes (k_s(x) is a
    constant, collinear with k_s); the oil temperature does not move."""
    _, rep = identified("fixed_piston", ())
    rows = {r["name"]: r for r in rep.candidate_table()}
    assert rows["seal_friction"]["status"] == "not_applicable"
    assert rows["stiffness_vs_position"]["status"] in ("not_excited", "collinear")
    assert rows["viscosity_temperature"]["status"] == "not_excited"
    assert rows["sensor_saturation"]["status"] == "not_applicable"
