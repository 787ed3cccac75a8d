"""The independent rig simulator (hil/identify/rig.py) checked against physics worked out here,
never against the identification tool's own model: determinism, parameter draws, the sensor
chains (noise, grids), the DC gain and frequency response from the closed-form transfer
function, the energy balance, the input timing and each effect's signature."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.cli import identify as cli
from hil.identify.csvdata import read_measured
from hil.identify.rig import (
    RIG_EFFECTS,
    SENSORS,
    TEMPERATURE_SHAPES,
    _ks_of_x,
    draw_parameters,
    generate_rig,
)
from plant.config import load_config

I_LSB = 80.0 / 4096
P_LSB = 7.0e6 / 4096
S_LSB = 6000.0 / 2**24
ENC_Q = 2 * math.pi / 2048


def _on_grid(x: np.ndarray, q: float) -> bool:
    k = x / q
    return bool(np.all(np.abs(k - np.round(k)) < 1e-6))


def _line_response(y: np.ndarray, t: np.ndarray, f: np.ndarray, a: np.ndarray,
                   ph: np.ndarray, t0: float) -> np.ndarray:
    """Complex response y/u at each line of the input ``sum a sin(2 pi f t + ph)``, by least
    squares on sin/cos of every line (plus a constant) over ``t >= t0``."""
    m = t >= t0
    tt = t[m]
    cols = [np.ones(tt.size)]
    for fj in f:
        cols += [np.sin(2 * np.pi * fj * tt), np.cos(2 * np.pi * fj * tt)]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), y[m], rcond=None)
    c = coef[1::2] + 1j * coef[2::2]
    return c / (a * np.exp(1j * ph))


def _analytic(load: str, par: dict, w: np.ndarray, k_m: float = 0.0,
              m_rate: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form F/i and v_c/i (N/A, m/s/A) of the linear rig at ``w`` rad/s:
    ``(J_p s + d_p) V_p = K I - F``, ``s F = k(s) (V_p - F/d_s - V_c)`` with
    ``k(s) = k_s + k_m s/(s + m_rate)``, ``F = Z_c V_c`` with the piston impedance ``Z_c``."""
    s = 1j * w
    k = par["ks"] + k_m * s / (s + m_rate)
    zp = par["jp"] * s + par["dp"]
    if load == "fixed_piston":
        inv_zc = 0.0 * s
    elif load == "free_piston":
        inv_zc = 1.0 / (par["jc"] * s + par["dc"])
    else:
        inv_zc = 1.0 / (par["jc"] * s + par["dc"] + par["c_rod"] + par["k_rod"] / s)
    ks_over_s = k / s
    f = ks_over_s * par["gain_n_per_a"] / zp / (1 + ks_over_s / par["ds"] + ks_over_s * inv_zc
                                                 + ks_over_s / zp)
    return f, f * inv_zc


# --- determinism and draws --------------------------------------------------------------

def test_deterministic_for_a_seed_and_different_between_seeds():
    eff = ("pump_pulsation", "pump_coulomb_friction", "input_delay", "mains_hum")
    a = generate_rig("fixed_piston", eff, seconds=0.4, seed=11)
    b = generate_rig("fixed_piston", eff, seconds=0.4, seed=11)
    c = generate_rig("fixed_piston", eff, seconds=0.4, seed=12)
    assert a.data.columns.keys() == b.data.columns.keys()
    for name in a.data.columns:
        assert np.array_equal(a.data.col(name), b.data.col(name)), name
    assert a.truth == b.truth
    assert not np.array_equal(a.data.col("p_pump_a"), c.data.col("p_pump_a"))
    assert a.truth["parameters"] != c.truth["parameters"]
    # the intersample mode is not written unless asked for
    assert "intersample" not in a.data.header


