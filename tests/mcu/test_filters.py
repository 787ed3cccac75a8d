"""The MCU's filter and loop blocks: behaviour and float32 throughout."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_model.mcu.filters import (
    DerivativeFilter,
    HighPassFilter,
    LowPassFilter,
    MomentumObserver,
    PIController,
)

F32 = np.float32
DT = 2e-4  # the MCU's 5 kHz


def test_low_pass_step_reaches_1_minus_1_over_e_after_one_time_constant():
    lp = LowPassFilter(20.0, DT)
    n = round(1.0 / (2 * math.pi * 20.0) / DT)
    for _ in range(n):
        y = lp(F32(1.0))
    assert y == pytest.approx(1 - math.exp(-1), abs=0.01)
    assert type(y) is np.float32


def test_high_pass_starts_at_rest_and_forgets_a_constant():
    hp = HighPassFilter(1.0, DT)
    assert hp(F32(50.0)) == 0.0  # the first sample is the reference, no step response
    y = hp(F32(60.0))
    assert y == pytest.approx(10.0 * float(hp.a), rel=1e-6)
    for _ in range(20000):
        y = hp(F32(60.0))
    # In float32, y + u - u_prev rounds y to the ulp of u (3.8e-6 at 60): the decay stalls
    # once a step is below that, here at ~1.5e-3, as it does on the Cortex-M4.
    assert abs(float(y)) < 2e-3 and type(y) is np.float32


def test_derivative_of_a_ramp_is_its_slope():
    d = DerivativeFilter(500.0, DT)
    for k in range(1, 200):
        y = d(F32(3.0 * k * DT))
    assert float(y) == pytest.approx(3.0, rel=1e-3)


def test_pi_output_and_integration():
    pi = PIController(2.0, 10.0, DT)
    assert pi(F32(1.5)) == F32(3.0)
    pi.integrate(F32(1.5))
    assert pi.integral == F32(10.0) * F32(1.5) * F32(DT)
    pi.reset()
    assert pi.integral == 0.0


def test_momentum_observer_finds_a_constant_disturbance():
    """J dv/dt = tau_in - tau_out - 40 N: the observer converges to the missing 40 N."""
    j = 118.0
    obs = MomentumObserver(j, 30.0, DT)
    v = 0.0
    for _ in range(2000):
        r = obs(F32(v), F32(100.0), F32(0.0))
        v += (100.0 - 40.0) / j * DT
    assert float(r) == pytest.approx(-40.0, rel=0.01)
