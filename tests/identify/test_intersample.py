"""The band-limited input's sub-step averages: the average of the band-limited signal behind
the samples over each model sub-step, shifted by the delay."""

from __future__ import annotations

import math

import numpy as np

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
