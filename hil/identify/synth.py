"""Synthetic identification datasets from the project's plant, with effects switched on.

Used by the tests, the benchmark, the docs and ``eha-hil identify-synth``. The plant
(:class:`plant.model.Plant`, 20 kHz ticks) is driven by a logged q-axis current (an ideal
current source) and its sensor outputs are recorded every ``tick_per_sample``-th tick, as the
MCU logs them (5 kHz by default). Row ``k`` holds ``t_k``, the current logged at ``t_k`` and
the sensor values at ``t_k``; the logged current is applied from ``t_k`` on (plus the delay
of the ``input_delay`` effect).

Effects of the library that live in the plant are switched on through its configuration;
the others are applied around it:

* ``input_delay``: the applied current lags the logged one by whole ticks (50 us);
* ``sensor_saturation``: pressure channels clip at a level (a sensor or ADC rail);
* ``pump_pulsation_extra``: the meshing torque ripple of a second pulsation order
  ``T sin(n theta + phi)`` (the plant has one order): every tick the applied current is the
  logged one minus ``T sin(n theta + phi) / K``, with ``theta`` the plant's rotor angle at
  the tick's midpoint, which is exactly a load torque of that form on the pump;
* outside the library: ``mains_hum`` (a 50 Hz sinusoid on ``p_pump_a``) and ``backlash``
  (a dead band in the motor-angle reading, as a loose encoder coupling gives).

The base is ``hydra_linear`` with sensor noise and quantisation on, so the fitted linear model
is exact for the null dataset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hil.identify.csvdata import LOAD_CASES, MeasuredData
from hil.identify.record_options import SYNTH_PROFILES
from hil.identify.synth_effects import (  # the lists here too, as before
    ALL_SYNTH_EFFECTS,
    OUTSIDE_EFFECTS,
    PLANT_EFFECTS,
    SYNTH_REGISTRY,
    WRAPPER_EFFECTS,
)
from plant import layout as L
from plant.config import Config, load_config
from plant.model import Plant, stiffness_range  # noqa: F401  (re-exported for docs)

#: Realistic default magnitudes of each effect (the plant's preset values where there is
#: one), from the per-effect classes of :mod:`hil.identify.synth_effects`.
DEFAULT_MAGNITUDES: dict[str, dict[str, float]] = {
    n: dict(e.defaults) for n, e in SYNTH_REGISTRY.items()}

#: Excitation profiles of :func:`generate` (defined beside the rig's options, which the
#: command line lists without loading this module).
PROFILES = SYNTH_PROFILES


@dataclass
class SynthResult:
    """A generated record and what was put into it."""

    data: MeasuredData
    truth: dict[str, dict[str, float]]
    config: Config
    iq_applied: np.ndarray
    states: dict[str, np.ndarray] = field(default_factory=dict)


def multisine(n: int, fs: float, rms: float, f_lo: float, f_hi: float, n_lines: int,
              seed: int) -> np.ndarray:
    """Random-phase multisine, log-spaced lines between ``f_lo`` and ``f_hi`` Hz, scaled to
    ``rms``; amplitudes fall as 1/sqrt(f) so that slow components (and so pump reversals
    and rotor travel) dominate while the resonance band stays excited."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    freqs = np.geomspace(f_lo, f_hi, n_lines)
    amps = 1.0 / np.sqrt(freqs)
    phases = rng.uniform(0, 2 * np.pi, n_lines)
    u = (amps[None, :] * np.sin(2 * np.pi * t[:, None] * freqs[None, :] + phases)).sum(axis=1)
    return u * (rms / np.sqrt(np.mean(u * u)))


def synth_config(load: str, effects: dict[str, dict[str, float]],
                 preset: str | Config = "hydra_linear",
                 seed: int = 1, noise: bool = True) -> Config:
    """Plant configuration for a dataset: the preset (a name, a TOML path or a ready
    :class:`~plant.config.Config`), the load, the plant-side effects."""
    cfg = preset if isinstance(preset, Config) else load_config(preset)
    ov: dict[str, Any] = {
        "load.kind": LOAD_CASES[load],
        "sim.seed": int(seed),
        "effects.sensor_noise.enabled": noise,
        "effects.quantisation.enabled": noise,
    }
    for name, mag in effects.items():
        effect = SYNTH_REGISTRY.get(name)
        if effect is not None:
            ov.update(effect.plant_overrides(mag))
    return cfg.with_overrides(ov, source="identify synth")


