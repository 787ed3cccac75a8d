"""A model reuses, between simulations, the applied force (by gain and timing) and the start
state (by linear part and first input): a run after others must be bit for bit the run of a
fresh model, whichever parameter changed in between."""

from __future__ import annotations

import numpy as np

from hil.identify.experiment import prepare
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def test_a_run_after_others_is_a_fresh_model_s_run():
    rig = generate_rig("free_piston", ["pump_coulomb_friction"], seconds=0.6, seed=4)
    exp = prepare(rig.data, load_config("hydra_default"), "bl")
    model = FastModel(exp)
    base = model.start_vector()
    base[IDX["pc_force_n"]] = 60.0
    moves = [("gain_n_per_a", 1.02), ("skew_s", 4e-5), ("delay_s", 7e-5), ("ks", 1.01),
             ("jc", 0.97), ("pc_force_n", 1.5)]
    thetas = [base]
    for name, change in moves:
        theta = base.copy()
        if name in ("skew_s", "delay_s"):
            theta[IDX[name]] = change
        else:
            theta[IDX[name]] *= change
        thetas.append(theta)
    for theta in thetas + thetas[::-1]:  # each after every other kind of change
        got = model.states(theta, keep=False)
        want = FastModel(exp).states(theta, keep=False)
        assert got.tobytes() == want.tobytes()
    # the runs differ (the changes reach the states: the test is not vacuous)
    runs = [FastModel(exp).states(t, keep=False) for t in thetas]
    assert all(not np.array_equal(runs[0], r) for r in runs[1:])
