"""The kernel skips the sub-step's effect inputs (the pump's force, the series compliance's
rate, the piston's force) where no effect can make them non-zero: the states must be those
of the full input product, bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np

from hil.identify.experiment import prepare
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config


def _exp():
    rig = generate_rig("conrod_fixed", ["strain_thermal_drift"], seconds=0.8, seed=2)
    return prepare(rig.data, load_config("hydra_default"), "bl")


def test_the_skipped_effect_inputs_change_no_bit():
    """A viscosity law at the reference temperature throughout keeps every effect input at
    zero but takes the full input product (the law is on): its states equal those of the
    same model without the law, which skips the effect inputs, to the last bit. Both
    frictions on, so the solves' half-step velocity takes the same path."""
    exp = _exp()
    assert exp.temperature is not None
    flat = dataclasses.replace(exp, temperature=np.full_like(exp.temperature, exp.t_ref))
    model = FastModel(flat)
    theta = model.start_vector()
    for name, value in (("pc_force_n", 40.0), ("pc_shape", 0.6), ("sf_coulomb_n", 20.0),
                        ("sf_static_n", 35.0)):
        theta[IDX[name]] = value
    skipped = model.states(theta)
    with_law = theta.copy()
    with_law[IDX["visc_coeff_per_c"]] = 0.03
    full = model.states(with_law)
    assert np.array_equal(full, skipped)
    # the law does act where the temperature moves (the case is not vacuous)
    assert not np.array_equal(FastModel(exp).states(with_law), FastModel(exp).states(theta))
