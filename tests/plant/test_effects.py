"""Each effect beyond the linear model shows its signature when on, and not when off.

Every test runs the same experiment twice, effect on and effect off, and checks both: the
signature must be there when the effect is on (so the test fails if the effect stops
working) and absent when it is off (so the switch really switches).
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.analysis.bode import simulate_bode
from plant.config import linearised
from plant.layout import (
    Y_F_ROD,
    Y_F_STRAIN,
    Y_P_PUMP_A,
    Y_T_OIL,
    Y_TAU_P,
    Y_TAU_Q,
    Y_THETA_M,
    Y_V_PISTON,
    Y_VP,
    Y_X_PISTON,
)
from plant.model import Plant


def _with(cfg, effect: str, on: bool, **extra):
    """The linear model with one effect switched on or off (plus extra overrides)."""
    over = {f"effects.{effect}.enabled": on}
    over.update(extra)
    return linearised(cfg).with_overrides(over)


def _run(cfg, n_ticks: int, setup) -> np.ndarray:
    plant = Plant(cfg)
    setup(plant)
    rec = np.zeros((n_ticks, plant.y.shape[0]))
    plant.advance(n_ticks, rec)
    return rec


@pytest.mark.parametrize("on", [True, False])
def test_pulsation_at_order_4_of_rotor_angle(default_cfg, on):
    """Pressure ripple at 4 x the rotor frequency (4-tooth trochoid) only when on."""
    cfg = _with(default_cfg, "pulsation", on)
    rec = _run(cfg, 20000, lambda p: p.set_current(10.0))[8000:]
    tau_q = rec[:, Y_TAU_Q]
    theta = rec[:, Y_THETA_M]
    # Project the pressure onto the 4th order of rotor angle (works at any speed).
    ripple = 2 * np.abs(np.mean((tau_q - tau_q.mean()) * np.exp(-4j * theta)))
    off_order = 2 * np.abs(np.mean((tau_q - tau_q.mean()) * np.exp(-3j * theta)))
    if on:
        assert ripple > 0.005 * tau_q.mean()
        assert ripple > 20 * off_order
    else:
        assert ripple < 1e-4 * tau_q.mean()


@pytest.mark.parametrize("on", [True, False])
def test_pulsation_order_is_configurable(default_cfg, on):
    cfg = _with(default_cfg, "pulsation", on, **{"effects.pulsation.order": 6})
    rec = _run(cfg, 20000, lambda p: p.set_current(10.0))[8000:]
    tau_q = rec[:, Y_TAU_Q] - rec[:, Y_TAU_Q].mean()
    theta = rec[:, Y_THETA_M]
    a6 = np.abs(np.mean(tau_q * np.exp(-6j * theta)))
    a4 = np.abs(np.mean(tau_q * np.exp(-4j * theta)))
    assert (a6 > 20 * a4) if on else (a6 < 1e-3)


@pytest.mark.parametrize("torque", [0.0, 150.0])
def test_meshing_torque_ripple_drives_the_pump_speed_at_order_4(default_cfg, torque):
    """With the displacement ripple at zero, only the meshing torque ripple can make the
    pump speed ripple at 4 x rotor angle; its size follows the configured torque."""
    cfg = _with(default_cfg, "pulsation", True, **{"effects.pulsation.amplitude": 0.0,
                                                  "effects.pulsation.torque_n": torque})
    rec = _run(cfg, 20000, lambda p: p.set_current(10.0))[8000:]
    v = rec[:, Y_VP] - rec[:, Y_VP].mean()
    theta = rec[:, Y_THETA_M]
    a4 = 2 * np.abs(np.mean(v * np.exp(-4j * theta)))
    a3 = 2 * np.abs(np.mean(v * np.exp(-3j * theta)))
    if torque:
        assert a4 > 1e-5 and a4 > 20 * a3
    else:
        assert a4 < 1e-9


def test_meshing_torque_ripple_proportional_to_the_load(default_cfg):
    """``torque_amplitude`` is a ripple relative to the pump's pressure force: at a steady
    load it drives the same pump-speed ripple as a constant ``torque_n`` of that fraction of
    the load, and it scales with the load."""
    def ripple(current: float, **over) -> tuple[float, float]:
        cfg = _with(default_cfg, "pulsation", True, **{"effects.pulsation.amplitude": 0.0,
                                                      "effects.pulsation.torque_n": 0.0,
                                                      **over})
        rec = _run(cfg, 20000, lambda p: p.set_current(current))[8000:]
        v = rec[:, Y_VP] - rec[:, Y_VP].mean()
        a4 = 2 * np.abs(np.mean(v * np.exp(-4j * rec[:, Y_THETA_M])))
        return float(a4), float(rec[:, Y_TAU_Q].mean())

    rel = 0.26
    a_rel, load = ripple(10.0, **{"effects.pulsation.torque_amplitude": rel})
    a_const, _ = ripple(10.0, **{"effects.pulsation.torque_n": rel * load})
    a_half, load_half = ripple(5.0, **{"effects.pulsation.torque_amplitude": rel})
    assert a_rel > 1e-5
    assert abs(a_rel / a_const - 1.0) < 0.1, (a_rel, a_const)
    # Half the current, about half the load: the ripple follows the load, not the current.
    assert abs((a_half / a_rel) / (load_half / load) - 1.0) < 0.25, (a_half, a_rel, load_half)


@pytest.mark.parametrize("on", [True, False])
def test_pump_coulomb_friction_offsets_the_force_speed_line(default_cfg, on):
    """Piston fixed: pump force vs pump speed is a line whose intercept is the Coulomb force."""
    cfg = _with(default_cfg, "pump_coulomb", on)
    friction = []
    for iq in (6.0, 12.0):
        plant = Plant(cfg)
        plant.set_current(iq)
        plant.advance(3000)
        vp = plant.y[Y_VP]
        # Pump-side balance at steady state: tau_p = d_p v_p + F_c + tau_q.
        dp = cfg.get("hydraulics.dp_ns_per_m")
        friction.append(plant.y[Y_TAU_P] - plant.y[Y_TAU_Q] - dp * vp)
    coulomb = cfg.get("effects.pump_coulomb.force_n")
    if on:
        assert friction == pytest.approx([coulomb, coulomb], rel=0.02)
    else:
        assert np.abs(friction).max() < 0.5


@pytest.mark.parametrize("on", [True, False])
def test_seal_friction_coulomb_and_stribeck(default_cfg, on):
    """Free piston at constant speed: the cylinder pressure carries the seal friction; it is
    larger at low speed (Stribeck) than at high speed (Coulomb)."""
    cfg = _with(default_cfg, "seal_friction", on, **{"load.kind": "free", "load.x0_m": -0.024})
    fc = cfg.get("effects.seal_friction.coulomb_n")
    fs = cfg.get("effects.seal_friction.static_n")
    friction = {}
    for force in (60.0, 600.0):  # pump force -> slow (below v_s) and fast piston
        plant = Plant(cfg)
        plant.set_force(force)
        plant.advance(3000)
        vc = plant.y[Y_V_PISTON]
        # Piston balance at steady speed: tau_q - d_c v_c - F_seal = 0.
        friction[force] = (plant.y[Y_TAU_Q] - cfg.get("hydraulics.dc_ns_per_m") * vc, vc)
    (f_slow, v_slow), (f_fast, v_fast) = friction[60.0], friction[600.0]
    assert 0 < v_slow < v_fast
    if on:
        assert fc * 0.98 < f_fast < fc * 1.05
        assert f_slow > f_fast + 0.2 * (fs - fc)
    else:
        assert abs(f_slow) < 0.5 and abs(f_fast) < 0.5


@pytest.mark.parametrize("on", [True, False])
def test_ks_depends_on_piston_position(default_cfg, on):
    """Eq. 2.27: k_s is largest at the stroke ends, so the fixed-piston resonance moves up."""
    cfg = _with(default_cfg, "ks_position", on)
    freqs = np.arange(30.0, 101.0)
    mid = simulate_bode(cfg, "fixed", freqs, x0_m=0.0).peak_hz()
    end = simulate_bode(cfg, "fixed", freqs, x0_m=0.024).peak_hz()
    if on:
        assert end >= mid + 4.0
    else:
        assert end == mid


@pytest.mark.parametrize("on", [True, False])
def test_hot_oil_leaks_more(default_cfg, on):
    """Viscosity falls with temperature, so d_s and d_p fall: at stall the pump turns faster."""
    speeds = []
    for t in (25.0, 60.0):
        cfg = _with(default_cfg, "oil_temperature", on,
                    **{"effects.oil_temperature.initial_c": t,
                       "effects.oil_temperature.ambient_c": t})
        plant = Plant(cfg)
        plant.set_current(18.0)
        plant.advance(3000)
        speeds.append(plant.y[Y_VP])
    if on:
        assert speeds[1] > 1.5 * speeds[0]
    else:
        assert speeds[1] == speeds[0]


@pytest.mark.parametrize("on", [True, False])
def test_losses_heat_the_oil(default_cfg, on):
    cfg = _with(default_cfg, "oil_temperature", on,
                **{"effects.oil_temperature.heat_capacity_j_per_k": 5.0})
    rec = _run(cfg, 40000, lambda p: p.set_current(18.0))
    rise = rec[-1, Y_T_OIL] - rec[0, Y_T_OIL]
    if on:
        assert rise > 0.5
    else:
        assert rise == 0.0


@pytest.mark.parametrize("on", [True, False])
def test_strain_gauge_drifts_with_rod_temperature(default_cfg, on):
    """Thesis 4.4: 2.5 N/degC on the strain reading, none on the true rod force."""
    cfg = _with(default_cfg, "strain_drift", on,
                **{"effects.strain_drift.rod_time_constant_s": 0.05, "load.kind": "conrod"})
    plant = Plant(cfg)
    plant.set_force(0.0)
    plant.set_ambient(45.0)
    plant.advance(20000)  # 1 s = 20 rod time constants
    drift = plant.y[Y_F_STRAIN] - plant.y[Y_F_ROD]
    if on:
        assert drift == pytest.approx(2.5 * 20.0, rel=1e-3)
    else:
        assert drift == 0.0


@pytest.mark.parametrize("on", [True, False])
def test_sensor_noise(default_cfg, on):
    cfg = _with(default_cfg, "sensor_noise", on)
    rec = _run(cfg, 4000, lambda p: p.set_force(0.0))
    p_a = rec[:, Y_P_PUMP_A]
    sigma = cfg.get("effects.sensor_noise.pressure_pa")
    if on:
        assert np.std(p_a) == pytest.approx(sigma, rel=0.1)
        assert abs(np.mean(p_a) - cfg.get("hydraulics.precharge_pa")) < 0.1 * sigma
    else:
        assert np.std(p_a) == 0.0


@pytest.mark.parametrize("on", [True, False])
def test_quantisation(default_cfg, on):
    cfg = _with(default_cfg, "quantisation", on,
                **{"effects.sensor_noise.enabled": True, "load.kind": "free"})
    rec = _run(cfg, 2000, lambda p: p.set_force(300.0))
    lsb_p = cfg.get("effects.quantisation.pressure_lsb_pa")
    counts = rec[:, Y_P_PUMP_A] / lsb_p
    motor = rec[:, Y_THETA_M] / (2 * np.pi / 2048)
    piston = rec[:, Y_X_PISTON] / 5e-9
    on_grid = [np.allclose(c, np.round(c), atol=1e-6) for c in (counts, motor, piston)]
    if on:
        assert all(on_grid)
    else:
        assert not any(on_grid)
