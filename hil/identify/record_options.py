"""The options of a synthetic record that the command line offers, without the generators.

The generators (:mod:`hil.identify.rig`, :mod:`hil.identify.synth`) load the simulation
(numba's kernels, the plant) when imported; they take these names from here, so
``eha-hil identify-synth --help`` lists them without loading either.
"""

from __future__ import annotations

#: The rig's oil temperature shapes, degC, over a record of length R (s).
TEMPERATURE_SHAPES: dict[str, str] = {
    "constant": "25 degC (the preset's reference)",
    "ramp": "15 -> 25 degC linearly",
    "ramp_level": "15 + 7 (1 - exp(-3 t / R)): heats, then levels off near 22 degC",
    "steps": "15 degC, then +2.5 degC at R/4, R/2, 3R/4 (first-order, time constant R/60)",
    "oscillation": "20 + 3 sin(4 pi t / R): period R/2",
}

#: The rig's excitation profiles.
RIG_PROFILES: tuple[str, ...] = ("multisine", "slide", "resonance")
#: The rig's current between samples: continuous, or the logged value held.
INTERSAMPLE: tuple[str, ...] = ("continuous", "zoh")

#: Excitation profiles of the plant's generator (:func:`hil.identify.synth.generate`).
SYNTH_PROFILES: tuple[str, ...] = ("multisine", "resonance", "slide")

__all__ = ["INTERSAMPLE", "RIG_PROFILES", "SYNTH_PROFILES", "TEMPERATURE_SHAPES"]
