"""Noise on the logged input, and what it leaves in an output-error residual.

The fit simulates the model from the logged current, and a logged current carries converter
noise (about one LSB of a 12-bit +-40 A converter, ~0.02 A). The plant never saw that noise;
the simulation does, so the residual holds the noise filtered by the model: coloured, peaked
at the hydraulic resonance. Judged as if it were white sensor noise it looks like structure.

* :func:`estimate_input_noise` — the noise level from the current's own spectrum: the
  excitation occupies lines or a band, the noise the whole band, so the spectrum's floor
  (the median of the Welch spectrum over the upper half of the band, where an actuator's
  excitation has little power) gives the white-noise density;
* :func:`predicted_residual` — the same noise pushed through the fitted model (a simulation
  with synthetic white noise of that level added to the current, minus one without): its
  spectrum is what the residual must hold even when the model is right. The residual
  analysis whitens each residual with that spectrum plus a white sensor floor before it tests
  whiteness and predictability (:mod:`hil.identify.residuals`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.signal import welch

from hil.identify.csvdata import MeasuredData
from hil.identify.experiment import Experiment

#: Seed of the synthetic noise realisation (the prediction is a spectrum, any seed does).
NOISE_SEED = 20240611


@dataclass
class InputNoise:
    """White noise on the logged current: rms (A) and how it was found."""

    rms_a: float
    density_a2_per_hz: float
    band_hz: tuple[float, float]
    lsb_a: float  # the current's quantisation step, 0 if continuous

    def as_dict(self) -> dict:
        return {"rms_a": self.rms_a, "density_a2_per_hz": self.density_a2_per_hz,
                "band_hz": list(self.band_hz), "lsb_a": self.lsb_a,
                "rms_lsb": self.rms_a / self.lsb_a if self.lsb_a > 0 else None}


def _nperseg(n: int, fs: float) -> int:
    return int(min(n, 2 ** int(np.ceil(np.log2(fs / 2.0)))))  # ~2 Hz bins


def estimate_input_noise(iq: np.ndarray, fs: float, lsb_a: float = 0.0) -> InputNoise:
    """White-noise level of ``iq`` (A) from the floor of its spectrum (module docstring)."""
    f, p = welch(iq - np.mean(iq), fs=fs, nperseg=_nperseg(iq.size, fs))
    lo, hi = 0.25 * fs, 0.49 * fs
    sel = (f >= lo) & (f <= hi)
    density = float(np.median(p[sel])) if sel.any() else 0.0
    # one-sided density: white noise of variance s^2 has p = 2 s^2 / fs
    rms = float(np.sqrt(max(density, 0.0) * fs / 2.0))
    return InputNoise(rms, density, (lo, hi), lsb_a)


def noisy_experiment(exp: Experiment, rms_a: float, iq: np.ndarray | None = None) -> Experiment:
    """``exp`` with white noise of ``rms_a`` added to its logged current (fixed seed), or to
    ``iq`` in its place."""
    rng = np.random.default_rng(NOISE_SEED)
    base = exp.iq if iq is None else iq
    return experiment_with_current(exp, base + rng.normal(0.0, rms_a, exp.n))


#: A line of the current's spectrum is kept as signal when its power exceeds this multiple of
#: the white noise's expected power per line: a noise-only line's power is exponentially
#: distributed, so it passes with probability exp(-10) (5e-5), and an excitation line (tens of
#: dB above the floor) is kept whole.
SIGNAL_LINE_FACTOR = 10.0


def clean_current(iq: np.ndarray, noise: InputNoise) -> np.ndarray:
    """An estimate of the current the plant felt: ``iq`` with every line of its spectrum that
    does not stand :data:`SIGNAL_LINE_FACTOR` above the white floor set to zero."""
    x = np.fft.rfft(iq - np.mean(iq))
    per_line = iq.size * noise.rms_a ** 2  # E|X_k|^2 of white noise of that rms
    x[np.abs(x) ** 2 < SIGNAL_LINE_FACTOR * per_line] = 0.0
    return np.fft.irfft(x, iq.size) + np.mean(iq)


def experiment_with_current(exp: Experiment, iq: np.ndarray) -> Experiment:
    """``exp`` with its logged current replaced by ``iq``."""
    cols = dict(exp.data.columns)
    cols["iq"] = iq
    data = MeasuredData(exp.data.path, exp.data.load, exp.data.sample_rate_hz, exp.data.t,
                        cols, dict(exp.data.header), list(exp.data.ignored))
    return dataclasses.replace(exp, data=data)


def held_noise_models(exp: Experiment, noise: InputNoise) -> tuple:
    """(model from the cleaned current, model from it plus a noise of the logged level): the
    input-noise increment of a model whose friction can hold the piston (module docstring)."""
    from hil.identify.model import FastModel

    clean = clean_current(exp.iq, noise)
    return (FastModel(experiment_with_current(exp, clean)),
            FastModel(noisy_experiment(exp, noise.rms_a, clean)))


def predicted_residual(simulate_clean: dict[str, np.ndarray],
                       simulate_noisy: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per channel, the part of the outputs that input noise alone makes (noisy - clean)."""
    return {c: simulate_noisy[c] - simulate_clean[c] for c in simulate_clean}


__all__ = ["InputNoise", "clean_current", "estimate_input_noise", "experiment_with_current",
           "held_noise_models", "noisy_experiment", "predicted_residual"]
