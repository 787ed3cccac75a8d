"""The readable linear model (plant.reference) and the compiled kernel agree."""

from __future__ import annotations

import numpy as np
import pytest

from plant import kernel
from plant import layout as L
from plant.config import linearised
from plant.model import build_params
from plant.reference import STATES, LinearEha

KERNEL_ROWS = (L.S_THP, L.S_VP, L.S_TQ, L.S_THC, L.S_VC)


def _kernel_derivatives(cfg, state, tau_p, f_ext):
    p = build_params(cfg, substeps=1)
    x = np.zeros(L.N_STATES)
    x[list(KERNEL_ROWS)] = state
    x[L.S_TOIL] = x[L.S_TROD] = cfg.get("effects.oil_temperature.reference_c")
    u = np.zeros(L.N_INPUTS)
    u[L.IN_MODE] = L.DriveMode.FORCE
    u[L.IN_TAU_REF] = tau_p
    u[L.IN_F_EXT] = f_ext
    u[L.IN_T_AMB] = x[L.S_TOIL]
    dx = np.zeros(L.N_STATES)
    kernel.derivatives(x, p, u, dx)
    return dx[list(KERNEL_ROWS)]


@pytest.mark.parametrize("load", ["free", "fixed", "conrod"])
def test_kernel_is_the_linear_model_with_the_effects_off(default_cfg, load):
    cfg = linearised(default_cfg).with_overrides({"load.kind": load, "load.x0_m": 2e-3})
    ref = LinearEha.from_config(cfg)
    assert (ref.k_rod > 0) == (load == "conrod")
    rng = np.random.default_rng(4)
    for _ in range(50):
        state = rng.normal(size=5) * np.array([1e-3, 0.1, 500.0, 1e-3, 0.05])
        if load == "fixed":
            state[3] = state[4] = 0.0
        tau_p, f_ext = rng.normal(size=2) * 300.0
        want = ref.derivatives(state, tau_p, f_ext if load == "free" else 0.0,
                               piston_free=load != "fixed")
        got = _kernel_derivatives(cfg, state, tau_p, f_ext)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


def test_the_state_space_is_the_derivatives(linear_cfg):
    ref = LinearEha.from_config(linear_cfg)
    a, b = ref.state_space()
    x = np.array([0.0, 0.05, 300.0, 1e-3, -0.02])
    u = np.array([120.0, -40.0])
    np.testing.assert_allclose(a @ x + b @ u, ref.derivatives(x, *u), rtol=1e-14)
    assert len(STATES) == a.shape[0]


def test_the_comparison_sees_a_wrong_parameter(default_cfg):
    """Not vacuous: a reference with a 1 % wrong d_s differs from the kernel."""
    cfg = linearised(default_cfg).with_overrides({"load.kind": "free"})
    ref = LinearEha.from_config(cfg)
    wrong = LinearEha(ref.jp, ref.jc, ref.dp, ref.dc, ref.ds * 1.01, ref.ks)
    state = np.array([0.0, 0.1, 400.0, 0.0, 0.0])
    assert not np.allclose(wrong.derivatives(state, 100.0),
                           _kernel_derivatives(cfg, state, 100.0, 0.0), rtol=1e-9)


def test_the_rod_held_piston_is_the_kernel_s_in_the_frequency_domain(default_cfg):
    """F1 with the piston held through a rod path (hil.scenarios.f1_measured): the stepped
    sines the compiled plant integrates give the reference's state-space response
    tau_p -> tau_q, and its peak sits where the reference's does, far below the rigidly
    held piston's."""
    from hil.scenarios.f1_measured import held, peak_hz, stepped_bode

    cfg = held(linearised(default_cfg), "rod end, reinforced", 4.3e6)
    ref = LinearEha.from_config(cfg)
    a, b = ref.state_space()
    freqs = tuple(float(f) for f in range(14, 32, 2))
    want = np.array([np.linalg.solve(2j * np.pi * f * np.eye(5) - a, b[:, 0])[2]
                     for f in freqs])
    got = stepped_bode(cfg, freqs, amplitude_n=100.0)
    np.testing.assert_allclose(np.abs(got), np.abs(want), rtol=5e-3)
    np.testing.assert_allclose(np.angle(got), np.angle(want), atol=5e-3)
    rigid = LinearEha(ref.jp, ref.jc, ref.dp, ref.dc, ref.ds, ref.ks)
    a0, b0 = rigid.state_space(piston_free=False)
    fine = tuple(float(f) for f in np.arange(14.0, 80.0, 1.0))
    gain = [abs(np.linalg.solve(2j * np.pi * f * np.eye(5) - a0, b0[:, 0])[2]) for f in fine]
    assert peak_hz(freqs, got) < 0.5 * fine[int(np.argmax(gain))]
