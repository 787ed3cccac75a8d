"""The plant kernel's arithmetic recipes (``sim.plant_numerics``): recipe 2 draws the sensor
noise in pairs by the polar method and turns phase a's angle functions for phase b; recipe 1
is what logs recorded before it ran with. Same model: the recipes differ by roundings and
by the noise realisation, never by physics or by the noise's statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit
from scipy import stats

from plant.blocks.motor_dq import TWO_PI_3, phase_angles
from plant.config import PLANT_NUMERICS, RECORDED_BEFORE, as_recorded, load_config
from plant.layout import (
    Y_F_STRAIN,
    Y_IA,
    Y_IB,
    Y_P_ACC,
    Y_P_CYL_A,
    Y_P_PUMP_A,
    Y_TEMP,
    Y_X_PISTON,
)
from plant.model import Plant
from plant.sensors.readings import _gauss_pair


@njit(cache=True)
def _pairs(n, rng):
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = _gauss_pair(rng)
    return out


def test_polar_pairs_are_independent_standard_normals():
    """200 000 pairs from the plant's xorshift stream: both coordinates pass a
    Kolmogorov-Smirnov test against N(0, 1), their moments are the normal's, they are
    uncorrelated, and the tail beyond 3 sigma has the normal's weight."""
    g = _pairs(200_000, np.array([0x9E3779B97F4A7C15], dtype=np.uint64))
    for col in (g[:, 0], g[:, 1]):
        assert stats.kstest(col, "norm").pvalue > 1e-3
        assert abs(col.mean()) < 0.01 and abs(col.var() - 1.0) < 0.01
        assert abs(stats.skew(col)) < 0.02 and abs(stats.kurtosis(col)) < 0.05
        tail = np.mean(np.abs(col) > 3.0)
        assert tail == pytest.approx(2 * stats.norm.sf(3.0), rel=0.1)
    assert abs(np.corrcoef(g[:, 0], g[:, 1])[0, 1]) < 0.01
    # Consecutive pairs are independent too (the stream is not reused).
    assert abs(np.corrcoef(g[:-1, 1], g[1:, 0])[0, 1]) < 0.01


@settings(max_examples=200, deadline=None)
@given(th=st.floats(-1e4, 1e4, allow_nan=False))
def test_phase_b_turned_from_phase_a_equals_libm_within_roundings(th):
    c, s, c2, s2 = phase_angles(th, 2.0)
    assert (c, s) == (math.cos(th), math.sin(th))
    # A few ulps of the argument's size: cos(th - 2pi/3) itself is only that accurate.
    tol = 1e-15 * max(1.0, abs(th)) * 8
    assert abs(c2 - math.cos(th - TWO_PI_3)) <= tol
    assert abs(s2 - math.sin(th - TWO_PI_3)) <= tol
    assert phase_angles(th, 1.0) == (c, s, math.cos(th - TWO_PI_3), math.sin(th - TWO_PI_3))


def _run(numerics: int, noise: bool, ticks: int = 4000) -> np.ndarray:
    cfg = load_config(None, [f"sim.plant_numerics={numerics}", "load.kind=free",
                             f"effects.sensor_noise.enabled={str(noise).lower()}"])
    plant = Plant(cfg)
    plant.set_duty(0.56, 0.45, 0.5)  # the motor turns: phase currents and angles change
    rec = np.zeros((ticks, plant.y.shape[0]))
    plant.advance(ticks, rec)
    return rec


@pytest.mark.parametrize("other", [2, 3, 4])
def test_the_recipes_give_the_same_physics(other):
    """Without noise recipes 2 and 3 agree with 1 to roundings; the phase currents, which
    use the turned angles (and recipe 3's own sin/cos), included."""
    one, two = _run(1, False), _run(other, False)
    assert not np.array_equal(one[:, Y_IB], two[:, Y_IB])  # the recipe really switched
    for col in (Y_IA, Y_IB, Y_X_PISTON, Y_P_PUMP_A):
        scale = np.max(np.abs(one[:, col]))
        assert scale > 0
        assert np.max(np.abs(one[:, col] - two[:, col])) <= 1e-9 * scale


def _noise_run(numerics: int, noise: bool, ticks: int = 4000) -> np.ndarray:
    cfg = load_config(None, [f"sim.plant_numerics={numerics}", "load.kind=fixed",
                             "effects.quantisation.enabled=false",
                             f"effects.sensor_noise.enabled={str(noise).lower()}"])
    plant = Plant(cfg)
    plant.set_force(500.0)  # chamber A and pump side A well above the precharge
    rec = np.zeros((ticks, plant.y.shape[0]))
    plant.advance(ticks, rec)
    return rec[ticks // 2:]


def test_the_recipes_draw_noise_of_the_same_size():
    """With noise, the realisations differ but each channel's noise has its configured
    size under both recipes, uncorrelated with the other channels' (a channel that lost,
    doubled or shared its noise would show)."""
    cfg = load_config(None)
    one, two, four = _noise_run(1, True), _noise_run(2, True), _noise_run(4, True)
    quiet = _noise_run(2, False)
    assert not np.array_equal(one[:, Y_P_CYL_A], two[:, Y_P_CYL_A])
    assert not np.array_equal(four[:, Y_P_CYL_A], two[:, Y_P_CYL_A])
    sigma_p = cfg.get("effects.sensor_noise.pressure_pa")
    sigmas = {Y_P_ACC: sigma_p, Y_P_PUMP_A: sigma_p, Y_P_CYL_A: sigma_p,
              Y_F_STRAIN: cfg.get("effects.sensor_noise.strain_n"),
              Y_TEMP: cfg.get("effects.sensor_noise.temperature_c")}
    for col, sigma in sigmas.items():
        assert quiet[:, col].min() > 5 * sigma or col in (Y_F_STRAIN, Y_TEMP)
        for rec in (one, two, four):
            assert np.std(rec[:, col] - quiet[:, col]) == pytest.approx(sigma, rel=0.15), col
    for rec in (one, two, four):  # and every channel draws its own samples
        noise = (rec - quiet)[:, list(sigmas)]
        corr = np.corrcoef(noise.T) - np.eye(len(sigmas))
        assert np.max(np.abs(corr)) < 0.1, corr


def test_a_log_without_the_key_ran_recipe_one():
    assert PLANT_NUMERICS == 4 and load_config(None).get("sim.plant_numerics") == 4
    assert as_recorded({"sim.seed": 3})["sim.plant_numerics"] == RECORDED_BEFORE[
        "sim.plant_numerics"] == 1
    assert as_recorded({"sim.plant_numerics": 2})["sim.plant_numerics"] == 2
    assert as_recorded({"sim.plant_numerics": 3})["sim.plant_numerics"] == 3
    assert as_recorded({"sim.plant_numerics": 4})["sim.plant_numerics"] == 4
