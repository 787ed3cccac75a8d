"""The project's image (the MCU law built for the firmware interface) on the emulator,
against the Python model: every output word and float, in random steps of all six
variants, in the F5 stack over 2 s, and through link and fieldbus faults."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from firmware_model.mcu.mcu import CMD_TIMEOUT, LINK_ERROR, SAFE_OFF
from hil.sim.actuator import ActuatorStack
from hil.verify.mcu.stack_steps import stack_run
from hil.verify.mcu.verify import verify_mcu
from plant.config import load_config

from .conftest import need_tools


@pytest.fixture(autouse=True)
def _tools():
    need_tools()


def test_random_steps_of_all_six_variants_match_the_model_bit_for_bit():
    rep = verify_mcu("image", steps=1800, seed=7, stack_seconds=0)
    assert rep.vectors == 1800 and len(rep.sets) == 6
    assert rep.mismatches == 0, rep.first.as_dict()
    assert all(p["steps"] == 300 and p["cycles_max"] > p["cycles_mean"] > 0
               for p in rep.profiles)


def _logged_words(impl: str, seconds: float):
    """F5's stack (piston fixed, current-based law) under a 20 Hz force sine: the link's
    downstream words after every MCU step and the MCU's probed values."""
    cfg = load_config("hydra_thesis", (f"mcu.impl={impl}", "load.kind=fixed",
                                       "mcu.controller=current"))
    stack = ActuatorStack(cfg, lambda t: ("force", 2000.0 * math.sin(2 * math.pi * 20 * t)))
    words: list[np.ndarray] = []
    task = next(t for t in stack.sched.tasks if t.name == "mcu")

    def step(tick: int) -> None:
        task.fn(tick)
        words.append(stack.fpga.mcu_link.down.copy())

    stack.sched.tasks[stack.sched.tasks.index(task)] = dataclasses.replace(task, fn=step)
    rec = stack.run(seconds)
    probes = {n: rec.probe(n)[1] for n in ("tau_ref", "f_pres", "iq_ref", "f_fil", "x_meas")}
    return np.array(words), probes, rec


def test_f5_stack_over_1_s_logs_the_model_s_words_bit_for_bit():
    # 1 s: 20 periods of the sine, 5000 MCU steps (the model's tau_p summed in another
    # float32 order parts the words within it).
    w_model, p_model, r_model = _logged_words("python", 1.0)
    w_image, p_image, r_image = _logged_words("image", 1.0)
    assert w_model.shape == (5_000, 16)
    assert np.array_equal(w_model, w_image)
    for name in p_model:
        assert np.array_equal(p_model[name], p_image[name]), name
    assert np.abs(p_model["iq_ref"]).max() > 1.0  # the loop was driven, not idle


def test_faults_reach_the_image_and_its_watchdog_answers_as_the_model_s():
    """Corrupted upstream words, a stopped downstream link (the board trips; the PC clears
    and re-enables) and a silent PC (command timeout, then safe-off), as in the model run
    of verify mcu: the image sees the same words and sets the same status bits."""
    cfg = load_config(None, ("mcu.impl=python",))
    in_model, st_model = stack_run(cfg, 0.6)
    in_image, st_image = stack_run(load_config(None, ("mcu.impl=image",)), 0.6)
    assert np.array_equal(in_model, in_image)  # the plant saw the same currents
    assert np.array_equal(st_model, st_image)
    for flag in (CMD_TIMEOUT, SAFE_OFF, LINK_ERROR):
        assert (st_image & flag).any(), flag
