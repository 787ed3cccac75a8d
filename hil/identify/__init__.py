"""Identification: fit the thesis's linear EHA model to measured data, find the residual,
trace it to a missing effect, add it and report the error before and after.

Modules, one job each: :mod:`~hil.identify.csvdata` (reader, one-line errors),
:mod:`~hil.identify.experiment` (channels, schedules, split), :mod:`~hil.identify.model`
(fast exactly discretised model + effect terms), :mod:`~hil.identify.fit` (output-error fit,
HAC confidence intervals), :mod:`~hil.identify.stats`, :mod:`~hil.identify.residuals`,
:mod:`~hil.identify.candidates` (effect library and tests), :mod:`~hil.identify.pipeline`
(the loop), :mod:`~hil.identify.effects` (one class per library effect),
:mod:`~hil.identify.report`, :mod:`~hil.identify.synth` (datasets from the plant),
:mod:`~hil.identify.rig` (the independent generator; its per-effect classes in
:mod:`~hil.identify.rig_effects`), :mod:`~hil.identify.thesis` (the thesis 2.4.3
residual), :mod:`~hil.cli.identify`.
See docs/identify.md.
"""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
