"""The pressure and strain sensors' first-order lag, as a continuous sensor sees the
band-limited signal behind the samples (:func:`sensor_lag`). A fit maps every simulation
through it: the transforms are about a sixth of a fit's CPU on the bench's records (a
module of its own, so that work on it does not recompile the simulation kernels).

The even extension's transform could be had from a DCT-II and a DCT-III/DST-III of the
signal itself (three transforms of ``n`` samples for two of ``2n``: a third of the time,
the same values to 1e-15); it is not used, because the bench's free-piston record's path
changes with the last bits of its outputs (see docs/identify.md)."""

from __future__ import annotations

import math

import numpy as np


def sensor_lag(y: np.ndarray, tau: float, dt: float, n_valid: int | None = None
               ) -> np.ndarray:
    """``y`` (samples ``dt`` apart) through a first-order sensor lag ``tau`` s, as a
    continuous sensor sees the band-limited signal behind the samples: ``1/(1 + j w tau)``
    applied to the spectrum of the even extension (no jump at the record's ends, so it
    starts settled). A recursion exact for a signal linear between samples (first-order
    hold) attenuates by the hold's ``sinc^2(f dt)`` as well: 18 % too much at 1.3 kHz of a
    5 kHz record, where the free piston rings on ``k_s``. Only the first ``n_valid`` samples
    are filtered (the rest is returned as is); a signal with a non-finite value falls back
    to that recursion, which keeps the damage local."""
    return sensor_lags([y], tau, dt, n_valid)[0]


def sensor_lags(ys: list[np.ndarray], tau: float, dt: float, n_valid: int | None = None
                ) -> list[np.ndarray]:
    """:func:`sensor_lag` of several equally long signals with the same lag, in one batched
    transform (the four pressure sensors share theirs: a third of a simulation's cost)."""
    size = ys[0].size
    n = size if n_valid is None else max(2, min(n_valid, size))
    key = _constant_key(ys, tau, dt, n)
    if key is not None:
        hit = _CONSTANT_CACHE.get(key)
        if hit is not None:
            return [h.copy() for h in hit]
    out = _transformed(ys, tau, dt, n, size)
    if key is not None:
        if len(_CONSTANT_CACHE) > 16:
            _CONSTANT_CACHE.clear()
        _CONSTANT_CACHE[key] = [o.copy() for o in out]
    return out


def _constant_key(ys: list[np.ndarray], tau: float, dt: float, n: int) -> tuple | None:
    """The memo's key for signals that are each one finite value throughout (a free
    piston's strain: its rod force is zero, the channel is the offset alone), else None.
    Only whole calls of constant signals are memoised: a call's transform is the same
    computation on the same input, so the memo returns its bits exactly."""
    values = []
    for y in ys:
        if y.dtype != np.float64 or not math.isfinite(y[0]):
            return None
        # compared as bit patterns (a +0 and a -0 transform apart); the cheap checks
        # first: a pressure differs from its first sample at once
        bits = y.view(np.int64)
        v = bits[0]
        if bits[n - 1] != v or bits[-1] != v or not np.all(bits == v):
            return None
        values.append(int(v))
    return (tuple(values), float(tau), float(dt), n, ys[0].size)


def _transformed(ys: list[np.ndarray], tau: float, dt: float, n: int, size: int
                 ) -> list[np.ndarray]:
    ext = np.empty((len(ys), 2 * n))
    for i, y in enumerate(ys):
        ext[i, :n] = y[:n]
        ext[i, n:] = ext[i, n - 1::-1]
    if not np.all(np.isfinite(ext[:, :n])):
        return [_sensor_lag_foh(y, tau, dt) for y in ys]
    spec = np.fft.rfft(ext, axis=1)
    spec *= _lag_response(ext.shape[1], tau, dt)
    filtered = np.fft.irfft(spec, ext.shape[1], axis=1)
    out = []
    for i, y in enumerate(ys):
        if n == size:  # the whole signal filtered (a head handed over as such)
            out.append(filtered[i, :n])
            continue
        o = y.copy()
        o[:n] = filtered[i, :n]
        out.append(o)
    return out


def _lag_response(size: int, tau: float, dt: float) -> np.ndarray:
    """``1/(1 + j w tau)`` on the ``rfft`` bins of ``size`` samples ``dt`` apart (a fit's
    Jacobian simulates one lag many times: the last few are kept)."""
    key = (size, float(tau), float(dt))
    hit = _LAG_CACHE.get(key)
    if hit is None:
        if len(_LAG_CACHE) > 16:
            _LAG_CACHE.clear()
        hit = 1.0 / (1.0 + 2j * math.pi * np.fft.rfftfreq(size, dt) * tau)
        _LAG_CACHE[key] = hit
    return hit


_LAG_CACHE: dict[tuple[int, float, float], np.ndarray] = {}
#: The lags of constant signals, by value, lag, step and length (:func:`_constant_key`):
#: the free piston's strain is the same constant for every Jacobian column but its offset's,
#: a third of the rows the fits filter on that record.
_CONSTANT_CACHE: dict[tuple, list[np.ndarray]] = {}


def _sensor_lag_foh(y: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """The lag, exact for an input linear between samples: ``tau y' = x - y`` gives
    ``y[k+1] = a y[k] + b0 x[k+1] + b1 x[k]`` with ``a = exp(-dt/tau)``,
    ``b0 = 1 - (tau/dt)(1 - a)``, ``b1 = (tau/dt)(1 - a) - a``; it starts settled."""
    from scipy.signal import lfilter

    a = math.exp(-dt / tau)
    r = tau / dt * (1.0 - a)
    b0, b1 = 1.0 - r, r - a
    zi = np.array([y[0] * (1.0 - b0)])  # steady state for y[0]: the filter state a*y - b1*x
    out, _ = lfilter([b0, b1], [1.0, -a], y, zi=zi)
    return out


__all__ = ["sensor_lag", "sensor_lags"]
