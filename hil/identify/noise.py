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
  whiteness and predictability (:mod:`hil.identify.residuals`). Where a seal friction can
  hold the piston the part is predicted from several draws of the noise
  (:func:`held_noise_draws`, :func:`predicted_draws`): its power there differs widely from
  one draw to the next;
* :func:`input_band` and :func:`lowpass_current` — the current the model is simulated from.
  A logged current that samples a continuous one is a measurement: above the band where its
  spectrum stands clear of the white floor it holds only the converter's noise, which the
  plant never felt. Simulated, that noise rings the model's hydraulic resonance, and an
  output-error fit then prefers parameters that damp the model's response to it (a longer
  pressure lag, a softer friction law): the errors-in-variables bias, which moves the fit's
  minimum away from the rig's even when the model is right. So the current is low-passed
  (zero phase, 8th-order Butterworth run forward and back) at :data:`CUTOFF_FACTOR` times
  the band's upper edge, for every model of the run alike; the noise inside the band stays
  (it cannot be told from the signal) and the predicted noise part is that noise through the
  same filter. A current logged as the command the motor got (``zoh``) is the input itself,
  noise and all, and is not filtered; nor is one whose band reaches near the Nyquist rate,
  nor one whose spectrum above the corner is not white (a loop closed on the plant puts
  there what the plant felt).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import butter, sosfiltfilt, welch

from hil.identify.csvdata import MeasuredData
from hil.identify.experiment import Experiment

if TYPE_CHECKING:
    from hil.identify.model import FastModel

#: Seed of the synthetic noise realisation (the prediction is a spectrum, any seed does for a
#: linear noise path; a held piston's draws take the seeds after it).
NOISE_SEED = 20240611


