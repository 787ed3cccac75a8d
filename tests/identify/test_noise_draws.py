"""The residual judge's input-noise part from several draws (a piston held by its seal).

Through a seal that holds the piston the input noise's part of the residual is
intermittent: each break-away the noise shifts rings the piston's resonance, and its power
differs several-fold from one noise draw to the next. Whitening by one draw judges the
record's own realisation by a guess of its level: a weak draw leaves a strong realisation's
resonance as structure. Here the part is a resonance at 1350 Hz of a given power in each
draw (numpy only: a stand-in for the simulated draws, whose spectra differ in level, not in
shape), the record one more realisation on a white sensor floor.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import iirpeak, lfilter

from hil.identify.pipeline import MATERIAL_SHARE
from hil.identify.residuals import predictable_share, whiten

FS = 5000.0
N = 12000
#: The draws' powers relative to the sensor floor's: a spread of 5x, as through a held seal.
DRAW_POWERS = (0.5, 0.6, 0.8, 1.0, 1.2, 1.5, 2.0, 2.5)


def _resonant(seed: int, power: float, hz: float = 1350.0) -> np.ndarray:
    b, a = iirpeak(hz, 15.0, fs=FS)
    x = lfilter(b, a, np.random.default_rng(seed).normal(size=N))
    return x * np.sqrt(power) / x.std()


def _draws() -> np.ndarray:
    return np.stack([_resonant(10 + j, p) for j, p in enumerate(DRAW_POWERS)])


def _record(own_power: float) -> np.ndarray:
    return np.random.default_rng(1).normal(size=N) + _resonant(99, own_power)


def test_a_strong_realisation_within_the_draws_spread_is_noise_not_structure():
    r = _record(2.2)
    draws = _draws()
    # one weak draw (the old single-draw part) reads the realisation as structure
    assert predictable_share(whiten(r, draws[0], FS)) > MATERIAL_SHARE
    # the draws' mean at its own level does not: the realisation is stronger than the mean
    assert predictable_share(whiten(r, draws, FS)) < MATERIAL_SHARE


def test_no_level_beyond_the_strongest_draw_is_granted():
    # a resonance 3x the strongest draw's power is more than input noise can explain
    assert predictable_share(whiten(_record(8.0), _draws(), FS)) > MATERIAL_SHARE


def test_structure_where_the_noise_part_has_none_is_still_seen():
    line = _resonant(5, 0.1, hz=400.0)
    assert predictable_share(whiten(_record(2.2) + line, _draws(), FS)) > MATERIAL_SHARE