def test_parameters_drawn_within_spread_and_vary_with_seed():
    cfg = load_config("hydra_default")
    nominal = {
        "gain_n_per_a": 2150.0 / 18.0, "ds": cfg.get("hydraulics.ds_ns_per_m"),
        "dp": cfg.get("hydraulics.dp_ns_per_m"), "dc": cfg.get("hydraulics.dc_ns_per_m"),
        "ks": cfg.get("hydraulics.ks_n_per_m"), "jp": cfg.get("hydraulics.jp_kg"),
        "jc": cfg.get("hydraulics.jc_kg"), "k_rod": cfg.get("load.conrod_stiffness_n_per_m"),
        "c_rod": cfg.get("load.conrod_damping_ns_per_m"),
    }
    draws = [draw_parameters(seed=s) for s in range(1, 41)]
    for key, nom in nominal.items():
        rel = np.array([d[key] / nom - 1.0 for d in draws])
        lim = 0.10 if key in ("jp", "jc") else 0.15
        assert np.all(np.abs(rel) <= lim + 1e-12), (key, rel)
        # spread out over most of the range, not a constant
        assert rel.max() - rel.min() > lim, (key, rel)
    pre = np.array([d["precharge_pa"] for d in draws])
    assert np.all((pre >= 0.3e6) & (pre <= 0.7e6)) and pre.std() > 0.05e6
    exact = draw_parameters(seed=3, spread=0.0)
    for key, nom in nominal.items():
        assert exact[key] == pytest.approx(nom, rel=1e-12)
    res = generate_rig("conrod_fixed", seconds=0.05, seed=7)
    d7 = draw_parameters(seed=7)
    for key in nominal:
        assert res.truth["parameters"][key] == d7[key]


# --- sensor chains --------------------------------------------------------------------------

@pytest.mark.parametrize("lsb", [0.5, 1.0, 2.0])
def test_logged_current_noise_rms_and_grid(lsb):
    res = generate_rig("fixed_piston", seconds=1.0, seed=2, current_noise_lsb=lsb)
    iq = res.data.col("iq")
    err = iq - res.signals["iq_true"]
    want = math.sqrt((lsb * I_LSB) ** 2 + I_LSB**2 / 12)
    assert res.config["current_error_rms_a"] == pytest.approx(want)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(want, rel=0.05)
    assert abs(np.mean(err)) < 0.05 * want
    assert _on_grid(iq, I_LSB)
    # the true current is continuous: not on the grid
    assert not _on_grid(res.signals["iq_true"], I_LSB)


def test_channels_on_their_grids_and_noise_levels():
    res = generate_rig("conrod_fixed", seconds=1.0, seed=4)
    d = res.data
    for c in ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc"):
        assert _on_grid(d.col(c), P_LSB), c
        assert d.col(c).min() >= 0 and d.col(c).max() < 7.0e6
    assert _on_grid(d.col("f_strain"), S_LSB)
    assert _on_grid(d.col("theta_m"), ENC_Q)
    assert _on_grid(d.col("x_piston"), 5e-9)
    assert _on_grid(d.col("temp_c"), 0.0625)
    # the encoder floors: reading <= true angle < reading + one count
    gap = res.signals["theta_rotor"] - d.col("theta_m")
    assert gap.min() >= -1e-12 and gap.max() < ENC_Q
    # pressure noise: the accumulator channel holds only noise and quantisation
    p0 = res.truth["parameters"]["precharge_pa"]
    acc_rms = np.sqrt(np.mean((d.col("p_acc") - p0) ** 2))
    assert acc_rms == pytest.approx(math.sqrt(2e3**2 + P_LSB**2 / 12), rel=0.1)
    # the strain chain: rod force through a 1 kHz lag plus 0.3 N noise; the lag's error on
    # this (<= 300 Hz) signal is a few N at most
    err = d.col("f_strain") - res.signals["f_rod_true"]
    assert np.std(err) < 5.0


# --- physics ----------------------------------------------------------------------------

