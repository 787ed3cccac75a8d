"""The band-limited input's sub-step averages: the average of the band-limited signal behind
the samples over each model sub-step, shifted by the delay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.identify.intersample import substep_average


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


@pytest.mark.parametrize("n", [5, 64, 1001, 4000])
@pytest.mark.parametrize("n_sub", [1, 2, 4])
def test_the_dct_form_is_the_fft_form_to_rounding(n, n_sub, monkeypatch):
    """The band-limited average from the input's DCT (the default) against an inverse FFT
    of the even extension per sub-step, delays of either sign and beyond a sample: the
    same values to rounding; asked again (its transform kept), the same bits."""
    from hil.identify import intersample

    u = np.random.default_rng(n).normal(size=n).cumsum()
    dt = 2e-4
    for delay in (0.0, 3.1e-5, -7e-5, 2.7e-4):
        monkeypatch.setattr(intersample, "DCT", False)
        want = substep_average(u, dt, n_sub, delay, "bl")
        monkeypatch.setattr(intersample, "DCT", True)
        intersample._BL_CACHE.clear()
        got = substep_average(u, dt, n_sub, delay, "bl")
        assert got.shape == want.shape
        assert np.max(np.abs(got - want)) <= 1e-13 * np.abs(u).max()
        assert np.array_equal(substep_average(u, dt, n_sub, delay, "bl"), got)