@dataclass
class InputNoise:
    """White noise on the logged current: rms (A) and how it was found."""

    rms_a: float
    density_a2_per_hz: float
    band_hz: tuple[float, float]
    lsb_a: float  # the current's quantisation step, 0 if continuous
    #: the low-pass the model's current went through (:func:`lowpass_current`), 0 if none
    cutoff_hz: float = 0.0

    def as_dict(self) -> dict:
        return {"rms_a": self.rms_a, "density_a2_per_hz": self.density_a2_per_hz,
                "band_hz": list(self.band_hz), "lsb_a": self.lsb_a,
                "cutoff_hz": self.cutoff_hz or None,
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


def noisy_experiment(exp: Experiment, rms_a: float, iq: np.ndarray | None = None,
                     cutoff_hz: float = 0.0, draw: int = 0) -> Experiment:
    """``exp`` with white noise of ``rms_a`` added to its logged current (fixed seed, the
    ``draw``-th realisation), or to ``iq`` in its place; the noise low-passed at
    ``cutoff_hz`` first when > 0, as the model's current was (:func:`lowpass_current`)."""
    rng = np.random.default_rng(NOISE_SEED + draw)
    base = exp.iq if iq is None else iq
    noise = rng.normal(0.0, rms_a, exp.n)
    if cutoff_hz > 0:
        noise = lowpass_current(noise, exp.data.sample_rate_hz, cutoff_hz)
    return experiment_with_current(exp, base + noise)


#: The low-pass's corner, in multiples of the band's upper edge: an 8th-order Butterworth run
#: forward and back passes |H|^2 = 1 / (1 + (f/fc)^16)^2, at the edge (f/fc = 2/3) 0.9970
#: in power, 0.15 % in amplitude, below the fit's own resolution of the gain.
CUTOFF_FACTOR = 1.5
#: Above this fraction of the Nyquist rate a low-pass would remove too little noise to matter
#: (and the floor of :func:`estimate_input_noise` is taken there): no filter.
CUTOFF_MAX_OF_NYQUIST = 0.8
BUTTER_ORDER = 8


#: Segments the band's spectrum averages at least: a noise-only bin of an average of ~2K
#: degrees of freedom stands :data:`SIGNAL_LINE_FACTOR` above the floor with a probability
#: far below one in the bins of a record (one segment: exp(-10 ln 2), a few bins per record).
BAND_SEGMENTS = 8


def input_band(iq: np.ndarray, fs: float) -> float:
    """Upper edge (Hz) of the band where the current's Welch spectrum stands
    :data:`SIGNAL_LINE_FACTOR` above its own white floor (the median over the upper half of
    the band, as :func:`estimate_input_noise` takes it); 0 if it nowhere does."""
    f, p = _welch_band(iq, fs)
    sel = (f >= 0.25 * fs) & (f <= 0.49 * fs)
    floor = float(np.median(p[sel])) if sel.any() else 0.0
    if floor <= 0:
        return 0.0
    above = f[p > SIGNAL_LINE_FACTOR * floor]
    return float(above.max()) if above.size else 0.0


#: Sub-bands above the corner whose mean power :func:`white_above` compares, and the largest
#: ratio between them that still counts as white: each mean averages hundreds of bins, a few
#: per cent apart for white noise; a current loop answering an encoder's steps or a friction's
#: stick and slip leaves a spectrum falling over the octave above the band (free piston under
#: ``slide``: 3.4x the floor at 1-1.25 kHz, 1.8x at 1.25-1.6 kHz, 0.8x near Nyquist).
WHITE_SUBBANDS = 4
WHITE_SPREAD = 1.3


def _welch_band(iq: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    nper = max(16, min(_nperseg(iq.size, fs), 2 ** int(np.log2(2 * iq.size / (BAND_SEGMENTS + 1)))))
    return welch(iq - np.mean(iq), fs=fs, nperseg=nper)


def white_above(iq: np.ndarray, fs: float, cutoff_hz: float) -> bool:
    """Whether the current's spectrum from ``cutoff_hz`` to the Nyquist rate is flat: the
    mean power of :data:`WHITE_SUBBANDS` equal sub-bands within :data:`WHITE_SPREAD` of each
    other. Only then is what a low-pass there removes the converter's noise alone; a current
    fed back from the plant (a position loop on the encoder) carries, below the white floor's
    tenfold but above the floor, what the plant felt, and removing it moves the fit."""
    f, p = _welch_band(iq, fs)
    edges = np.linspace(cutoff_hz, 0.49 * fs, WHITE_SUBBANDS + 1)
    means = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (f >= lo) & (f < hi)
        if not sel.any():
            return False
        means.append(float(np.mean(p[sel])))
    return min(means) > 0 and max(means) <= WHITE_SPREAD * min(means)


def current_cutoff(iq: np.ndarray, fs: float) -> float:
    """The low-pass corner for the model's current (module docstring), 0 for none: none
    where the band reaches near the Nyquist rate or the spectrum above the corner is not
    white (:func:`white_above`)."""
    edge = input_band(iq, fs)
    cut = CUTOFF_FACTOR * edge
    if edge <= 0 or cut > CUTOFF_MAX_OF_NYQUIST * 0.5 * fs or not white_above(iq, fs, cut):
        return 0.0
    return cut


def lowpass_current(iq: np.ndarray, fs: float, cutoff_hz: float) -> np.ndarray:
    """``iq`` through the zero-phase low-pass at ``cutoff_hz`` (module docstring); the ends
    padded by odd reflection over ten periods of the corner (no start-up transient)."""
    sos = butter(BUTTER_ORDER, cutoff_hz, fs=fs, output="sos")
    pad = int(min(iq.size - 1, max(3 * 2 * BUTTER_ORDER, 10.0 * fs / cutoff_hz)))
    return sosfiltfilt(sos, iq, padtype="odd", padlen=pad)


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


#: Realisations of the input noise a held piston's noise part is predicted from. Through a
#: seal that holds the piston the part is intermittent (each break-away the noise shifts
#: rings the piston's resonance) and its power varies widely from one noise draw to the
#: next: on the conrod with both frictions and the pulsation (rig seed 2, at the rig's
#: basin) 16 draws gave 681-2672 Pa rms on the pressure difference, the record's own 1585.
#: Eight draws span about the 11th to the 89th percentile of that power
#: (:func:`hil.identify.residuals.whiten`); each is one simulation more per judged fit.
HELD_DRAWS = 8


def held_noise_draws(exp: Experiment, noise: InputNoise, draws: int = HELD_DRAWS
                     ) -> tuple[FastModel, list[FastModel]]:
    """(model from the cleaned current, ``draws`` models from it plus independent noises of
    the logged level): the input-noise increments of a model whose friction can hold the
    piston, one per draw (module docstring). The first draw is the seed
    :data:`NOISE_SEED`'s."""
    from hil.identify.model import FastModel

    clean = clean_current(exp.iq, noise)
    return (FastModel(experiment_with_current(exp, clean)),
            [FastModel(noisy_experiment(exp, noise.rms_a, clean, noise.cutoff_hz, draw=j))
             for j in range(draws)])


def predicted_residual(simulate_clean: dict[str, np.ndarray],
                       simulate_noisy: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per channel, the part of the outputs that input noise alone makes (noisy - clean)."""
    return {c: simulate_noisy[c] - simulate_clean[c] for c in simulate_clean}


def predicted_draws(simulate_clean: dict[str, np.ndarray],
                    simulate_noisy: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per channel, the parts of the outputs that input noise alone makes in each draw, one
    row a draw (draws x samples): :func:`hil.identify.residuals.whiten` takes their
    spectra's spread as the spread of the record's own noise part."""
    return {c: np.stack([noisy[c] - simulate_clean[c] for noisy in simulate_noisy])
            for c in simulate_clean}


__all__ = ["InputNoise", "clean_current", "current_cutoff", "estimate_input_noise",
           "experiment_with_current", "held_noise_draws", "input_band",
           "lowpass_current", "noisy_experiment", "predicted_draws", "predicted_residual"]