def test_dc_gain_of_the_fixed_piston_is_the_leakage_divider():
    """A 5 A current step: in steady state the leakage d_s and the pump friction d_p share
    the pump force, tau_q / (K i) = d_s / (d_p + d_s) (thesis Eq. 2.32 at s = 0)."""
    res = generate_rig("fixed_piston", seconds=0.3, seed=5,
                       excitation_lines=([0.0], [5.0], [math.pi / 2]))
    par = res.truth["parameters"]
    want = par["ds"] / (par["dp"] + par["ds"])
    tau_p = par["gain_n_per_a"] * 5.0
    assert res.signals["tau_q"][-1] / tau_p == pytest.approx(want, rel=1e-6)
    assert res.signals["v_p"][-1] == pytest.approx(tau_p / (par["dp"] + par["ds"]), rel=1e-6)
    last = slice(-500, None)
    kc = 286e-6
    measured = kc * np.mean(res.data.col("p_pump_a")[last] - res.data.col("p_pump_b")[last])
    assert measured / tau_p == pytest.approx(want, rel=3e-3)
    # the low side sits on the precharge
    assert np.mean(res.data.col("p_pump_b")[last]) == pytest.approx(par["precharge_pa"],
                                                                   abs=2 * P_LSB)


@pytest.mark.parametrize("load,effect", [
    ("fixed_piston", None), ("conrod_fixed", None), ("free_piston", None),
    ("fixed_piston", "hose_viscoelastic"), ("fixed_piston", "stiffness_vs_position"),
])
def test_frequency_response_matches_the_closed_form(load, effect):
    """Sine lines 3-1500 Hz; the simulated hydraulic force (and piston speed) per ampere at
    each line against the closed-form transfer function with the drawn parameters (the
    Maxwell branch: k(s) = k_s + k_m s/(s + k_m/c_m))."""
    f = np.array([3.0, 9.0, 21.0, 40.0, 57.0, 75.0, 110.0, 230.0, 480.0, 900.0, 1300.0,
                  1500.0])
    rng = np.random.default_rng(0)
    a = np.full(f.size, 0.5)
    ph = rng.uniform(0, 2 * np.pi, f.size)
    eff = (effect,) if effect else ()
    res = generate_rig(load, eff, seconds=1.0, seed=6, excitation_lines=(f, a, ph),
                       position_loop_a_per_m=0.0)
    par = res.truth["parameters"]
    k_m, rate = 0.0, 1.0
    if effect == "hose_viscoelastic":
        h = res.truth["effects"][effect]
        k_m, rate = h["k_m_n_per_m"], h["k_m_n_per_m"] / h["c_m_ns_per_m"]
        assert k_m == pytest.approx(0.5 * par["ks"])
        assert rate == pytest.approx(2 * np.pi * 30.0)
    f_ana, v_ana = _analytic(load, par, 2 * np.pi * f, k_m, rate)
    t = res.data.t
    f_sim = _line_response(res.signals["tau_q"], t, f, a, ph, 0.3)
    np.testing.assert_allclose(f_sim, f_ana, rtol=2e-4, atol=1e-4 * np.abs(f_ana).max())
    if load != "fixed_piston":
        v_sim = _line_response(res.signals["v_c"], t, f, a, ph, 0.3)
        np.testing.assert_allclose(v_sim, v_ana, rtol=2e-4, atol=1e-4 * np.abs(v_ana).max())


def test_fixed_piston_resonance_where_the_second_order_formula_puts_it():
    """J_p s^2 + (d_p + J_p k_s/d_s) s + k_s (1 + d_p/d_s): the force response peaks at
    w_n sqrt(1 - 2 zeta^2) (about 57 Hz with the preset); located here from the record."""
    f = np.arange(36.0, 86.0, 2.0)
    a = np.full(f.size, 0.4)
    ph = np.random.default_rng(1).uniform(0, 2 * np.pi, f.size)
    res = generate_rig("fixed_piston", seconds=2.5, seed=8, excitation_lines=(f, a, ph))
    par = res.truth["parameters"]
    mag = np.abs(_line_response(res.signals["tau_q"], res.data.t, f, a, ph, 0.3))
    j = int(np.argmax(mag))
    assert 0 < j < f.size - 1
    # parabola through the three points around the maximum
    y0, y1, y2 = mag[j - 1], mag[j], mag[j + 1]
    f_peak = f[j] + (y0 - y2) / (2 * (y0 - 2 * y1 + y2)) * (f[1] - f[0])
    wn2 = par["ks"] * (1 + par["dp"] / par["ds"]) / par["jp"]
    two_zeta_wn = par["dp"] / par["jp"] + par["ks"] / par["ds"]
    zeta = two_zeta_wn / (2 * math.sqrt(wn2))
    want = math.sqrt(wn2) * math.sqrt(1 - 2 * zeta**2) / (2 * math.pi)
    assert f_peak == pytest.approx(want, abs=1.0)
    assert 35.0 < want < 85.0


