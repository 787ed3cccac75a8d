"""A fit that sees the pressures below the piston's line only: the first stage of
:meth:`hil.identify.pipeline._Loop.restart_slow_first`.

A piston rung by its seal's break-aways makes the pressure differences ring at the line
``sqrt(k_s/J_c)`` (about 1.25 kHz on the free piston). An output-error cost over a lightly
damped ring is multimodal in the ring's frequency and phase: a model whose line sits a tenth
off does better by not ringing at all, and its fit settles where the pressure sensors' lag
filters the line away while the slow parameters (the current's gain, the friction laws) take
up what the ring leaves (docs/identify.md, *The free piston's two frictions under the
multisine: four held values, one narrow basin*). Low-passed below the line, the pressures
cannot pin ``k_s``, ``J_c`` or the lag, and the slow parameters find the record's values;
the full band then frees the line's two. The line's skirt still reaches below the cut-off
(at 0.4 of the line the response is 1.2x the static one), so the line is put where the
record has it before the slow part (docs/identify.md, *... at rig seeds 1 and 2*).

The filter is causal and the same on the measured and the simulated pressures, so the
residual is the full-band residual filtered: a fit's head (``n_stop``) has the same values
as the whole record's.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.signal import butter, sosfilt

from hil.identify.experiment import Experiment
from hil.identify.model import PRESSURE_CHANNELS, FastModel


class LowPassedPressures:
    """``model`` with its pressure outputs, and a copy of its experiment with the measured
    pressures, low-passed below ``cutoff_hz`` (fourth-order Butterworth, causal); every other
    channel and attribute as ``model``'s."""

    def __init__(self, model: FastModel, cutoff_hz: float) -> None:
        self._model = model
        exp = model.exp
        self._sos = butter(4, cutoff_hz, fs=exp.data.sample_rate_hz, output="sos")
        self.exp: Experiment = copy.copy(exp)
        self.exp.measured = dict(exp.measured)
        for c in PRESSURE_CHANNELS:
            if c in exp.measured:
                self.exp.measured[c] = sosfilt(self._sos, exp.measured[c])

    def __getattr__(self, name: str):
        return getattr(self._model, name)

    def outputs(self, theta: np.ndarray, z: np.ndarray | None = None,
                n_stop: int | None = None, channels: frozenset[str] | None = None
                ) -> dict[str, np.ndarray]:
        out = dict(self._model.outputs(theta, z, n_stop=n_stop, channels=channels))
        for c in PRESSURE_CHANNELS:
            if c in out:
                out[c] = sosfilt(self._sos, out[c])
        return out


def pressures_finite(exp: Experiment) -> bool:
    """True where every measured pressure is finite (the filter would smear a gap)."""
    return all(bool(np.isfinite(exp.measured[c]).all())
               for c in PRESSURE_CHANNELS if c in exp.measured)


__all__ = ["LowPassedPressures", "pressures_finite"]
