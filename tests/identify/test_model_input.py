"""The current every model of an identification run is simulated from.

A sampled continuous current carries the converter's white noise over the whole band, and
the plant never felt it; above the excitation's band it is all noise. The run low-passes the
current there (zero phase), so what the model gets is closer to what the rig felt than the
log is, measured against the rig's true current, which the pipeline never sees. A current
logged as the command the motor got (``zoh``) is the input itself and stays as logged; a
band reaching near the Nyquist rate leaves nothing worth filtering.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from hil.identify.experiment import prepare
from hil.identify.noise import CUTOFF_FACTOR, lowpass_current, noisy_experiment, white_above
from hil.identify.pipeline import model_input
from hil.identify.rig import generate_rig
from plant.config import load_config


@pytest.fixture(scope="module")
def rig():
    # the conrod's default multisine: 5 A rms, 0.3-300 Hz, one LSB of converter noise
    return generate_rig("conrod_fixed", (), seconds=1.0, seed=4)


def test_the_model_gets_the_current_with_the_noise_above_its_band_removed(rig):
    cfg = load_config("hydra_default")
    exp, noise = model_input(prepare(rig.data, cfg, "bl"), lambda msg: None)
    true = rig.signals["iq_true"]
    logged = rig.data.col("iq")
    # the band ends near the multisine's 300 Hz; the corner sits above it
    assert 300.0 <= noise.cutoff_hz / CUTOFF_FACTOR <= 340.0
    err_log = np.std(logged - true)
    err_model = np.std(exp.iq - true)
    # white noise kept below ~450 Hz of 2500: ~sqrt(0.18) = 0.42 of it, plus the band's own
    assert err_model < 0.55 * err_log
    # the excitation passes whole: the lines' part of the current is not attenuated
    assert np.std(exp.iq) == pytest.approx(np.std(true), rel=2e-3)
    # the predicted noise part's realisation went through the same low-pass
    noisy = noisy_experiment(exp, noise.rms_a, None, noise.cutoff_hz)
    assert np.std(noisy.iq - exp.iq) < 0.55 * noise.rms_a


def test_a_held_command_and_a_band_up_to_nyquist_are_taken_as_logged(rig):
    cfg = load_config("hydra_default")
    exp, noise = model_input(prepare(rig.data, cfg, "zoh"), lambda msg: None)
    assert noise.cutoff_hz == 0.0
    assert np.array_equal(exp.iq, rig.data.col("iq"))
    wide = generate_rig("free_piston", (), seconds=1.0, seed=4)  # lines up to 2 kHz
    exp, noise = model_input(prepare(wide.data, cfg, "bl"), lambda msg: None)
    assert noise.cutoff_hz == 0.0
    assert np.array_equal(exp.iq, wide.data.col("iq"))


def test_the_lowpass_has_zero_phase_and_no_start_up_transient():
    fs = 5000.0
    t = np.arange(5000) / fs
    x = 2.0 + np.sin(2 * np.pi * 50.0 * t + 0.3)
    y = lowpass_current(x, fs, 450.0)
    assert np.max(np.abs(y - x)) < 1e-3


def test_a_current_fed_back_from_the_plant_is_taken_as_logged():
    # the free piston under `slide`: a position loop on the encoder plus the friction's stick
    # and slip put into the current, above the band's tenfold edge, a spectrum that falls
    # over the octave above it; the plant felt that part, and cutting it moved the fit
    cfg = load_config("hydra_default")
    slide = generate_rig("free_piston", ("seal_friction",), seconds=1.0, seed=4,
                         profile="slide")
    exp, noise = model_input(prepare(slide.data, cfg, "bl"), lambda msg: None)
    assert noise.cutoff_hz == 0.0
    assert np.array_equal(exp.iq, slide.data.col("iq"))


def test_white_above_tells_a_flat_floor_from_a_falling_spectrum():
    fs = 5000.0
    rng = np.random.default_rng(7)
    white = rng.normal(0.0, 0.02, 30000)
    assert white_above(white, fs, 450.0)
    # the same floor with a loop's answer on top (white noise through a first-order lag at
    # 300 Hz): 3.6x the floor at 450-550 Hz, 1.3x near Nyquist, as under `slide`
    a = np.exp(-2.0 * np.pi * 300.0 / fs)
    falling = white + lfilter([1.0 - a], [1.0, -a], rng.normal(0.0, 0.06, 30000))
    assert not white_above(falling, fs, 450.0)