def test_energy_decays_and_balances_the_dissipation():
    """No input, an initial state, the rod on the conrod, pump Coulomb friction and a 5 %
    flow ripple (whose reaction on the pump must not create energy): the stored energy
    E = J_p v_p^2/2 + J_c v_c^2/2 + F^2/(2 k_s) + k_rod x_c^2/2 never rises, and its loss
    equals the integral of d_p v_p^2 + F^2/d_s + (d_c + c_rod) v_c^2 + F_pc s(v_p) v_p."""
    eff = {"pump_coulomb_friction": {"force_n": 30.0},
           "pump_pulsation": {"amplitude": 0.05, "torque_n": 0.0}}
    res = generate_rig("conrod_fixed", eff, seconds=0.04, seed=9, sample_rate_hz=100_000.0,
                       excitation_lines=([], [], []),
                       initial_state={"v_p": 0.02, "tau_q": 800.0, "x_c": 2e-4, "v_c": -0.01})
    par = res.truth["parameters"]
    s = res.signals
    assert np.all(s["iq_applied"] == 0.0)
    vp, vc, force, xc = s["v_p"], s["v_c"], s["tau_q"], s["x_c"]
    energy = (0.5 * par["jp"] * vp**2 + 0.5 * par["jc"] * vc**2
              + force**2 / (2 * par["ks"]) + 0.5 * par["k_rod"] * xc**2)
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])
    assert energy[-1] < 1e-3 * energy[0]
    pc = res.truth["effects"]["pump_coulomb_friction"]
    diss = (par["dp"] * vp**2 + force**2 / par["ds"] + (par["dc"] + par["c_rod"]) * vc**2
            + pc["force_n"] * 2 / np.pi * np.arctan(vp / pc["eps_m_per_s"]) * vp)
    lost = energy[0] - energy[-1]
    dt = res.data.dt
    integral = float(np.sum(0.5 * (diss[1:] + diss[:-1])) * dt)
    assert integral == pytest.approx(lost, rel=2e-3)


def test_applied_current_is_the_delayed_continuous_one():
    f, a, ph = 37.0, 3.0, 0.4
    d = 330e-6  # not a whole number of samples nor of integration steps
    res = generate_rig("fixed_piston", {"input_delay": {"delay_s": d}}, seconds=0.2, seed=1,
                       excitation_lines=([f], [a], [ph]))
    t = res.data.t
    want = np.where(t >= d, a * np.sin(2 * np.pi * f * (t - d) + ph), 0.0)
    np.testing.assert_allclose(res.signals["iq_applied"], want, atol=1e-9)
    np.testing.assert_allclose(res.signals["iq_true"], a * np.sin(2 * np.pi * f * t + ph),
                               atol=1e-9)
    assert res.truth["effects"]["input_delay"]["delay_s"] == d
    # zoh: the logged values are what the motor gets, held over a sample, then delayed
    z = generate_rig("fixed_piston", {"input_delay": {"delay_s": d}}, seconds=0.2, seed=1,
                     excitation_lines=([f], [a], [ph]), intersample="zoh",
                     header_intersample=True)
    iq = z.data.col("iq")
    j = np.floor((t - d) / z.data.dt + 1e-9).astype(int)
    held = np.where(j >= 0, iq[np.clip(j, 0, None)], 0.0)
    np.testing.assert_array_equal(z.signals["iq_applied"], held)
    assert z.data.header["intersample"] == "zoh"
    assert z.config["current_error_rms_a"] == 0.0


