"""The sensor chips in vector lanes (plant.sensors.lanes) against the scalar
plant.sensors.harness.digitise: over random batches of actuators whose chips differ (dead
encoders, encoder resolutions, a modulus that is not a power of two, which takes the scalar
path, rod-temperature sensor fitted or not, strain ADC rates) and random plant outputs
(beyond every converter's range too), every tick's raw words bit for bit, held words
included."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from plant import lanes
from plant import layout as L
from plant.config import load_config
from plant.lane_outputs import load_outputs
from plant.lanes import LW
from plant.sensors import chips as K
from plant.sensors import lanes as SL
from plant.sensors.harness import ANALOG_ROWS, digitise

_BASE = K.chip_params(load_config(None))
_FITTED = [K.K_ANALOG + 4 * q + 3 for q in range(ANALOG_ROWS.size)]


@st.composite
def chips(draw):
    k = _BASE.copy()
    k[K.K_MOTOR_DEAD] = draw(st.sampled_from([0.0, 0.0, 1.0]))
    k[K.K_PISTON_DEAD] = draw(st.sampled_from([0.0, 0.0, 1.0]))
    k[K.K_SSI_N] = draw(st.sampled_from([2048.0, 2.0**13, 2.0**20, 3000.0]))
    k[K.K_BISS_MOD] = draw(st.sampled_from([2.0**32, 2.0**26, 2.0**36]))
    k[K.K_BISS_ZERO] = draw(st.sampled_from([0.0, 8388608.0, -12345.0]))
    k[K.K_ODR] = draw(st.sampled_from([4800.0, 1000.0, 19200.0, 50.0]))
    k[K.K_HALL_OFFSET] = draw(st.floats(-3.0, 3.0))
    k[K.K_SSI_MOUNT] = draw(st.floats(-3000.0, 3000.0))
    for f in _FITTED:
        k[f] = draw(st.sampled_from([0.0, 1.0]))
    return k


def outputs(draw):
    f = st.floats
    y = np.zeros(L.N_OUTPUTS)
    y[L.Y_THETA_M] = draw(st.one_of(f(-10.0, 10.0), f(-1e9, 1e9)))
    y[L.Y_X_PISTON] = draw(st.one_of(f(-0.05, 0.05), f(-50.0, 50.0)))
    y[L.Y_F_STRAIN] = draw(st.one_of(f(-3e3, 3e3), f(-1e5, 1e5)))
    y[L.Y_IA] = draw(f(-60.0, 60.0))
    y[L.Y_IB] = draw(f(-60.0, 60.0))
    for r in ANALOG_ROWS:
        y[r] = draw(st.one_of(f(-1e7, 2e7), f(-50.0, 200.0)))
    return y


@settings(max_examples=25, deadline=None)
@given(data=st.data(), ks=st.lists(chips(), min_size=1, max_size=LW),
       extra=st.integers(0, 3), tick0=st.one_of(st.integers(0, 3), st.integers(0, 1 << 36)),
       ticks=st.integers(1, 4), seed=st.integers(0, 2**32))
def test_digitise_in_lanes_is_the_scalar_digitise_bit_for_bit(data, ks, extra, tick0, ticks,
                                                              seed):
    """Up to LW actuators in one batch (rows of a larger array, out of order): after each
    tick every raw word equals what the scalar digitise gives each actuator alone."""
    _against_scalar(ks, extra, tick0, ticks, seed, lambda: outputs(data.draw))


def _far_outputs(draw):
    """Plant outputs some of which are beyond the lanes' fast conversions (a count or a
    code of 2**51 or more, a NaN): the lanes then take the general conversions."""
    y = outputs(draw)
    far = st.sampled_from([1e16, -3e17, 1e22, -1e30, np.inf, np.nan])
    for r in (L.Y_THETA_M, L.Y_X_PISTON, L.Y_F_STRAIN, L.Y_IA, ANALOG_ROWS[0]):
        if draw(st.booleans()):
            y[r] = draw(far)
    return y


@settings(max_examples=25, deadline=None)
@given(data=st.data(), ks=st.lists(chips(), min_size=1, max_size=LW),
       tick0=st.integers(0, 1 << 36), ticks=st.integers(1, 3), seed=st.integers(0, 2**32))
def test_digitise_in_lanes_beyond_the_fast_conversions_range(data, ks, tick0, ticks, seed):
    """Outputs far beyond any real one (counts and codes past 2**51, past int64, NaN) in
    some lanes: the raw words still equal the scalar digitise's, bit for bit."""
    _against_scalar(ks, 0, tick0, ticks, seed, lambda: _far_outputs(data.draw))


def _against_scalar(ks, extra, tick0, ticks, seed, draw_outputs):
    """The batch of chips ``ks`` (rows of a larger array, out of order) in lanes for
    ``ticks`` ticks from ``tick0``, fresh outputs each tick from ``draw_outputs``, against
    the scalar digitise of each actuator alone."""
    rng = np.random.default_rng(seed)
    n = len(ks) + extra
    rows = rng.permutation(n)[:len(ks)]
    m = len(rows)
    k = np.tile(_BASE, (n, 1))
    for j, r in enumerate(rows):
        k[r] = ks[j]
    raw = rng.integers(-(1 << 40), 1 << 40, (n, B.N_RAW))
    ref = raw.copy()
    sb = SL.sensor_lane_buffer()
    block = np.zeros(LW, dtype=np.int64)
    block[:m] = rows
    SL.load_chips(sb, k, block, m)
    # as in the engine: the outputs in the plant lanes, the raw words in the board lanes
    pb, fb = lanes.lane_buffer(), fpl.board_buffer()
    params, state = np.zeros((n, B.N_PARAMS), np.int64), np.zeros((n, B.N_STATE), np.int64)
    down = np.zeros((n, B.DOWN_WORDS), np.int64)
    fpl.load_board(fb, params, state, raw, down, block, m)
    y = np.zeros((n, L.N_OUTPUTS))
    for t in range(tick0, tick0 + ticks):
        for r in rows:
            y[r] = draw_outputs()
        load_outputs(pb, y, np.zeros((n, 1), np.uint64), block, m)
        SL.digitise_lanes(sb, pb, fb, k, block, m, t, y, raw)
        fpl.store_board(fb, state, raw, down, block, m)
        for r in rows:
            digitise(y[r], k[r], t, ref[r])
        np.testing.assert_array_equal(raw, ref)
