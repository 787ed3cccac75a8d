"""The template an engineer copies (firmware_model/mcu/image/template): its own Makefile
builds it with arm-none-eabi-gcc, and the image closes the force loop in the harness."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.cli import main
from hil.sim.actuator import ActuatorStack
from hil.sim.image import build
from plant.config import load_config

from .conftest import need_tools


@pytest.fixture(scope="module")
def template_elf():
    need_tools()
    return build.template_image()


def test_the_template_tracks_a_force_sine_with_the_piston_fixed(template_elf):
    cfg = load_config("hydra_thesis", ("mcu.impl=image", f"mcu.image={template_elf}",
                                       "load.kind=fixed"))
    amp = 1000.0  # inside the firmware force limit
    stack = ActuatorStack(cfg, lambda t: ("force", amp * math.sin(2 * math.pi * 10 * t)))
    rec = stack.run(0.3)
    t, ref = rec.probe("tau_ref")
    _, f = rec.probe("f_pres")
    late = t > 0.1
    assert np.abs(ref[late]).max() == pytest.approx(amp, rel=0.01)
    # the loop follows: the error well below the amplitude, the force really moving
    assert np.abs(f[late]).max() > 0.7 * amp
    assert np.sqrt(np.mean((f[late] - ref[late]) ** 2)) < 0.3 * amp
    assert stack.mcu.profile.steps == 1500


@pytest.mark.slow
def test_the_template_passes_f5(template_elf, capsys):
    code = main(["run", "f5", "--mcu-image", str(template_elf)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "MCU image execution time" in out and "firmware.elf" in out
