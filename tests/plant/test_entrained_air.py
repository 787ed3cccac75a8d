"""Entrained air (effects.entrained_air): the compiled stiffness law equals the readable
reference, a run with it equals a Python RK4 of the reference, the arithmetic without it
is the old one, and the F1 calibration stays inside its physical bound."""

from __future__ import annotations

import numpy as np
import pytest

from plant import kernel
from plant import layout as L
from plant.blocks.hydraulics import aerated_stiffness, line_stiffness
from plant.config import linearised, load_config
from plant.model import Plant, build_params
from plant.reference import EntrainedAir, LinearEha


def _air(cfg, fraction=0.01):
    return cfg.with_overrides({"effects.entrained_air.enabled": True,
                               "effects.entrained_air.volume_fraction": fraction})


@pytest.mark.parametrize("ks_position", [True, False])
def test_compiled_stiffness_is_the_reference(default_cfg, ks_position):
    cfg = _air(default_cfg.with_overrides({"effects.ks_position.enabled": ks_position}))
    p = build_params(cfg, substeps=1)
    ref = EntrainedAir.from_config(cfg)
    for x_c in np.linspace(-0.024, 0.024, 7):
        for tq in np.linspace(-1500.0, 1500.0, 13):
            assert aerated_stiffness(p, x_c, tq) == pytest.approx(ref.stiffness(x_c, tq),
                                                                  rel=1e-12)


def test_air_is_softest_at_the_precharge_and_stiffens_with_pressure(default_cfg):
    cfg = _air(default_cfg)
    ref = EntrainedAir.from_config(cfg)
    without = kernel.series_stiffness(build_params(cfg, substeps=1), 0.0)
    ks = [ref.stiffness(0.0, tq) for tq in (0.0, 200.0, 600.0, 1500.0)]
    assert all(a < b for a, b in zip(ks, ks[1:], strict=False)), ks
    assert ks[0] < 0.3 * without and ks[-1] < without
    # A push and a pull of the same size see the same stiffness (symmetric circuit).
    assert ref.stiffness(0.0, 700.0) == pytest.approx(ref.stiffness(0.0, -700.0), rel=1e-12)


def test_without_air_the_arithmetic_is_the_old_one(default_cfg):
    """Off, the law is series_stiffness bit for bit, whatever the fraction says."""
    for fraction in (0.0, 0.01, 0.1):
        cfg = default_cfg.with_overrides({"effects.entrained_air.volume_fraction": fraction})
        p = build_params(cfg, substeps=1)
        for x_c, tq in ((0.0, 0.0), (0.01, 800.0), (-0.02, -300.0)):
            assert line_stiffness(p, x_c, tq) == kernel.series_stiffness(p, x_c)
    runs = []
    for fraction in (0.01, 0.05):
        cfg = load_config("hydra_thesis", [f"effects.entrained_air.volume_fraction={fraction}"])
        plant = Plant(cfg)
        plant.set_current(9.0)
        rec = np.zeros((400, L.N_OUTPUTS))
        plant.advance(400, rec)
        runs.append(rec)
    assert np.array_equal(runs[0], runs[1])


def test_a_run_with_air_is_the_reference_integrated(default_cfg):
    """Fixed piston, pump force given, every other effect off: the kernel's RK4 ticks and
    a plain RK4 of LinearEha with EntrainedAir's k_s agree."""
    cfg = _air(linearised(default_cfg).with_overrides({"load.kind": "fixed"}), 0.01)
    ref, air = LinearEha.from_config(cfg), EntrainedAir.from_config(cfg)
    plant = Plant(cfg, substeps=4)
    h = plant.tick_s / 4

    def f(state, tau_p):
        return ref.derivatives(state, tau_p, piston_free=False,
                               ks=air.stiffness(0.0, state[2]))

    state = np.zeros(5)
    for k in range(600):
        tau_p = 400.0 * np.sin(2 * np.pi * 30.0 * k * plant.tick_s)
        plant.set_force(tau_p)
        plant.advance(1)
        for _ in range(4):
            k1 = f(state, tau_p)
            k2 = f(state + 0.5 * h * k1, tau_p)
            k3 = f(state + 0.5 * h * k2, tau_p)
            k4 = f(state + h * k3, tau_p)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    got = plant.x[[L.S_THP, L.S_VP, L.S_TQ]]
    np.testing.assert_allclose(got, state[:3], rtol=1e-9, atol=1e-12)
    # Not vacuous: the same run without air ends elsewhere.
    plain = Plant(linearised(default_cfg).with_overrides({"load.kind": "fixed"}), substeps=4)
    for k in range(600):
        plain.set_force(400.0 * np.sin(2 * np.pi * 30.0 * k * plain.tick_s))
        plain.advance(1)
    assert abs(plain.x[L.S_TQ] - got[2]) > 1.0


def test_the_preset_fraction_is_inside_its_bound():
    from hil.scenarios.f1_measured import AIR_FRACTION_BOUND

    alpha = load_config("hydra_thesis").get("effects.entrained_air.volume_fraction")
    lo, hi = AIR_FRACTION_BOUND
    assert lo < alpha < hi
    assert load_config("hydra_thesis").get("effects.entrained_air.enabled") is False


@pytest.mark.slow
def test_the_preset_fraction_is_the_search_result():
    """calibrate_air_fraction on hydra_thesis finds the preset's value (to its step), and
    the F1 peak it gives sits at the thesis's measured figure's side of the model's."""
    from hil.scenarios.f1_measured import calibrate_air_fraction
    from hil.scenarios.plant_figures import THESIS_F1

    cfg = load_config("hydra_thesis")
    found = calibrate_air_fraction(cfg, THESIS_F1["measured_peak_hz"])
    assert found == pytest.approx(cfg.get("effects.entrained_air.volume_fraction"), abs=3e-4)