def test_zoh_input_gives_the_exact_discrete_response():
    """A held 4 A command: the fixed-piston response at the samples equals the exact
    zero-order-hold discretisation of the linear model (matrix exponential), independent of
    the Runge-Kutta integration."""
    from scipy.linalg import expm

    res = generate_rig("fixed_piston", seconds=0.1, seed=3, intersample="zoh",
                       current_noise_lsb=0.0, excitation_lines=([0.0], [4.0], [math.pi / 2]))
    par = res.truth["parameters"]
    iq = res.data.col("iq")
    assert np.all(iq == iq[0]) and iq[0] == pytest.approx(4.0, abs=I_LSB)
    a = np.array([[-par["dp"] / par["jp"], -1 / par["jp"]],
                  [par["ks"], -par["ks"] / par["ds"]]])
    b = np.array([par["gain_n_per_a"] / par["jp"], 0.0])
    m = np.zeros((3, 3))
    m[:2, :2] = a
    m[:2, 2] = b
    e = expm(m * res.data.dt)
    x = np.zeros(2)
    for k in range(1, 60):
        x = e[:2, :2] @ x + e[:2, 2] * iq[k - 1]
        assert res.signals["v_p"][k] == pytest.approx(x[0], rel=1e-7, abs=1e-12)
        assert res.signals["tau_q"][k] == pytest.approx(x[1], rel=1e-7, abs=1e-6)


# --- temperature and its effects ------------------------------------------------------

@pytest.mark.parametrize("shape", list(TEMPERATURE_SHAPES))
def test_temperature_shapes(shape):
    res = generate_rig("fixed_piston", seconds=1.2, seed=2, temperature=shape)
    temp, t, rec = res.signals["t_oil"], res.data.t, 1.2
    expect = {
        "constant": np.full(t.size, 25.0),
        "ramp": 15.0 + 10.0 * t / rec,
        "ramp_level": 15.0 + 7.0 * (1 - np.exp(-3 * t / rec)),
        "oscillation": 20.0 + 3.0 * np.sin(4 * np.pi * t / rec),
    }
    if shape in expect:
        np.testing.assert_allclose(temp, expect[shape], atol=1e-9)
    else:
        assert temp[0] == 15.0 and temp[-1] == pytest.approx(22.5, abs=0.05)
        assert np.all(np.diff(temp) >= 0)
    logged = res.data.col("temp_c")
    assert np.sqrt(np.mean((logged - temp) ** 2)) == pytest.approx(
        math.sqrt(0.05**2 + 0.0625**2 / 12), rel=0.1)


def test_temperature_defaults_and_errors():
    res = generate_rig("fixed_piston", ("viscosity_temperature",), seconds=0.1)
    assert res.config["temperature"] == "ramp_level"
    assert generate_rig("fixed_piston", seconds=0.1).config["temperature"] == "constant"
    with pytest.raises(ValueError, match="moving temperature"):
        generate_rig("fixed_piston", ("strain_thermal_drift",), seconds=0.1,
                     temperature="constant")
    with pytest.raises(ValueError, match="unknown rig effect"):
        generate_rig("fixed_piston", ("friction",), seconds=0.1)
    with pytest.raises(ValueError, match="needs load free_piston"):
        generate_rig("fixed_piston", seconds=0.1, profile="slide")


def test_viscosity_scales_the_dampers_with_the_true_temperature():
    """A DC step while the oil warms: v_p = K i / (r(T) (d_p + d_s)) with
    r = exp(-c (T - T_ref)) at the true (not the logged) oil temperature."""
    res = generate_rig("fixed_piston", {"viscosity_temperature": {"coeff_per_c": 0.03}},
                       seconds=1.0, seed=4, temperature="ramp",
                       excitation_lines=([0.0], [5.0], [math.pi / 2]))
    par = res.truth["parameters"]
    r = np.exp(-0.03 * (res.signals["t_oil"] - par["reference_c"]))
    want = par["gain_n_per_a"] * 5.0 / (r * (par["dp"] + par["ds"]))
    k = slice(1000, None)
    np.testing.assert_allclose(res.signals["v_p"][k], want[k], rtol=2e-3)