def generate(
    load: str = "fixed_piston",
    effects: dict[str, dict[str, float]] | list[str] | tuple[str, ...] = (),
    seconds: float = 8.0,
    seed: int = 1,
    preset: str | Config = "hydra_linear",
    sample_rate_hz: float = 5000.0,
    rms_a: float | None = None,
    noise: bool = True,
    excitation: np.ndarray | None = None,
    profile: str = "multisine",
    sweep_m: float | None = None,
    sweep_hz: float | None = None,
) -> SynthResult:
    """Simulate one identification experiment and return the record as it would be logged.

    ``effects`` maps effect names (library names, or ``mains_hum`` / ``backlash``) to
    magnitude overrides; a list takes :data:`DEFAULT_MAGNITUDES`. ``excitation`` (A, one
    value per sample) replaces the default multisine. With the piston free, a weak position
    loop (300 A/m, about 0.4 Hz) keeps the piston inside its stroke; its output is
    part of the logged current, and its reference sweeps the piston over +-18 mm at 0.125 Hz.

    ``profile="resonance"`` is the experiment that makes ``k_s(x)`` identifiable with the
    piston free (see docs/identify.md): a weak broadband multisine (1 A rms, 0.3-300 Hz)
    plus a strong one over the piston-on-``k_s`` resonance (4 A rms, 700-2000 Hz, about
    1.3 kHz), while the position loop sweeps the piston at 0.5 Hz over most of the stroke
    (reference +-30 mm, about +-19 mm reached), so every part of the record sees the
    resonance move with the position. ``sweep_m`` / ``sweep_hz`` override the sweep.
    """
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    if load not in LOAD_CASES:
        raise ValueError(f"unknown load {load!r}")
    if not isinstance(effects, dict):
        effects = {name: {} for name in effects}
    mags: dict[str, dict[str, float]] = {}
    for name, over in effects.items():
        if name not in DEFAULT_MAGNITUDES:
            raise ValueError(f"unknown effect {name!r} (known: {', '.join(ALL_SYNTH_EFFECTS)})")
        mags[name] = {**DEFAULT_MAGNITUDES[name], **over}
    cfg = synth_config(load, {k: v for k, v in mags.items() if k in PLANT_EFFECTS}, preset,
                       seed, noise)
    plant = Plant(cfg)
    every = int(round(1.0 / (sample_rate_hz * plant.tick_s)))
    if every < 1 or abs(every * plant.tick_s * sample_rate_hz - 1.0) > 1e-9:
        raise ValueError("sample rate must divide the 20 kHz tick rate")
    fs = 1.0 / (every * plant.tick_s)
    n = int(round(seconds * fs))
    if rms_a is None:
        rms_a = 2.5 if load == "free_piston" else 5.0
    if excitation is None and profile == "slide":
        exc = multisine(n, fs, 0.5, 0.3, 300.0, 50, seed + 1000)
    elif excitation is None and profile == "resonance":
        exc = (multisine(n, fs, 1.0, 0.3, 300.0, 50, seed + 1000)
               + multisine(n, fs, 4.0, 700.0, 2000.0, 60, seed + 2000))
    elif excitation is None:
        f_hi = 2000.0 if load == "free_piston" else 300.0
        exc = multisine(n, fs, rms_a, 0.3, f_hi, 100, seed + 1000)
    else:
        exc = np.asarray(excitation, dtype=float)
        if exc.size < n:
            raise ValueError("excitation shorter than the record")
    if "strain_thermal_drift" in mags:
        plant.set_ambient(mags["strain_thermal_drift"]["ambient_c"])
    delay_ticks = int(mags.get("input_delay", {}).get("delay_ticks", 0))
    q, r = divmod(delay_ticks, every)
    # Piston free: a slow position loop sweeps the piston over +-18 mm of its stroke (so
    # position-dependent effects are excited) and keeps it off the end stops.
    kx = 300.0 if load == "free_piston" else 0.0
    t_all = np.arange(n) / fs
    if sweep_m is None:
        sweep_m = {"resonance": 0.030}.get(profile, 0.018)
    if sweep_hz is None:
        sweep_hz = {"resonance": 0.5, "slide": 0.5}.get(profile, 0.125)
    if profile == "slide":
        # triangle: constant piston speed 4 A f, reversed within the pump's J_p/d_p ~ 8 ms;
        # the current that holds that speed against d_p + d_c is fed forward
        phase = (sweep_hz * t_all + 0.25) % 1.0
        x_sweep = sweep_m * (4.0 * np.abs(phase - 0.5) - 1.0) if kx else 0.0 * t_all
        v_ref = np.gradient(x_sweep, t_all)
        pp = plant.params
        exc = exc + (pp[L.P_DP] + pp[L.P_DC]) * np.sign(np.round(v_ref, 6)) \
            * 4.0 * sweep_m * sweep_hz / pp[L.P_KT_EQ]
    else:
        x_sweep = sweep_m * np.sin(2 * np.pi * sweep_hz * t_all) if kx else 0.0 * t_all
    rec = np.zeros((n, L.N_OUTPUTS))
    iq_log = np.zeros(n)
    iq_app = np.zeros(n)
    rec[0] = plant.y
    x_ref = float(plant.y[L.Y_X_PISTON])
    extra = mags.get("pump_pulsation_extra")
    if extra is not None:
        p = plant.params
        ex_order, ex_phase = float(extra["order"]), float(extra["phase_rad"])
        ex_amp = float(extra["torque_n"]) / p[L.P_KT_EQ]  # A of current per N of torque
        kc_kp, half_tick = p[L.P_KC_OVER_KP], 0.5 * plant.tick_s
    for k in range(n):
        iq_log[k] = exc[k] - kx * (rec[k, L.Y_X_PISTON] - x_ref - x_sweep[k])
        if k == n - 1:
            break
        i_prev = iq_log[k - q - 1] if k - q - 1 >= 0 else 0.0
        i_now = iq_log[k - q] if k - q >= 0 else 0.0
        if extra is None:
            if r:
                plant.set_current(i_prev)
                plant.advance(r)
            plant.set_current(i_now)
            plant.advance(every - r)
        else:
            for tick in range(every):
                x = plant.x
                theta = (x[L.S_THP] + half_tick * x[L.S_VP]) * kc_kp
                ripple = ex_amp * math.sin(ex_order * theta + ex_phase)
                plant.set_current((i_prev if tick < r else i_now) - ripple)
                plant.advance(1)
        iq_app[k] = i_now
        rec[k + 1] = plant.y
    t = np.arange(n) / fs
    cols = {
        "iq": iq_log,
        "theta_m": rec[:, L.Y_THETA_M].copy(),
        "p_pump_a": rec[:, L.Y_P_PUMP_A].copy(),
        "p_pump_b": rec[:, L.Y_P_PUMP_B].copy(),
        "p_cyl_a": rec[:, L.Y_P_CYL_A].copy(),
        "p_cyl_b": rec[:, L.Y_P_CYL_B].copy(),
        "p_acc": rec[:, L.Y_P_ACC].copy(),
        "x_piston": rec[:, L.Y_X_PISTON].copy(),
        "f_strain": rec[:, L.Y_F_STRAIN].copy(),
        "temp_c": rec[:, L.Y_TEMP].copy(),
    }
    truth: dict[str, dict[str, float]] = {}
    for name, mag in mags.items():
        truth[name] = SYNTH_REGISTRY[name].truth(mag, cfg, rec, fs)
    if "sensor_saturation" in mags:
        level = mags["sensor_saturation"]["level_pa"]
        for c in ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc"):
            cols[c] = np.minimum(cols[c], level)
    if "mains_hum" in mags:
        m = mags["mains_hum"]
        cols["p_pump_a"] = cols["p_pump_a"] + m["amplitude_pa"] * np.sin(
            2 * np.pi * m["freq_hz"] * t + 0.3)
    if "backlash" in mags:
        # the dead band sits between rotor and encoder disc, so the reading stays on the
        # encoder's count grid
        q = 2 * math.pi / cfg.get("effects.quantisation.motor_counts_per_rev")
        true_angle = np.cumsum(rec[:, L.Y_OMEGA_M]) / fs
        cols["theta_m"] = np.floor(_backlash(true_angle, mags["backlash"]["width_rad"]) / q) * q
    data = MeasuredData(path=f"<synth {load} {'+'.join(mags) or 'null'} seed {seed}>",
                        load=load, sample_rate_hz=fs, t=t, columns=cols,
                        header={"source": "eha-hil identify synth",
                                # the plant is driven by the logged value, held per sample
                                "intersample": "zoh"})
    states = {"v_p": rec[:, L.Y_VP].copy(), "tau_q": rec[:, L.Y_TAU_Q].copy(),
              "t_oil": rec[:, L.Y_T_OIL].copy(), "v_piston": rec[:, L.Y_V_PISTON].copy()}
    return SynthResult(data, truth, cfg, iq_app, states)


def _backlash(theta: np.ndarray, width: float) -> np.ndarray:
    """A dead band of ``width`` rad between the rotor and the encoder disc."""
    out = np.empty_like(theta)
    pos = theta[0]
    half = width / 2
    for i, th in enumerate(theta):
        if th - pos > half:
            pos = th - half
        elif pos - th > half:
            pos = th + half
        out[i] = pos
    return out


__all__ = ["ALL_SYNTH_EFFECTS", "DEFAULT_MAGNITUDES", "OUTSIDE_EFFECTS", "PLANT_EFFECTS",
           "PROFILES", "SynthResult", "WRAPPER_EFFECTS", "generate", "multisine",
           "synth_config"]
