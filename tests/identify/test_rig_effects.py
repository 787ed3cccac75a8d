"""The rig's per-effect classes against the identification library's: the same effects by
name, and the rig still the other side of the test (it loads nothing of the fitted model)."""

from __future__ import annotations

import subprocess
import sys

from hil.identify.effects import EFFECTS
from hil.identify.rig import (
    LIBRARY_EFFECTS,
    NEEDS_TEMPERATURE,
    OUTSIDE_EFFECTS,
    RIG_DEFAULT_MAGNITUDES,
)
from hil.identify.rig_effects import RIG_REGISTRY

#: Modules of the fitted model and of the plant the rig must not load, directly or through
#: another module: a rig that shared them would no longer test the fit.
FITTED_SIDE = ("hil.identify.model", "hil.identify.fit", "hil.identify.candidates",
               "hil.identify.effects", "hil.identify.experiment", "hil.identify.pipeline",
               "hil.identify.synth", "hil.identify.residuals", "hil.identify.consistency",
               "plant.model", "plant.kernel", "plant.layout")


def test_the_two_registries_name_the_same_library_effects():
    assert sorted(LIBRARY_EFFECTS) == sorted(EFFECTS)
    assert not set(OUTSIDE_EFFECTS) & set(EFFECTS)
    for name, effect in RIG_REGISTRY.items():
        assert effect.name == name
        assert effect.library == (name in EFFECTS), name


def test_rig_tables_come_from_the_classes():
    assert list(RIG_DEFAULT_MAGNITUDES) == list(RIG_REGISTRY)
    assert set(NEEDS_TEMPERATURE) == {"viscosity_temperature", "strain_thermal_drift"}


def test_the_rig_loads_nothing_of_the_fitted_model():
    code = ("import sys, hil.identify.rig, hil.identify.rig_effects; "
            "print('\\n'.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout.split()
    assert "hil.identify.rig_effects" in out  # the probe saw the rig's modules
    leaked = [m for m in FITTED_SIDE if m in out]
    assert not leaked, f"the independent rig loads the fitted side: {leaked}"


def test_the_plant_generator_makes_every_library_effect():
    from hil.identify.synth import OUTSIDE_EFFECTS as SYNTH_OUTSIDE
    from hil.identify.synth_effects import SYNTH_REGISTRY

    assert set(EFFECTS) <= set(SYNTH_REGISTRY)
    assert not set(SYNTH_OUTSIDE) & set(EFFECTS)
    assert all(e.name == n for n, e in SYNTH_REGISTRY.items())