def test_strain_drift_follows_the_oil_temperature():
    res = generate_rig("free_piston", {"strain_thermal_drift": {"n_per_c": 2.5}},
                       seconds=2.0, seed=3, temperature="ramp")
    drift = res.truth["effects"]["strain_thermal_drift"]["drift_n"]
    temp = res.signals["t_oil"]
    assert drift == pytest.approx(2.5 * (temp[-1] - temp[0]))
    fs = res.data.col("f_strain")
    # free piston: no rod force, the reading is the drift plus noise
    np.testing.assert_allclose(fs, 2.5 * (temp - temp[0]), atol=2.0)
    assert np.mean(fs[-500:]) - np.mean(fs[:500]) == pytest.approx(2.5 * (
        np.mean(temp[-500:]) - np.mean(temp[:500])), abs=0.1)


# --- effects' signatures ------------------------------------------------------------------

def _order_amplitudes(r: np.ndarray, theta: np.ndarray, orders: range) -> np.ndarray:
    return np.array([2 / r.size * abs(np.sum(r * np.exp(-1j * n * theta))) for n in orders])


def test_meshing_torque_ripple_orders_and_size():
    """A 5 A step turns the pump at the leakage speed v_p = K i / (d_p + d_s) (about 5 rev/s)
    against the fixed piston; meshing torque ripples T_n sin(n theta + psi_n) at orders 4 and
    2 then show in the pressure force at those orders only, each with the size the
    closed-form response of F to a pump torque gives at n times the rotor speed."""
    eff = {"pump_pulsation": {"amplitude": 0.0, "torque_n": 150.0, "order_2": 2,
                              "torque_n_2": 100.0, "torque_phase_rad_2": 0.7}}
    res = generate_rig("fixed_piston", eff, seconds=1.0, seed=5,
                       excitation_lines=([0.0], [5.0], [math.pi / 2]))
    assert set(res.truth["effects"]) == {"pump_pulsation", "pump_pulsation[order=4]",
                                         "pump_pulsation[order=2]"}
    par = res.truth["parameters"]
    keep = slice(1000, None)
    force = res.signals["tau_q"][keep]
    theta = res.signals["theta_rotor"][keep]
    amps = _order_amplitudes(force - force.mean(), theta, range(1, 9))
    assert set(np.argsort(amps)[-2:] + 1) == {2, 4}, amps
    # odd orders absent; 6 and 8 only as the intermodulation of the speed the ripple
    # itself modulates
    assert amps[[0, 2, 4, 6]].max() < 0.05 * min(amps[1], amps[3]), amps
    assert amps[[5, 7]].max() < 0.3 * min(amps[1], amps[3]), amps
    v_p = par["gain_n_per_a"] * 5.0 / (par["dp"] + par["ds"])
    w_rot = v_p * 286e-6 / 66.5e-9
    for order, torque in ((4, 150.0), (2, 100.0)):
        f_per_a, _ = _analytic("fixed_piston", par, np.array([order * w_rot]))
        want = torque * abs(f_per_a[0]) / par["gain_n_per_a"]
        assert amps[order - 1] == pytest.approx(want, rel=0.05), (order, amps)


def test_sensor_saturation_clips_at_the_level():
    res = generate_rig("fixed_piston", ("sensor_saturation",), seconds=1.0, seed=7)
    tr = res.truth["effects"]["sensor_saturation"]
    assert tr["level_pa"] == pytest.approx(4.0e6, abs=P_LSB)
    hit = 0.0
    for c in ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b"):
        col = res.data.col(c)
        assert col.max() <= tr["level_pa"] + 1e-6
        hit = max(hit, float(np.mean(col == tr["level_pa"])))
    assert hit > 0.001  # a plateau the identifier can see


