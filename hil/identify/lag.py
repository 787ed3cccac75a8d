"""The pressure and strain sensors' first-order lag, as a continuous sensor sees the
band-limited signal behind the samples (:func:`sensor_lag`). A fit maps every simulation
through it: the transforms are about a sixth of a fit's CPU on the bench's records (a
module of its own, so that work on it does not recompile the simulation kernels).

The even extension's filtered transform can be had from a DCT-II of the signal itself and
a DCT-III and a DST-III back (:func:`even_filtered`: three transforms of ``n`` samples for
two of ``2n``, a third of the time, the same values to ~1e-15 but not to the bit). For the
lags it is off (:data:`DCT`): with it the whole matrix is right, but the bench's
free-piston record, whose path forks on last bits, adds no effect (see docs/identify.md);
:mod:`hil.identify.intersample`'s band-limited input uses it."""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

#: The lags by DCTs of the signal rather than FFTs of its even extension (off: see the
#: module docstring).
DCT = False


def even_filtered(c: np.ndarray, re: np.ndarray, im: np.ndarray) -> np.ndarray:
    """The first ``n`` samples of the even extension ``[y, y[::-1]]`` (``2n`` samples)
    filtered by ``H`` (Hermitian, no Nyquist term: the even extension has none), from
    ``c = dct(y, 2)`` (along the last axis) and ``re``, ``im``: ``H``'s parts on the
    extension's first ``n`` bins, divided by ``2n``. The extension's bin ``k`` is
    ``exp(j pi k / 2n) c[k]``, so its inverse transform's first half is a DCT-III of
    ``c Re H`` less a DST-III of ``c Im H`` (shifted by one bin)."""
    return even_filtered_parts(c * re, c * im)


def even_filtered_parts(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`even_filtered` from ``a = c Re H`` and ``b = c Im H`` (both overwritten)."""
    # the DST-III's input is b one bin on: its first bin's sine is zero, its last the
    # extension's Nyquist bin, which is zero
    b[..., :-1] = b[..., 1:]
    b[..., -1] = 0.0
    out = scipy.fft.dct(a, 3, axis=-1, overwrite_x=True)
    out -= scipy.fft.dst(b, 3, axis=-1, overwrite_x=True)
    return out


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
    # the even extensions, written straight from the signals (no head copied first)
    ext = np.empty((len(ys), n if DCT else 2 * n))
    head = ext[:, :n]
    for i, y in enumerate(ys):
        head[i] = y[:n]
    if not np.all(np.isfinite(head)):
        return [_sensor_lag_foh(y, tau, dt) for y in ys]
    if DCT:
        re, im = _lag_parts(n, tau, dt)
        filtered = even_filtered(scipy.fft.dct(head, 2, axis=1, overwrite_x=True), re, im)
    else:
        ext[:, n:] = head[:, ::-1]
        # scipy's pocketfft, numpy's transforms to the bit, with the input's buffer
        # reused for the work (numpy's copies it first: a tenth of the call)
        spec = scipy.fft.rfft(ext, axis=1, overwrite_x=True)
        spec *= _lag_response(ext.shape[1], tau, dt)
        filtered = scipy.fft.irfft(spec, ext.shape[1], axis=1, overwrite_x=True)
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


def _lag_parts(n: int, tau: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The lag's response on the first ``n`` bins of a ``2n``-sample even extension,
    real and imaginary parts over ``2n`` (:func:`even_filtered`; kept as
    :func:`_lag_response`)."""
    key = (-n, float(tau), float(dt))
    hit = _LAG_CACHE.get(key)
    if hit is None:
        if len(_LAG_CACHE) > 16:
            _LAG_CACHE.clear()
        h = _lag_response(2 * n, tau, dt)[:n] / (2 * n)
        hit = np.stack([h.real, h.imag])
        _LAG_CACHE[key] = hit
    return hit[0], hit[1]


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


__all__ = ["DCT", "even_filtered", "even_filtered_parts", "sensor_lag", "sensor_lags"]
