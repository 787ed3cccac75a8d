"""The input between its samples: what the logged current did between two log rows.

A log holds samples of the q-axis current ``i_q(t_k)``; the model needs the current over each
of its sub-steps. How the current behaved between samples is a property of the data, as in
MATLAB's ``iddata.InterSample``:

* ``zoh`` — held: a digital command applied exactly from each sample on (a current reference
  sent to an ideal drive, the project's own ``identify-synth`` data);
* ``foh`` — first-order hold: the current moved linearly between samples (a continuous signal
  sampled fast enough, with corners: a current-loop step response, a triangle);
* ``bl`` — band-limited: a continuous signal with no content above half the sample rate,
  recovered exactly by sinc interpolation (a measured current behind an anti-alias filter).

Holding a sampled continuous current (``zoh`` on such data) delays it by half a sample on
average: fitted, that shows as a spurious -T/2 "input delay". The helpers here give the
average of the input over every model sub-step, shifted by a delay ``d`` (the applied current
is ``i(t - d)``; ``d`` may be negative for a sub-sample timing skew between the logged input and
the outputs), each exact for its intersample behaviour: the average, not the midpoint value,
because the exactly discretised model holds each sub-step's input constant.

Before the first sample the first value is held, after the last the last one.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from hil.identify import lag

MODES = ("zoh", "foh", "bl")
#: The band-limited input from the input's DCT (:func:`_bandlimited_dct`) rather than an
#: inverse FFT of its even extension per sub-step.
DCT = True
#: Samples of held value padded on each side so a shifted window never leaves the record.
_PAD = 4


def _padded(u: np.ndarray, pad: int) -> np.ndarray:
    return np.concatenate([np.full(pad, u[0]), u, np.full(pad, u[-1])])


def substep_average(u: np.ndarray, dt: float, n_sub: int, delay_s: float, mode: str
                    ) -> np.ndarray:
    """Average of ``u(t - delay_s)`` over each of the ``n_sub`` sub-steps of every sample
    interval ``[t_k, t_k + dt)``; ``u`` interpolated between samples as ``mode`` says.

    Returns ``n * n_sub`` values, sub-step ``j`` of sample ``k`` at index ``k * n_sub + j``.
    """
    if mode not in MODES:
        raise ValueError(f"unknown intersample mode {mode!r} (one of {', '.join(MODES)})")
    u = np.asarray(u, dtype=float)
    n = u.size
    h = dt / n_sub
    if mode == "bl":
        return _bandlimited(u, dt, n_sub, delay_s)
    pad = _PAD + int(np.ceil(abs(delay_s) / dt))
    up = _padded(u, pad)
    # sub-step edges in units of samples, relative to the padded start
    edges = (np.arange(n * n_sub + 1) * h - delay_s) / dt + pad
    if mode == "zoh":
        cum = np.concatenate([[0.0], np.cumsum(up)])  # integral at sample edges, in sample units
        big = np.interp(edges, np.arange(cum.size), cum)
    else:  # foh: the integral of a piecewise-linear u is piecewise quadratic
        k = np.clip(np.floor(edges).astype(np.int64), 0, up.size - 2)
        tau = edges - k
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (up[:-1] + up[1:]))])
        big = cum[k] + up[k] * tau + 0.5 * (up[k + 1] - up[k]) * tau * tau
    return np.diff(big) * dt / h


def _bandlimited(u: np.ndarray, dt: float, n_sub: int, delay_s: float) -> np.ndarray:
    """Sinc interpolation by FFT on the even extension (no jump at the record's ends), the
    sub-step average as the box filter ``sinc(f h)`` and the shift as a phase ramp."""
    if DCT:
        return _bandlimited_dct(u, dt, n_sub, delay_s)
    n = u.size
    h = dt / n_sub
    key = (hash(u.tobytes()), n, dt, n_sub)
    # a fit asks for many delays of the same input, and the candidates' tests for them at
    # half the sub-steps: a few slots (each entry set whole: safe from the fit's threads)
    hit = _BL_CACHE.get(key)
    if hit is None:
        ext = np.concatenate([u, u[::-1]])
        f = np.fft.rfftfreq(ext.size, dt)
        hit = (np.fft.rfft(ext) * np.sinc(f * h), f, ext.size)
        if len(_BL_CACHE) >= _BL_SLOTS:
            _BL_CACHE.clear()
        _BL_CACHE[key] = hit
    spec, f, size = hit
    out = np.empty((n, n_sub))
    for j in range(n_sub):
        shift = (j + 0.5) * h - delay_s  # value at t_k + shift
        out[:, j] = np.fft.irfft(spec * np.exp(2j * np.pi * f * shift), size)[:n]
    return out.ravel()


def _bandlimited_dct(u: np.ndarray, dt: float, n_sub: int, delay_s: float) -> np.ndarray:
    """:func:`_bandlimited` from the input's DCT-II (the even extension's spectrum but for
    a phase) and, per sub-step, one DCT-III and one DST-III of ``n`` samples back
    (:func:`hil.identify.lag.even_filtered`), all sub-steps in one batch: the same values
    to ~1e-15, in under half the time of an inverse FFT of ``2n`` samples per sub-step."""
    n = u.size
    h = dt / n_sub
    key = ("dct", hash(u.tobytes()), n, dt, n_sub)
    hit = _BL_CACHE.get(key)
    if hit is None:
        f = np.fft.rfftfreq(2 * n, dt)[:n]
        w = 2.0 * np.pi * f
        # the box filter and the inverse transform's 1/2n kept with the input's transform,
        # and each sub-step's phase from the first one's (j h later): a delay then costs
        # one cosine and one sine per bin, not one per bin and sub-step
        c = scipy.fft.dct(u, 2) * (np.sinc(f * h) / (2 * n))
        offset = np.multiply.outer(np.arange(n_sub) * h, w)
        hit = (c * np.cos(offset), c * np.sin(offset), w)
        if len(_BL_CACHE) >= _BL_SLOTS:
            _BL_CACHE.clear()
        _BL_CACHE[key] = hit
    c_cos, c_sin, w = hit
    phase = w * (0.5 * h - delay_s)  # the first sub-step's value at t_k + h/2 - delay
    cos, sin = np.cos(phase), np.sin(phase)
    # c H on sub-step j: c exp(i (phase + j h w)), its real and imaginary parts
    a = c_cos * cos
    a -= c_sin * sin
    b = c_sin * cos
    b += c_cos * sin
    values = lag.even_filtered_parts(a, b)
    return values.T.ravel()


#: The last inputs' even-extension spectra times the sub-step box filter (or DCTs).
_BL_CACHE: dict[tuple, tuple] = {}
_BL_SLOTS = 4


__all__ = ["MODES", "substep_average"]
