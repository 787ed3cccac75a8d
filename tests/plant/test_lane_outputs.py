"""The plant's outputs and sensor noise in vector lanes (plant.lane_outputs) against the
scalar kernel's (plant.kernel.outputs) bit for bit per actuator, under recipes 3 (the polar
method, lane by lane) and 4 (Box-Muller with the recipe's own log and sin/cos, in lanes);
recipe 4's log against libm, and its normal samples against N(0, 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit
from scipy import stats

from plant import kernel, lanes
from plant import layout as L
from plant.blocks.lanemath import log4
from plant.lane_outputs import outputs_lanes
from plant.sensors.readings import gauss_pair4
from tests.plant.test_lanes import actuator


@st.composite
def sensed_actuator(draw):
    """An actuator of :func:`tests.plant.test_lanes.actuator` with its sensor effects (noise,
    quantisation, strain-gauge drift) each on or off, recipe 3 or 4, and a noise stream
    state."""
    p, x, u = draw(actuator())
    for f in (L.P_NOISE_ON, L.P_QUANT_ON, L.P_DRIFT_ON):
        p[f] = float(draw(st.booleans()))
    p[L.P_NUMERICS] = float(draw(st.sampled_from([3, 4])))
    return p, x, u, draw(st.integers(1, 2**64 - 1))


def _bits(a):
    return np.ascontiguousarray(a).view(np.int64)


@settings(max_examples=80, deadline=None)
@given(acts=st.lists(sensed_actuator(), min_size=1, max_size=lanes.LW),
       ticks=st.integers(1, 3))
def test_outputs_in_lanes_are_the_scalar_kernels_bit_for_bit(acts, ticks):
    """Up to LW different actuators in one batch, ``ticks`` calls (the noise streams move
    on): each lane's output row and stream state have the scalar call's bits."""
    n = len(acts)
    P = np.array([a[0] for a in acts])
    X = np.array([a[1] for a in acts])
    U = np.array([a[2] for a in acts])
    rng = np.array([[a[3]] for a in acts], dtype=np.uint64)
    ref_y, ref_rng = np.zeros((n, L.N_OUTPUTS)), rng.copy()
    y = np.full((n, L.N_OUTPUTS), np.nan)
    buf = lanes.lane_buffer()
    rows = np.arange(n)
    lanes.load_params(buf, P, rows, n)
    lanes.load_states(buf, X, U, rows, n)
    for _ in range(ticks):
        for i in range(n):
            kernel.outputs(X[i], P[i], U[i], ref_rng[i], ref_y[i])
        outputs_lanes(buf, y, rng, rows, n)
        np.testing.assert_array_equal(_bits(y), _bits(ref_y))
        np.testing.assert_array_equal(rng, ref_rng)
    noisy = P[:, L.P_NOISE_ON] > 0.5
    assert np.all((rng[:, 0] != np.array([a[3] for a in acts], dtype=np.uint64)) == noisy)


def test_lanes_of_other_rows_leave_the_rest_alone():
    """A batch of rows 3 and 1 of five writes those rows' outputs and streams only."""
    rng0 = np.arange(1, 6, dtype=np.uint64).reshape(5, 1) * np.uint64(0x9E3779B97F4A7C15)
    p = np.tile(_params(4), (5, 1))
    x, u = np.zeros((5, L.N_STATES)), np.zeros((5, L.N_INPUTS))
    y, rng = np.full((5, L.N_OUTPUTS), -1.0), rng0.copy()
    buf = lanes.lane_buffer()
    rows = np.array([3, 1, 0, 0, 0, 0, 0, 0])
    lanes.load_params(buf, p, rows, 2)
    lanes.load_states(buf, x, u, rows, 2)
    outputs_lanes(buf, y, rng, rows, 2)
    ref_y, ref_rng = np.full((5, L.N_OUTPUTS), -1.0), rng0.copy()
    for i in (3, 1):
        kernel.outputs(x[i], p[i], u[i], ref_rng[i], ref_y[i])
    np.testing.assert_array_equal(_bits(y), _bits(ref_y))
    np.testing.assert_array_equal(rng, ref_rng)
    assert np.all(rng[[0, 2, 4]] == rng0[[0, 2, 4]])


def _params(numerics: int) -> np.ndarray:
    from plant.config import load_config
    from plant.model import build_params

    return build_params(load_config(None, [f"sim.plant_numerics={numerics}",
                                           "effects.sensor_noise.enabled=true"]))


@njit(cache=True)
def _pairs4(n, s):
    out = np.empty((n, 2))
    for i in range(n):
        s, out[i, 0], out[i, 1] = gauss_pair4(s)
    return out


def test_recipe_four_pairs_are_independent_standard_normals():
    """200 000 Box-Muller pairs of recipe 4 from the plant's xorshift stream: both
    coordinates pass a Kolmogorov-Smirnov test against N(0, 1), their moments are the
    normal's, they are uncorrelated, and the tail beyond 3 sigma has the normal's weight."""
    g = _pairs4(200_000, np.uint64(0x9E3779B97F4A7C15))
    for col in (g[:, 0], g[:, 1]):
        assert stats.kstest(col, "norm").pvalue > 1e-3
        assert abs(col.mean()) < 0.01 and abs(col.var() - 1.0) < 0.01
        assert abs(stats.skew(col)) < 0.02 and abs(stats.kurtosis(col)) < 0.05
        tail = np.mean(np.abs(col) > 3.0)
        assert tail == pytest.approx(2 * stats.norm.sf(3.0), rel=0.1)
    assert abs(np.corrcoef(g[:, 0], g[:, 1])[0, 1]) < 0.01
    assert abs(np.corrcoef(g[:-1, 1], g[1:, 0])[0, 1]) < 0.01


@njit(cache=True)
def _log4(v):
    return log4(v)


@njit(cache=True, error_model="numpy")
def _log4_loop(x, out):
    for i in range(x.shape[0]):
        out[i] = log4(x[i])


def _ulps(a, b):
    return abs(a - b) / math.ulp(abs(b)) if b != 0.0 else abs(a) / math.ulp(1e-300)


@settings(max_examples=300, deadline=None)
@given(v=st.one_of(st.floats(2.0**-52, 1.0), st.floats(1e-300, 1e300),
                   st.floats(0.999, 1.001)))
def test_log4_is_within_one_ulp_of_libm(v):
    assert _ulps(_log4(v), math.log(v)) <= 1.0


@settings(max_examples=40, deadline=None)
@given(xs=st.lists(st.floats(2.0**-52, 1.0), min_size=1, max_size=40))
def test_log4_in_a_vector_loop_equals_the_scalar_call(xs):
    x = np.array(xs)
    out = np.empty(len(x))
    _log4_loop(x, out)
    assert _bits(out).tolist() == _bits(np.array([_log4(v) for v in xs])).tolist()


def test_log4_at_exact_points():
    assert _log4(1.0) == 0.0 and _log4(0.5) == -math.log(2.0)
    for k in range(-60, 60, 7):
        assert _ulps(_log4(2.0**k), math.log(2.0**k)) <= 0.5
