"""The residual test's input-noise part on a record whose seal friction holds the piston.

The conrod's piston is held by its seal for most of a multisine record. At the rig's own
parameters the residual is the sensors' noise plus what the logged current's noise does in
the model; a held piston answers that noise more strongly from a clean start than from one
already shaken by noise, so a second noise added to the logged current under-predicts it and
the pressure difference's residual read as material structure. The noise part taken from a
cleaned current must leave it immaterial (below the judge's 1 %).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.identify.experiment import prepare, quantum
from hil.identify.model import IDX, FastModel
from hil.identify.noise import (
    clean_current,
    estimate_input_noise,
    held_noise_draws,
    predicted_residual,
)
from hil.identify.pipeline import MATERIAL_SHARE
from hil.identify.residuals import analyse
from hil.identify.rig import SENSORS, generate_rig


def test_clean_current_keeps_the_excitation_lines_and_drops_the_white_floor():
    fs, n, rms = 5000.0, 20000, 0.02
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    lines = sum(a * np.sin(2 * np.pi * f * t + p)
                for a, f, p in zip(rng.uniform(0.5, 2.0, 12), np.arange(1, 13) * 7.25,
                                   rng.uniform(0, 6.28, 12), strict=True))
    iq = 3.0 + lines + rng.normal(0.0, rms, n)
    noise = estimate_input_noise(iq, fs)
    assert noise.rms_a == pytest.approx(rms, rel=0.1)
    clean = clean_current(iq, noise)
    # what is left of the noise is the part on the twelve kept lines: ~sqrt(12/n) of it
    assert np.std(clean - 3.0 - lines) < 0.1 * rms
    assert np.mean(clean) == pytest.approx(np.mean(iq))


def _truth_theta(model: FastModel, rig) -> np.ndarray:
    seal = rig.truth["effects"]["seal_friction"]
    theta = model.start_vector()
    for k in ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod"):
        theta[IDX[k]] = rig.truth["parameters"][k]
    theta[IDX["sf_coulomb_n"]] = seal["coulomb_n"]
    theta[IDX["sf_static_n"]] = seal["static_n"]
    theta[IDX["sf_vs_m_per_s"]] = seal["stribeck_m_per_s"]
    theta[IDX["sf_shape"]] = 1.0  # the rig's atan law
    theta[IDX["sf_eps_m_per_s"]] = 0.5 * math.pi * seal["eps_m_per_s"]
    theta[IDX["lag_pressure_s"]] = 1.0 / (2.0 * math.pi * SENSORS["pressure_bandwidth_hz"])
    theta[IDX["lag_strain_s"]] = 1.0 / (2.0 * math.pi * SENSORS["strain_bandwidth_hz"])
    return theta


@pytest.mark.slow
def test_held_seal_at_the_rig_truth_leaves_no_material_structure(ident_cfg):
    rig = generate_rig("conrod_fixed", ["seal_friction"], seconds=6.0, seed=1,
                       preset=ident_cfg)
    exp = prepare(rig.data, ident_cfg, "bl")
    model = FastModel(exp)
    theta = _truth_theta(model, rig)
    y = model.outputs(theta)
    residual = {c: exp.measured[c] - y[c] for c in exp.channels}
    noise = estimate_input_noise(exp.iq, exp.data.sample_rate_hz, quantum(exp.iq))
    assert noise.rms_a > 0
    clean, (noisy,) = held_noise_draws(exp, noise, 1)
    part = predicted_residual(clean.outputs(theta), noisy.outputs(theta))
    a = analyse(exp, residual, exp.val, part)
    for c in ("p_pump_a-p_pump_b", "p_cyl_a-p_cyl_b", "f_strain"):
        assert a.channels[c].predictable_share < MATERIAL_SHARE, (c, a.channels[c].summary())
