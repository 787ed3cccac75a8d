"""The seal's friction levels stay >= 0 in the fit: F(v) = (F_c + (F_s - F_c) exp(-(v/v_s)^2))
s(v) dissipates only with both levels >= 0 (:data:`hil.identify.fit.NON_NEGATIVE`).

On a free piston whose only friction is the pump's, a fit with the seal's levels free and the
pump's friction left out pulls them below zero (a seal pushing the piston along near rest,
standing in for the missing pump friction: -0.2 .. -0.5 N here, -82 .. -131 N on the 16 s
bench record); with the bound they stop at zero."""

from __future__ import annotations

from hil.identify.experiment import prepare
from hil.identify.fit import BASELINE_FREE, OutputErrorFit
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def test_a_seal_standing_in_for_pump_friction_keeps_non_negative_levels():
    rig = generate_rig("free_piston", ["pump_coulomb_friction"], seconds=0.8, seed=3,
                       profile="slide")
    model = FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))
    theta = model.start_vector()
    theta[IDX["sf_coulomb_n"]] = theta[IDX["sf_static_n"]] = 15.0
    levels = ["sf_coulomb_n", "sf_static_n"]
    fitter = OutputErrorFit(model, {p: 15.0 for p in levels})
    result = fitter.fit(theta, list(BASELINE_FREE["free"]) + levels, passes=1, max_nfev=3)
    # the data pull them down from 15 N to their floor (without it: below zero)
    assert all(0.0 <= result.value(p) < 1.0 for p in levels), {p: result.value(p)
                                                               for p in levels}
