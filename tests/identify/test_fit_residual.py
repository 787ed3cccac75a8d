"""The fit's weighted residual: written channel by channel into one array where the compared
samples are one run, masked and joined where they are not. Both must give, to the bit, the
residual as defined: ``(measured - model) / sigma`` on the compared samples, channel after
channel, a clipped channel's plateau counted only where the model is below it, non-finite
values replaced, the model simulated up to the last compared sample."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify.experiment import prepare
from hil.identify.fit import PRESSURE_CHANNELS, OutputErrorFit
from hil.identify.model import IDX, SAT_PRESSURE, FastModel, fast_stop
from hil.identify.rig import generate_rig
from plant.config import load_config


def _defined(fitter: OutputErrorFit, theta: np.ndarray, sigma: dict[str, float],
             mask: np.ndarray) -> np.ndarray:
    """The residual as defined: every channel's masked samples, joined."""
    n_stop = fast_stop(int(np.flatnonzero(mask)[-1]) + 1, fitter.exp.n)
    out = fitter.model.outputs(theta, n_stop=n_stop)
    parts = []
    for c in fitter.exp.channels:
        n = out[c].size
        e = fitter.exp.measured[c][:n] - out[c]
        clipped = fitter._clipped.get(c)
        if clipped is not None and theta[IDX[f"sat_{c}"]] == 0.0 and (
                c not in PRESSURE_CHANNELS or theta[IDX[SAT_PRESSURE]] == 0.0):
            e = np.where(clipped[:n], np.maximum(e, 0.0), e)
        parts.append(np.nan_to_num(e[mask[:n]] / sigma[c]))
    return np.concatenate(parts)


@pytest.mark.parametrize("effects", [["sensor_saturation"], ["pump_coulomb_friction"]])
def test_the_residual_is_the_defined_one(effects):
    rig = generate_rig("fixed_piston", effects, seconds=1.0, seed=7)
    model = FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))
    fitter = OutputErrorFit(model)
    assert bool(fitter._clipped) == ("sensor_saturation" in effects)
    theta = model.start_vector()
    theta[IDX["gain_n_per_a"]] *= 1.5  # the model above the clip's plateau in places
    theta[IDX["lag_pressure_s"]] = 6e-5
    theta[IDX["pc_force_n"]] = 30.0
    sigma = {c: 1.0 + 0.37 * i for i, c in enumerate(model.exp.channels)}
    # every sample after the burn-in: the record's clips are in its validation part
    full = model.exp.est | model.exp.val
    where = np.flatnonzero(full)
    head = full.copy()
    head[where[where.size // 2]:] = False  # a fit's iterations: the first compared samples
    gap = full.copy()
    gap[where[10]:where[40]] = False  # undefined samples inside the compared part
    spans = [fitter._span(m)[1] for m in (full, head, gap)]
    assert spans[0] is not None and spans[1] is not None and spans[2] is None
    if fitter._clipped:
        out = model.outputs(theta)
        assert any((full & clipped & (model.exp.measured[c] < out[c])).any()
                   for c, clipped in fitter._clipped.items())
    for mask in (full, head, gap):
        got = fitter._stack(theta, sigma, mask)
        assert got.size == len(model.exp.channels) * int(mask.sum())
        assert np.array_equal(got, _defined(fitter, theta, sigma, mask))
