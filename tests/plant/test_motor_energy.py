"""Motor and inverter in duty-cycle mode, energy balance, and integration accuracy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plant.config import linearised
from plant.layout import (
    Y_E_DISS,
    Y_E_EXT,
    Y_E_IN,
    Y_E_STORED,
    Y_ID,
    Y_IQ,
    Y_OMEGA_M,
    Y_TAU_Q,
    Y_THETA_M,
)
from plant.model import Plant, motor_torque_constant


def _voltage_vector(plant: Plant, v_q: float, v_d: float = 0.0) -> None:
    """Apply (v_d, v_q) at the rotor's present electrical angle through the duty cycles."""
    pole_pairs = plant.config.get("motor.pole_pairs")
    vdc = plant.config.get("inverter.dc_bus_v")
    th = pole_pairs * plant.y[Y_THETA_M]  # quantisation is off in these tests
    v_alpha = v_d * math.cos(th) - v_q * math.sin(th)
    v_beta = v_d * math.sin(th) + v_q * math.cos(th)
    v_a = v_alpha
    v_b = -0.5 * v_alpha + math.sqrt(3) / 2 * v_beta
    v_c = -0.5 * v_alpha - math.sqrt(3) / 2 * v_beta
    plant.set_duty(0.5 + v_a / vdc, 0.5 + v_b / vdc, 0.5 + v_c / vdc)


def test_dq_steady_state_matches_the_voltage_equations(default_cfg):
    """Piston fixed, constant v_q: i_d, i_q settle where v = R i + w_e L (x) i + w_e psi."""
    cfg = linearised(default_cfg).with_overrides({"inverter.dead_time_s": 0.0})
    plant = Plant(cfg)
    v_q = 3.0
    for _ in range(6000):
        _voltage_vector(plant, v_q)
        plant.advance(1)
    r = cfg.get("motor.resistance_ohm")
    ind = cfg.get("motor.inductance_h")
    pp = cfg.get("motor.pole_pairs")
    psi = motor_torque_constant(cfg) / (1.5 * pp)
    w_e = pp * plant.y[Y_OMEGA_M]
    # Solve [R, -w L; w L, R] [id, iq] = [0, v_q - w psi].
    a = np.array([[r, -w_e * ind], [w_e * ind, r]])
    i_d, i_q = np.linalg.solve(a, [0.0, v_q - w_e * psi])
    assert plant.y[Y_IQ] == pytest.approx(i_q, rel=0.02)
    assert abs(plant.y[Y_ID] - i_d) < 0.02 * abs(i_q)
    assert i_q > 5.0  # a real operating point, not a trivial zero


def test_dead_time_costs_voltage(default_cfg):
    """Dead time acts as a voltage error against the current: less current, same duty."""
    currents = []
    for dead in (0.0, 1.0e-6):
        cfg = linearised(default_cfg).with_overrides({"inverter.dead_time_s": dead})
        plant = Plant(cfg)
        for _ in range(4000):
            _voltage_vector(plant, 3.0)
            plant.advance(1)
        currents.append(plant.y[Y_IQ])
    assert currents[1] < 0.95 * currents[0]


def test_duty_limits_clamp_the_voltage(default_cfg):
    cfg = linearised(default_cfg).with_overrides({"inverter.dead_time_s": 0.0,
                                                  "inverter.duty_min": 0.45,
                                                  "inverter.duty_max": 0.55})
    free = Plant(linearised(default_cfg).with_overrides({"inverter.dead_time_s": 0.0}))
    clamped = Plant(cfg)
    for p in (free, clamped):
        for _ in range(2000):
            _voltage_vector(p, 10.0)
            p.advance(1)
    assert clamped.y[Y_IQ] < 0.6 * free.y[Y_IQ]


def _energy_error(plant: Plant) -> float:
    y = plant.y
    return abs(y[Y_E_IN] + y[Y_E_EXT] - y[Y_E_DISS] - y[Y_E_STORED]) / max(abs(y[Y_E_IN]), 1e-9)


@pytest.mark.parametrize("kind", ["fixed", "free", "conrod", "cart"])
def test_energy_balance_current_mode(default_cfg, kind):
    """Work in + external work = dissipated + stored, with the nonlinear frictions on."""
    cfg = linearised(default_cfg).with_overrides({
        "load.kind": kind,
        "effects.pulsation.enabled": True,
        "effects.pump_coulomb.enabled": True,
        "effects.seal_friction.enabled": True,
        "effects.oil_temperature.enabled": True,
    })
    plant = Plant(cfg)
    for k in range(400):
        plant.set_current(12.0 * math.sin(2 * math.pi * 7.0 * k * 1e-3))
        plant.set_external_force(30.0 * math.cos(2 * math.pi * 3.0 * k * 1e-3))
        plant.advance(20)
    assert plant.y[Y_E_IN] > 1.0
    assert _energy_error(plant) < 1e-4


def test_energy_balance_duty_mode(default_cfg):
    """Same balance with the electrical input at the motor terminals (copper loss included)."""
    cfg = linearised(default_cfg).with_overrides({"load.kind": "free",
                                                  "effects.pulsation.enabled": True})
    plant = Plant(cfg)
    for k in range(8000):
        _voltage_vector(plant, 2.0 * math.sin(2 * math.pi * 10.0 * k * 5e-5))
        plant.advance(1)
    assert abs(plant.x[3]) < 0.02  # kept off the end stops
    assert plant.y[Y_E_IN] > 0.1
    assert _energy_error(plant) < 1e-4


@pytest.mark.parametrize("kind", ["fixed", "free", "conrod", "cart"])
@pytest.mark.parametrize("preset", ["hydra_default", "hydra_nonlinear"])
def test_tick_integration_is_accurate(kind, preset):
    """The chosen sub-steps give the answer of a four times finer integration."""
    from plant.config import load_config

    cfg = load_config(preset, [f"load.kind={kind}", "load.conrod_stiffness_n_per_m=5.81e6"])
    coarse, fine = Plant(cfg), Plant(cfg, substeps=None)
    fine = Plant(cfg, substeps=4 * coarse.substeps)
    out = []
    for plant in (coarse, fine):
        rec = np.zeros((6000, plant.y.shape[0]))
        row = 0
        for k in range(300):
            plant.set_current(15.0 * math.sin(2 * math.pi * 20.0 * k * 1e-3))
            row = plant.advance(20, rec, row)
        out.append(rec[:, Y_TAU_Q])
    assert np.all(np.isfinite(out[0]))
    span = np.ptp(out[1])
    assert span > 10.0
    assert np.abs(out[0] - out[1]).max() < 1e-3 * span
