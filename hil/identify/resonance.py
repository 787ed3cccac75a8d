"""The piston's resonance in a record: where the measured pressure difference rings, and the
series stiffness that puts the model's resonance there.

A piston on the oil column (and on the rod, with the conrod) rings at
``sqrt((k_s + k_rod) / J_c)``, about 1.35 kHz on the preset. A seal that holds the piston
rings it at every break-away, so the measured pressure difference shows the resonance as a
line tens of times above its neighbourhood. An output-error fit started with ``k_s`` at the
preset can settle in a minimum whose resonance sits elsewhere, the seal's law and the
pressure lag taking up the mismatch (conrod, both frictions and the pulsation, rig seed 2:
``k_s`` 1.16x the rig's, the model's line at 1423 Hz for the record's 1340 Hz, the pressure
differences 59 % predictable); a refit started from the stiffness that moves the model's line
onto the record's reaches the rig's basin (docs/identify.md, *The conrod triple at seed 2*).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.signal import welch

from hil.identify.experiment import Experiment
from hil.identify.model import IDX

#: The band searched for the line, as a share either side of the model's undamped resonance.
BAND = 0.3
#: A line counts where its power stands this many times above the band's median power (the
#: held-seal records: 83-170x; the conrod without a seal, whose piston nothing rings: 2x).
MIN_LINE_RATIO = 20.0
#: The model's line within this share of the record's: nothing to move.
SAME_LINE = 0.01
#: A descent started with the model's line on the record's has left it once the model's
#: undamped resonance is this share away from where it started (:func:`line_left`): the
#: polishes that keep the line move it by a few per cent (conrod triple, 16 s, rig seed 3:
#: at most 3.5 %), the one that went to the far basin by 28 % in its second step (seed 1:
#: ``J_c`` 2.1x, ``k_s`` 1.07x).
LINE_KEPT = 0.15


def spectral_line(y: np.ndarray, fs: float, lo: float, hi: float) -> tuple[float, float]:
    """(frequency Hz, power over the band's median) of the strongest Welch bin of ``y``
    between ``lo`` and ``hi`` Hz (about 1 Hz bins); (0, 0) where the band holds no bin."""
    nper = int(min(y.size, 2 ** int(math.log2(fs))))
    f, p = welch(y - np.mean(y), fs=fs, nperseg=nper)
    sel = (f >= lo) & (f <= hi)
    if not sel.any():
        return 0.0, 0.0
    med = float(np.median(p[sel]))
    k = int(np.argmax(p[sel]))
    return float(f[sel][k]), (float(p[sel][k]) / med if med > 0 else 0.0)


def undamped_hz(exp: Experiment, theta: np.ndarray) -> float:
    """The model's piston resonance without damping (Hz): ``k_s`` and the rod on ``J_c``."""
    k_rod = theta[IDX["k_rod"]] if exp.load == "conrod" else 0.0
    return math.sqrt((theta[IDX["ks"]] + k_rod) / theta[IDX["jc"]]) / (2.0 * math.pi)


def line_left(exp: Experiment, start: np.ndarray) -> Callable[[np.ndarray], bool]:
    """For a fit started at ``start`` with the model's piston line on the record's: a test
    of a parameter vector, True where its undamped resonance (:func:`undamped_hz`) is more
    than :data:`LINE_KEPT` from the start's. Such a fit trades the line for another basin
    (``J_c`` taking up the seal's friction: the model's line far below the record's) and is
    stopped there rather than run to that basin's end."""
    f_start = undamped_hz(exp, start)
    return lambda theta: abs(undamped_hz(exp, theta) / f_start - 1.0) > LINE_KEPT


def stiffness_at_line(exp: Experiment, theta: np.ndarray, outputs: dict[str, np.ndarray],
                      configured: np.ndarray | None = None
                      ) -> tuple[float, float, float] | None:
    """``(k_s, record's line Hz, model's line Hz)``: the series stiffness that moves the
    model's piston line (in its simulated ``outputs`` at ``theta``) onto the record's, the
    rest of the model as it is (the line's square scales with ``k_s + k_rod``). None where
    the piston is fixed, the record shows no line (:data:`MIN_LINE_RATIO`) or the model's is
    already on it (:data:`SAME_LINE`).

    The record's line is looked for within :data:`BAND` of the model's undamped resonance.
    Where that band lies wholly above the record's (the model's piston rings above the
    Nyquist frequency: free piston, both frictions under the multisine, rig seed 2, ``J_c``
    at 0.07x the rig's, the model's line at 3.4 kHz) and ``configured`` (the configured
    parameter vector) is given, it is looked for around the configured resonance instead,
    and the model's undamped resonance stands for its line (its outputs cannot show it)."""
    pair = ("p_pump_a", "p_pump_b")
    if exp.load == "fixed" or not all(c in outputs and c in exp.measured for c in pair):
        return None
    fs = exp.data.sample_rate_hz
    top = 0.95 * 0.5 * fs
    centre = undamped_hz(exp, theta)
    beyond = (1.0 - BAND) * centre >= top and configured is not None
    if beyond:
        centre = undamped_hz(exp, configured)
    lo, hi = (1.0 - BAND) * centre, min((1.0 + BAND) * centre, top)
    measured = exp.measured[pair[0]] - exp.measured[pair[1]]
    f_rec, ratio = spectral_line(measured, fs, lo, hi)
    f_mod = (undamped_hz(exp, theta) if beyond
             else spectral_line(outputs[pair[0]] - outputs[pair[1]], fs, lo, hi)[0])
    if ratio < MIN_LINE_RATIO or not f_mod > 0 or abs(f_rec / f_mod - 1.0) <= SAME_LINE:
        return None
    k_rod = theta[IDX["k_rod"]] if exp.load == "conrod" else 0.0
    ks = (theta[IDX["ks"]] + k_rod) * (f_rec / f_mod) ** 2 - k_rod
    return (float(ks), f_rec, f_mod) if ks > 0 else None


__all__ = ["line_left", "spectral_line", "stiffness_at_line", "undamped_hz"]
