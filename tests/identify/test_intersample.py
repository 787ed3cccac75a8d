"""The band-limited input's sub-step averages: one batched transform for every sub-step must
give, to the bit, the spectrum's inverse transform per sub-step with its phase ramp (the
fit's outputs, and so its path, hang on the last bits of the input), and that is the
average of the band-limited signal over each sub-step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.identify.intersample import _BL_CACHE, substep_average


def _per_substep(u: np.ndarray, dt: float, n_sub: int, delay_s: float) -> np.ndarray:
    """The definition: sinc interpolation by the even extension's spectrum, the sub-step's
    box filter, the shift as a phase ramp, one inverse transform per sub-step."""
    n = u.size
    h = dt / n_sub
    ext = np.concatenate([u, u[::-1]])
    f = np.fft.rfftfreq(ext.size, dt)
    spec = np.fft.rfft(ext) * np.sinc(f * h)
    out = np.empty((n, n_sub))
    for j in range(n_sub):
        shift = (j + 0.5) * h - delay_s
        out[:, j] = np.fft.irfft(spec * np.exp(2j * np.pi * f * shift), ext.size)[:n]
    return out.ravel()


@pytest.mark.parametrize("n_sub", [1, 2, 4])
@pytest.mark.parametrize("delay_s", [0.0, 3.7e-5, -1.1e-4])
def test_batched_transform_is_a_transform_per_substep(n_sub, delay_s):
    rng = np.random.default_rng(n_sub)
    u = np.cumsum(rng.normal(size=3000)) * 0.01
    _BL_CACHE.clear()
    got = substep_average(u, 2e-4, n_sub, delay_s, "bl")
    assert np.array_equal(got, _per_substep(u, 2e-4, n_sub, delay_s))
    # from the kept spectrum too
    assert np.array_equal(substep_average(u, 2e-4, n_sub, delay_s, "bl"), got)


def test_a_slow_sine_averages_over_each_substep():
    """A sine far below the sample rate, delayed: each value is the sine's average over its
    shifted sub-step (away from the record's ends, where the even extension folds it)."""
    dt, n_sub, delay, f0 = 2e-4, 4, 7e-5, 37.0
    t = np.arange(4000) * dt
    u = np.sin(2 * math.pi * f0 * t)
    got = substep_average(u, dt, n_sub, delay, "bl").reshape(-1, n_sub)
    h = dt / n_sub
    w = 2 * math.pi * f0
    start = t[:, None] + np.arange(n_sub)[None, :] * h - delay
    exact = (np.cos(w * start) - np.cos(w * (start + h))) / (w * h)
    inner = slice(500, 3500)
    assert np.max(np.abs(got[inner] - exact[inner])) < 1e-3
