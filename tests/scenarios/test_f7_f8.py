"""Thesis 4.4 experiments F7 and F8 on the full stack, held to the issue's tolerances."""

from __future__ import annotations

import math

import numpy as np
import pytest

import hil.scenarios.strain as strain
from plant.config import load_config


@pytest.fixture(scope="module")
def cfg():
    return load_config("hydra_thesis")


@pytest.fixture(scope="module")
def f7(cfg):
    return strain.f7(cfg, None)


@pytest.fixture(scope="module")
def f8(cfg):
    return strain.f8(cfg, None)


def test_registered():
    from hil.scenarios import SCENARIOS

    assert {"f7", "f8"} <= set(SCENARIOS)


@pytest.mark.slow
def test_f7_pressure_feedback_error(f7):
    """Thesis 12.1 N RMS without strain feedback (the seal's Coulomb force is calibrated
    on this figure, so it checks the calibration still holds)."""
    e = f7.metric("RMS error, pressure feedback").value
    assert abs(e - 12.1) <= 4.0, e


@pytest.mark.slow
def test_f7_strain_feedback_error(f7):
    """Thesis 1.3 N RMS with strain feedback; the issue requires <= 2.5 N."""
    e = f7.metric("RMS error, strain feedback").value
    assert e <= 2.5, f"{e:.2f} N; {' '.join(f7.notes)}"


@pytest.mark.slow
def test_f7_strain_feedback_reduces_the_error(f7):
    m = f7.metric
    assert m("RMS error, strain feedback").value < m("RMS error, pressure feedback").value


@pytest.mark.slow
def test_f7_the_seal_friction_makes_the_pressure_figure(cfg):
    """Without the rod-seal friction the pressure-feedback error is far below 12.1 N: the
    calibrated effect is what produces the figure, not the loop's other errors."""
    run = strain.f7_run(cfg, "pressure", coulomb_n=0.0)
    assert run["rms"] < 0.5 * 12.1, run["rms"]


@pytest.mark.slow
@pytest.mark.parametrize("name,thesis", [("strain", 15.1), ("pressure", 6.58),
                                         ("complementary", 4.18)])
def test_f8_errors_within_40_percent(f8, name, thesis):
    e = f8.metric(f"RMS error, {name}").value
    assert abs(e - thesis) <= 0.4 * thesis, (e, f8.notes)


@pytest.mark.slow
def test_f8_order(f8):
    rms = f8.series["rms"]
    assert rms["strain"] > rms["pressure"] > rms["complementary"], rms


@pytest.mark.slow
def test_f8_strain_drift_gradient(f8):
    """Fig. 4.10: the strain reading drifts 2.5 N/degC with the rod temperature."""
    assert abs(f8.metric("strain drift vs rod temperature").value - 2.5) < 0.1


@pytest.mark.slow
def test_f8_offline_filter_matches_the_mcu(f8, cfg):
    """The cutoff sweep recomputes Eq. 4.4 from the recording; at the preset's cutoff it
    must give the MCU's own float32 figure."""
    s = f8.series
    i = int(np.argmin(np.abs(s["sweep_hz"] - cfg.get("mcu.complementary_cutoff_hz"))))
    assert s["sweep_rms"][i] == pytest.approx(s["rms"]["complementary"], rel=0.01)


def test_complementary_filter_is_complementary():
    dt = 2e-4
    n = 50000
    t = np.arange(n) * dt
    f_pres = 100.0 * np.sin(2 * math.pi * t)
    # Equal inputs pass unchanged (Eq. 4.3: the two filters sum to one).
    assert np.allclose(strain.complementary(f_pres, f_pres, 0.02, dt), f_pres)
    # A step in the strain signal alone leaks out with the high-pass time constant.
    step = np.where(t >= 1.0, 10.0, 0.0)
    out = strain.complementary(np.zeros(n), step, 0.5, dt)
    k = int(round(1.0 / dt))
    assert out[k] == pytest.approx(10.0, rel=1e-3)
    assert out[k + int(round(1.0 / (2 * math.pi * 0.5) / dt))] == pytest.approx(
        10.0 * math.exp(-1.0), rel=0.01)


@pytest.mark.slow
def test_plots(f7, f8, tmp_path):
    for res in (f7, f8):
        path = tmp_path / f"{res.name}.png"
        res.plot(res, path)
        assert path.stat().st_size > 10000