def test_mains_hum_on_p_pump_a_only():
    base = generate_rig("fixed_piston", seconds=1.0, seed=6)
    res = generate_rig("fixed_piston", ("mains_hum",), seconds=1.0, seed=6)
    t = res.data.t
    d = res.data.col("p_pump_a") - base.data.col("p_pump_a")
    x = np.column_stack([np.sin(2 * np.pi * 50 * t), np.cos(2 * np.pi * 50 * t)])
    c, *_ = np.linalg.lstsq(x, d, rcond=None)
    assert math.hypot(*c) == pytest.approx(1.0e4, rel=0.03)
    assert np.array_equal(res.data.col("p_pump_b"), base.data.col("p_pump_b"))


def test_backlash_between_rotor_and_encoder():
    res = generate_rig("fixed_piston", ("backlash",), seconds=1.0, seed=6)
    lag = res.signals["theta_rotor"] - res.data.col("theta_m")
    assert lag.min() >= -0.025 - 1e-9 and lag.max() <= 0.025 + ENC_Q + 1e-9
    assert lag.max() - lag.min() > 0.04  # the rotor reverses: both sides of the band seen


def test_stiffness_law_and_its_span_over_the_sweep():
    """Eq. 2.25-2.27 with the preset's numbers: k_s 1.93e7 N/m mid-stroke, 2.54e7 N/m at the
    stroke ends (DESIGN.md); and the resonance profile's sweep spans > 10 % of it."""
    kc, half = 286e-6, 0.025
    k0 = float(_ks_of_x(0.0, 6.43e-6, 1.85e9, kc, half, 1.44e8))
    kend = float(_ks_of_x(0.025, 6.43e-6, 1.85e9, kc, half, 1.44e8))
    assert k0 == pytest.approx(1.93e7, rel=0.01) and kend == pytest.approx(2.54e7, rel=0.01)
    res = generate_rig("free_piston", ("stiffness_vs_position",), seconds=2.5, seed=2,
                       profile="resonance")
    tr = res.truth["effects"]["stiffness_vs_position"]
    assert tr["side_volume_m3"] == pytest.approx(6.43e-6)
    assert 0.08 < tr["ks_relative_span"] < 0.3
    assert tr["x_max_m"] - tr["x_min_m"] > 0.025
    assert res.truth["parameters"]["ks"] == tr["ks_mid_stroke_n_per_m"]
    assert not res.config["beyond_stroke"]


def test_free_piston_stays_inside_the_stroke():
    res = generate_rig("free_piston", seconds=6.0, seed=1)
    lo, hi = res.config["x_range_m"]
    assert -0.024 < lo < -0.005 and 0.005 < hi < 0.024
    assert not res.config["beyond_stroke"]


# --- command line -----------------------------------------------------------------------

def _synth(capsys, *argv: str) -> tuple[int, str, str]:
    import argparse

    p = argparse.ArgumentParser(prog="eha-hil")
    cli.configure_synth(p)
    args = p.parse_args(list(argv))
    code = cli.run_synth(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_realism_rig_writes_a_readable_record(tmp_path, capsys):
    path = tmp_path / "rig.csv"
    code, out, err = _synth(capsys, str(path), "--realism", "rig", "--seconds", "1.5",
                            "--effect", "pump_pulsation", "--effect", "viscosity_temperature",
                            "--temperature", "ramp", "--current-noise-lsb", "2",
                            "--magnitude", "pump_pulsation.torque_n=90")
    assert code == 0, err
    assert "torque_n 90" in out and "gain_n_per_a" in out
    data = read_measured(path)
    assert data.n == 7500 and "intersample" not in data.header
    assert _on_grid(data.col("iq"), I_LSB)
    code, _, err = _synth(capsys, str(path), "--realism", "rig", "--effect", "pump_ripple")
    assert code == 2 and err.count("\n") == 1 and "unknown effect" in err
    code, _, err = _synth(capsys, str(path), "--temperature", "ramp")
    assert code == 2 and "only with --realism rig" in err
    code, _, err = _synth(capsys, str(path), "--effect", "hose_viscoelastic")
    assert code == 2 and "--realism plant" in err


def test_effect_lists_consistent():
    assert set(RIG_EFFECTS) >= {"pump_pulsation", "hose_viscoelastic", "mains_hum", "backlash"}
    assert SENSORS["current_bits"] == 12
