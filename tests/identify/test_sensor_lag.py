"""The sensors' first-order lag: the filter applied to the spectrum of the signal's even
extension. Held here to that definition written out on its own, to the continuous filter's
gain and phase on a sine, and batched signals to single ones (a faster transform of the
lag must pass the same tests)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.identify.lag import sensor_lag, sensor_lags


def _by_extension(y: np.ndarray, tau: float, dt: float, n: int) -> np.ndarray:
    ext = np.concatenate([y[:n], y[:n][::-1]])
    h = 1.0 / (1.0 + 2j * math.pi * np.fft.rfftfreq(ext.size, dt) * tau)
    return np.fft.irfft(np.fft.rfft(ext) * h, ext.size)[:n]


@pytest.mark.parametrize("n", [2, 7, 1000, 3072])
@pytest.mark.parametrize("tau", [2e-5, 1.5e-4, 1e-3])
def test_the_transforms_give_the_extension_s_filter(n, tau):
    rng = np.random.default_rng(n)
    dt = 2e-4
    # a signal with a trend, a resonance and noise: every band carries something
    t = np.arange(3072) * dt
    y = 3e5 * t + 2e4 * np.sin(2 * math.pi * 1300 * t) + rng.normal(0.0, 2e3, t.size)
    got = sensor_lag(y, tau, dt, n_valid=n)
    want = _by_extension(y, tau, dt, n)
    scale = np.abs(y[:n]).max()
    assert np.max(np.abs(got[:n] - want)) <= 1e-13 * scale
    assert np.array_equal(got[n:], y[n:])  # beyond n_valid: as given


def test_a_lag_attenuates_and_delays_a_sine_as_the_continuous_filter_does():
    dt, tau, f = 2e-4, 1e-4, 400.0
    t = np.arange(4000) * dt
    out = sensor_lag(np.sin(2 * math.pi * f * t), tau, dt)
    w = 2 * math.pi * f
    want = np.sin(w * t - math.atan(w * tau)) / math.sqrt(1 + (w * tau) ** 2)
    mid = slice(1000, 3000)  # away from the reflected ends
    assert np.max(np.abs(out[mid] - want[mid])) < 2e-3


def test_batched_signals_are_filtered_each_as_alone_and_a_gap_falls_back():
    rng = np.random.default_rng(3)
    ys = [rng.normal(size=500).cumsum() for _ in range(3)]
    batched = sensor_lags(ys, 1e-4, 2e-4)
    for y, b in zip(ys, batched, strict=True):
        assert np.allclose(b, sensor_lag(y, 1e-4, 2e-4), rtol=0, atol=1e-12)
    gap = ys[0].copy()
    gap[100] = np.nan
    out = sensor_lag(gap, 1e-4, 2e-4)
    assert np.isfinite(out[:100]).all() and np.isnan(out[100])


def test_a_constant_signal_s_lag_is_remembered_to_the_bit():
    """A constant (a free piston's strain: the offset alone) is filtered once per value,
    lag and length; the remembered result is the transform's own to the bit, for each
    value (+0 and -0 apart) and length, and a caller writing into its copy changes none."""
    from hil.identify import lag

    dt = 2e-4
    cases = [(np.full(3072, 1.5e3), 1e-4, None), (np.full(3072, 1.5e3), 2e-4, None),
             (np.full(3072, 1.5e3), 1e-4, 1000), (np.full(3072, -7.0), 1e-4, None),
             (np.full(3072, 0.0), 1e-4, None), (np.full(3072, -0.0), 1e-4, None)]
    lag._CONSTANT_CACHE.clear()
    fresh = []
    for y, tau, n in cases:  # each computed with nothing remembered
        lag._CONSTANT_CACHE.clear()
        fresh.append(sensor_lag(y, tau, dt, n_valid=n))
    lag._CONSTANT_CACHE.clear()
    for _ in range(3):  # remembered: the first pass fills, the others read
        for (y, tau, n), want in zip(cases, fresh, strict=True):
            got = sensor_lag(y, tau, dt, n_valid=n)
            assert got.tobytes() == want.tobytes()
            got[:] = 99.0  # the caller's copy: the memo keeps its own
    assert lag._CONSTANT_CACHE
    # a signal that is not constant is not remembered (one sample moved)
    lag._CONSTANT_CACHE.clear()
    y = np.full(3072, 1.5e3)
    y[1500] += 1.0
    sensor_lag(y, 1e-4, dt)
    assert not lag._CONSTANT_CACHE


def _filtered_by_fft(y: np.ndarray, tau: float, dt: float, n: int) -> np.ndarray:
    from hil.identify import lag

    old = lag.DCT
    try:
        lag.DCT = False
        return sensor_lag(y, tau, dt, n_valid=n)
    finally:
        lag.DCT = old


@pytest.mark.parametrize("n", [2, 3, 8, 999, 3072])
def test_the_dct_form_is_the_even_extension_s_fft_to_rounding(n, monkeypatch):
    """The lag from a DCT-II and a DCT-III/DST-III of the signal (``lag.DCT``) against the
    FFT of the even extension: random walks, a step, an alternating (Nyquist) signal and a
    constant, odd and even lengths, all or a head filtered (``n_valid`` < size)."""
    from hil.identify import lag

    monkeypatch.setattr(lag, "DCT", True)
    rng = np.random.default_rng(n)
    size = 3072
    signals = [rng.normal(size=size).cumsum() * 1e3, np.where(np.arange(size) < size // 3,
                                                              -5.0, 2e5),
               (-1.0) ** np.arange(size) * 7.0, np.full(size, 3.25)]
    for y in signals:
        for tau in (3e-5, 4e-4):
            lag._CONSTANT_CACHE.clear()
            got = sensor_lag(y, tau, 2e-4, n_valid=n)
            want = _filtered_by_fft(y, tau, 2e-4, n)
            assert np.max(np.abs(got - want)) <= 1e-13 * max(np.abs(y).max(), 1.0)
            assert np.array_equal(got[n:], y[n:])


def test_the_dct_form_falls_back_on_a_gap_as_the_fft_form(monkeypatch):
    from hil.identify import lag

    monkeypatch.setattr(lag, "DCT", True)
    y = np.random.default_rng(5).normal(size=400).cumsum()
    y[150] = np.nan
    got = sensor_lag(y, 1e-4, 2e-4)
    want = _filtered_by_fft(y, 1e-4, 2e-4, y.size)
    assert np.array_equal(got, want, equal_nan=True)
