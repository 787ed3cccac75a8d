"""An independent test rig: identification datasets that differ from the fitted model the
way a real rig's logs do.

The identification tool (``eha-hil identify``) fits a fast linear model of thesis chapter 2
plus library effects. Data from the project's own plant (:mod:`hil.identify.synth`) shares
that model's structure, integrator and constants, so fitting it proves little. This module
simulates the actuator on its own, from the physical description, and imports nothing of
the fitted model or the plant (only the preset's numbers through
:func:`plant.config.load_config`).

Physics (piston-equivalent coordinates, thesis ch. 2, SI units). States: pump position
``theta_p`` (m) and velocity ``v_p`` (m/s), the series-spring force ``tau_s`` (N), the force
of an optional Maxwell branch ``tau_m`` (N), piston ``x_c`` (m), ``v_c`` (m/s), and the
sensor states (first-order filters of four pressures and the strain force)::

    F           = tau_s + tau_m                                  hydraulic force k_c (p_a - p_b)
    J_p dv_p/dt = K i(t - d) - d_p r v_p - g(theta) F - T_mesh(theta) - F_pc s(v_p / eps_p)
    w           = g(theta) v_p - F / (d_s r) - v_c               spring compression rate
    d tau_s/dt  = k_s(x_c) w
    d tau_m/dt  = k_m w - (k_m / c_m) tau_m                      (hose_viscoelastic only)
    J_c dv_c/dt = F - d_c r v_c - f_load + f_seal(v_c)

with ``theta = theta_0 + theta_p k_c/k_p`` the rotor angle (rad), ``g = 1 + sum a_n sin(n
theta + phi_n)`` the flow ripple (its reaction ``-(g - 1) F`` on the pump keeps the power
balance), ``T_mesh = sum T_n sin(n theta + psi_n)`` the load-independent meshing torque,
``r = exp(-c (T_oil - T_ref))`` the viscosity factor, ``s(u) = (2/pi) atan(u)`` the friction
sign law, ``f_load = 0`` (free), ``k_rod x_c + c_rod v_c`` (conrod) and ``x_c = v_c = 0``
(fixed). Pressures: ``p_pump_a = p_0 + max(F, 0)/k_c``, ``p_pump_b = p_0 + max(-F, 0)/k_c``;
the cylinder side uses ``f_cyl = F - d_c r v_c``. Strain: the rod force (fixed: ``f_cyl``,
conrod: ``k_rod x_c + c_rod v_c``, free: 0) plus ``n_per_c (T_oil - T_oil(0))``.

Integrator: classical fourth-order Runge-Kutta at a fixed step of about 10 us (the fit uses
an exact zero-order-hold discretisation over 4 sub-steps per 200 us sample). The sample
interval is split where the delayed input has a kink or a step, so the step grid never
straddles one. The current is continuous in time: the multisine is evaluated at every
Runge-Kutta stage (phasors rotated per half step), the position-loop current follows a 1 kHz
current-loop lag analytically; ``intersample="zoh"`` holds the logged current instead.

Realism: true parameters drawn up to ``spread`` from the preset; the logged current is the
true one plus Gaussian noise on a 12-bit +-40 A grid; pressures, strain, encoder, piston
scale and temperature have their bandwidths, noise and quantisation; the oil temperature
follows a selectable shape; friction laws and constants differ from the fit's defaults.
See :data:`SENSORS`, :data:`TEMPERATURE_SHAPES`, :data:`RIG_DEFAULT_MAGNITUDES` and
docs/identify.md ("An independent generator").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit

from hil.identify.csvdata import LOAD_CASES, MeasuredData
from hil.identify.record_options import INTERSAMPLE, RIG_PROFILES, TEMPERATURE_SHAPES
from hil.identify.rig_effects import (
    LIBRARY_EFFECTS,
    OUTSIDE_EFFECTS,
    POSITIVE_KEYS,
    RIG_EFFECTS,
    RIG_REGISTRY,
    KernelSetup,
    RigRecord,
    ks_of_x,
    pulsation_orders,
)
from hil.identify.rig_layout import (
    I_CROD,
    I_DC,
    I_DP,
    I_DRIFT,
    I_DS,
    I_HALF,
    I_JC,
    I_JP,
    I_K,
    I_KAPPA,
    I_KC,
    I_KCKP,
    I_KM,
    I_KM_RATE,
    I_KPIPE,
    I_KROD,
    I_KS,
    I_KSX,
    I_LOAD,
    I_P0,
    I_PC,
    I_PC_EPS,
    I_SF_C,
    I_SF_EPS,
    I_SF_S,
    I_SF_VS,
    I_T0,
    I_TAU_CL,
    I_TH0,
    I_TREF,
    I_VISC,
    I_VSIDE,
    I_WP,
    I_WS,
    I_XLSB,
    N_P,
    N_Z,
    Z_FS,
    Z_PCA,
    Z_PCB,
    Z_PPA,
    Z_PPB,
    Z_TAUM,
    Z_TAUS,
    Z_THP,
    Z_VC,
    Z_VP,
    Z_XC,
)
from plant.config import Config, load_config

# --------------------------------------------------------------------------------------
# Defaults
# --------------------------------------------------------------------------------------

#: Realistic default magnitudes. Pulsation: further orders by suffix (``order_2``,
#: ``amplitude_2``, ``phase_rad_2``, ``torque_n_2``, ``torque_phase_rad_2``; order 0 = off).
#: Friction regularisation and Stribeck velocities differ from the fit's defaults on purpose
#: (fit: tanh, eps_pump 1e-4 m/s; seal Stribeck 5 mm/s, eps 2 mm/s).
RIG_DEFAULT_MAGNITUDES: dict[str, dict[str, float]] = {
    n: dict(RIG_REGISTRY[n].defaults) for n in RIG_EFFECTS}

#: Effects that need a moving oil temperature.
NEEDS_TEMPERATURE = tuple(n for n in RIG_EFFECTS if RIG_REGISTRY[n].needs_temperature)

#: Sensor chain: first-order bandwidth (Hz), Gaussian noise (1 sigma) and quantisation.
SENSORS: dict[str, float] = {
    "current_full_scale_a": 40.0,        # 12-bit converter over +-40 A
    "current_bits": 12,
    "pressure_bandwidth_hz": 2500.0,
    "pressure_noise_pa": 2.0e3,
    "pressure_full_scale_pa": 7.0e6,     # 12-bit over 0..7 MPa
    "pressure_bits": 12,
    "strain_bandwidth_hz": 1000.0,
    "strain_noise_n": 0.3,
    "strain_full_scale_n": 3000.0,       # 24-bit over +-3000 N
    "strain_bits": 24,
    "encoder_counts_per_rev": 2048,      # floor quantisation
    "piston_lsb_m": 5.0e-9,              # floor quantisation
    "temperature_noise_c": 0.05,
    "temperature_lsb_c": 0.0625,
}

#: The kernel's number of each oil temperature shape. The shapes (:data:`TEMPERATURE_SHAPES`),
#: the excitation profiles and :data:`INTERSAMPLE` are defined in
#: :mod:`hil.identify.record_options`, which the command line lists without the kernels.
_SHAPE_ID = {name: i for i, name in enumerate(TEMPERATURE_SHAPES)}
PROFILES = RIG_PROFILES

#: Position loop of the free piston (A per m of error, per profile) and the current-loop
#: bandwidth (Hz). Under the default multisine the slow lines push the piston by up to
#: ~10 mm against a 600 A/m loop (corner ~0.7 Hz); with the +-14 mm sweep that stays
#: inside the +-25 mm stroke (~+-22 mm reached). The other profiles have little slow
#: excitation and keep the synth's 300 A/m.
POSITION_LOOP_A_PER_M = {"multisine": 600.0, "slide": 300.0, "resonance": 300.0}
CURRENT_LOOP_HZ = 1000.0
#: Nominal Runge-Kutta step, s.
STEP_S = 10e-6

# --------------------------------------------------------------------------------------
# Kernel (numba): parameter vector layout
# --------------------------------------------------------------------------------------

_TWO_OVER_PI = 2.0 / math.pi


@njit(cache=True)
def _temperature(t: float, tp: np.ndarray) -> float:
    """True oil temperature (degC) at time ``t`` (s); ``tp`` = shape id, a, b, c, record."""
    shape = int(tp[0])
    a, b, c, rec = tp[1], tp[2], tp[3], tp[4]
    if shape == 0:
        return a
    if shape == 1:
        return a + (b - a) * t / rec
    if shape == 2:
        return a + (b - a) * (1.0 - math.exp(-t / c))
    if shape == 3:
        temp = a
        for j in range(1, 4):
            tj = j * rec / 4.0
            if t > tj:
                temp += (b - a) / 3.0 * (1.0 - math.exp(-(t - tj) / c))
        return temp
    return a + b * math.sin(2.0 * math.pi * t / c)


@njit(cache=True)
def _deriv(z: np.ndarray, cur: float, temp: float, p: np.ndarray, po: np.ndarray,
           dz: np.ndarray) -> None:
    """Right-hand side: ``dz = f(z, i, T_oil)`` (see the module docstring)."""
    r = 1.0
    if p[I_VISC] != 0.0:
        r = math.exp(-p[I_VISC] * (temp - p[I_TREF]))
    ds = p[I_DS] * r
    dp = p[I_DP] * r
    dc = p[I_DC] * r
    vp = z[Z_VP]
    force = z[Z_TAUS] + z[Z_TAUM]
    xc = z[Z_XC]
    vc = z[Z_VC]
    kc = p[I_KC]
    ripple = 0.0
    mesh = 0.0
    if po.shape[0] > 0:
        th = p[I_TH0] + z[Z_THP] * p[I_KCKP]
        for m in range(po.shape[0]):
            n = po[m, 0]
            ripple += po[m, 1] * math.sin(n * th + po[m, 2])
            mesh += po[m, 3] * math.sin(n * th + po[m, 4])
    g = 1.0 + ripple
    f_pump = -mesh
    if p[I_PC] != 0.0:
        f_pump -= p[I_PC] * _TWO_OVER_PI * math.atan(vp / p[I_PC_EPS])
    ks = p[I_KS]
    if p[I_KSX] != 0.0:
        # Eq. 2.25-2.27 evaluated from the chamber volumes as they are
        v1 = p[I_VSIDE] + kc * (p[I_HALF] + xc)
        v2 = p[I_VSIDE] + kc * (p[I_HALF] - xc)
        kf = p[I_KAPPA] * kc * kc * (1.0 / v1 + 1.0 / v2)
        ks = 1.0 / (1.0 / kf + 1.0 / p[I_KPIPE])
    w = g * vp - force / ds - vc
    dz[Z_THP] = vp
    dz[Z_VP] = (p[I_K] * cur - dp * vp - g * force + f_pump) / p[I_JP]
    dz[Z_TAUS] = ks * w
    if p[I_KM] != 0.0:
        dz[Z_TAUM] = p[I_KM] * w - p[I_KM_RATE] * z[Z_TAUM]
    else:
        dz[Z_TAUM] = 0.0
    f_cyl = force - dc * vc
    load = int(p[I_LOAD])
    if load == 0:
        dz[Z_XC] = 0.0
        dz[Z_VC] = 0.0
        rod = f_cyl
    else:
        rod = 0.0
        if load == 2:
            rod = p[I_KROD] * xc + p[I_CROD] * vc
        f_seal = 0.0
        if p[I_SF_C] != 0.0 or p[I_SF_S] != 0.0:
            q = vc / p[I_SF_VS]
            level = p[I_SF_C] + (p[I_SF_S] - p[I_SF_C]) * math.exp(-q * q)
            f_seal = -level * _TWO_OVER_PI * math.atan(vc / p[I_SF_EPS])
        dz[Z_XC] = vc
        dz[Z_VC] = (f_cyl - rod + f_seal) / p[I_JC]
    p0 = p[I_P0]
    wp = p[I_WP]
    dz[Z_PPA] = wp * (p0 + max(force, 0.0) / kc - z[Z_PPA])
    dz[Z_PPB] = wp * (p0 + max(-force, 0.0) / kc - z[Z_PPB])
    dz[Z_PCA] = wp * (p0 + max(f_cyl, 0.0) / kc - z[Z_PCA])
    dz[Z_PCB] = wp * (p0 + max(-f_cyl, 0.0) / kc - z[Z_PCB])
    drift = p[I_DRIFT] * (temp - p[I_T0])
    dz[Z_FS] = p[I_WS] * (rod + drift - z[Z_FS])


@njit(cache=True)
def _quantise_current(i: float, lsb: float, full_codes: float) -> float:
    """Round to the converter's grid, clipped to its codes (-full_codes .. full_codes - 1)."""
    code = math.floor(i / lsb + 0.5)
    if code > full_codes - 1.0:
        code = full_codes - 1.0
    if code < -full_codes:
        code = -full_codes
    return code * lsb


@njit(cache=True)
def _simulate(p: np.ndarray, po: np.ndarray, tp: np.ndarray, lw: np.ndarray, la: np.ndarray,
              lph: np.ndarray, n: int, ts: float, h_nom: float, zoh: bool, delay: float,
              kx: float, xref: np.ndarray, ff: np.ndarray, noise: np.ndarray, i_lsb: float,
              i_codes: float, z0: np.ndarray, zs: np.ndarray, temps: np.ndarray,
              cur: np.ndarray) -> None:
    """Integrate the record; fill ``zs[k]`` (state at ``t_k``), ``temps[k]`` (true oil
    temperature) and ``cur[k]`` = (true current the log samples, applied current, logged
    current) at ``t_k``.

    Input ``i(t)``: ``lw, la, lph`` (rad/s, A, rad) the continuous multisine lines; ``kx``
    (A/m) the position-loop gain on the floor-quantised piston position against ``xref``
    (m), plus the feed-forward ``ff`` (A), one per sample, filtered by the current loop (time
    constant ``p[I_TAU_CL]``); ``noise`` (A) the converter noise. The motor sees ``i(t -
    delay)``; ``zoh`` holds the logged value instead of the continuous current.
    """
    nz = z0.size
    z = z0.copy()
    k1 = np.empty(nz)
    k2 = np.empty(nz)
    k3 = np.empty(nz)
    k4 = np.empty(nz)
    zt = np.empty(nz)
    nl = lw.size
    cre = np.empty(nl)
    cim = np.empty(nl)
    rre = np.empty(nl)
    rim = np.empty(nl)
    u = np.zeros(n)
    pl = np.zeros(n + 1)
    iq_log = np.zeros(n)
    tau_cl = p[I_TAU_CL]
    decay = math.exp(-ts / tau_cl)
    q = int(math.floor(delay / ts + 1e-9))
    dres = delay - q * ts
    if dres < 1e-9 * ts:
        dres = 0.0
    xlsb = p[I_XLSB]
    for k in range(n):
        tk = k * ts
        for i in range(nz):
            zs[k, i] = z[i]
        temps[k] = _temperature(tk, tp)
        uk = ff[k]
        if kx != 0.0:
            # the loop reads the encoder (floor-quantised), as the MCU does
            xm = math.floor(z[Z_XC] / xlsb) * xlsb
            uk -= kx * (xm - xref[k])
        u[k] = uk
        pl[k + 1] = uk + (pl[k] - uk) * decay
        ms = 0.0
        for m in range(nl):
            ms += la[m] * math.sin(lw[m] * tk + lph[m])
        if zoh:
            iq_log[k] = _quantise_current(ms + uk + noise[k], i_lsb, i_codes)
            cur[k, 0] = iq_log[k]
        else:
            cur[k, 0] = ms + pl[k]
            iq_log[k] = _quantise_current(cur[k, 0] + noise[k], i_lsb, i_codes)
        cur[k, 2] = iq_log[k]
        first = True
        for seg in range(2):
            # segment 0: [t_k, t_k + dres), delayed input in sample interval k - q - 1;
            # segment 1: [t_k + dres, t_k+1), delayed input in interval k - q
            if seg == 0:
                length = dres
                j = k - q - 1
                e0 = ts - dres
                t_seg = tk
            else:
                length = ts - dres
                j = k - q
                e0 = 0.0
                t_seg = tk + dres
            if length <= 0.0:
                continue
            msteps = max(1, int(math.ceil(length / h_nom - 1e-9)))
            h = length / msteps
            # before the record the motor got no current (the log starts with the drive)
            active = j >= 0
            ival = 0.0
            uj = 0.0
            pj = 0.0
            if active:
                ival = iq_log[j]
                uj = u[j]
                pj = pl[j]
            if not zoh and active:
                for m in range(nl):
                    ang = lw[m] * (t_seg - delay) + lph[m]
                    cre[m] = math.cos(ang)
                    cim[m] = math.sin(ang)
                    rre[m] = math.cos(0.5 * lw[m] * h)
                    rim[m] = math.sin(0.5 * lw[m] * h)
            if zoh or not active:
                i0 = ival
            else:
                i0 = uj + (pj - uj) * math.exp(-e0 / tau_cl)
                for m in range(nl):
                    i0 += la[m] * cim[m]
            if first:
                cur[k, 1] = i0
                first = False
            if k == n - 1:
                break
            temp0 = _temperature(t_seg, tp)
            for s in range(msteps):
                t0 = t_seg + s * h
                if zoh or not active:
                    ih = ival
                    i1 = ival
                else:
                    ih = uj + (pj - uj) * math.exp(-(e0 + (s + 0.5) * h) / tau_cl)
                    i1 = uj + (pj - uj) * math.exp(-(e0 + (s + 1.0) * h) / tau_cl)
                    for m in range(nl):
                        a = cre[m] * rre[m] - cim[m] * rim[m]
                        b = cre[m] * rim[m] + cim[m] * rre[m]
                        ih += la[m] * b
                        c2 = a * rre[m] - b * rim[m]
                        s2 = a * rim[m] + b * rre[m]
                        cre[m] = c2
                        cim[m] = s2
                        i1 += la[m] * s2
                temph = _temperature(t0 + 0.5 * h, tp)
                temp1 = _temperature(t0 + h, tp)
                _deriv(z, i0, temp0, p, po, k1)
                for i in range(nz):
                    zt[i] = z[i] + 0.5 * h * k1[i]
                _deriv(zt, ih, temph, p, po, k2)
                for i in range(nz):
                    zt[i] = z[i] + 0.5 * h * k2[i]
                _deriv(zt, ih, temph, p, po, k3)
                for i in range(nz):
                    zt[i] = z[i] + h * k3[i]
                _deriv(zt, i1, temp1, p, po, k4)
                for i in range(nz):
                    z[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
                i0 = i1
                temp0 = temp1


# --------------------------------------------------------------------------------------
# Python side
# --------------------------------------------------------------------------------------


@dataclass
class RigResult:
    """A generated record, the truth behind it and the rig's configuration.

    ``truth``: ``"parameters"`` (drawn baseline values: ``gain_n_per_a`` N/A, ``ds``,
    ``dp``, ``dc`` N s/m at ``reference_c``, ``ks`` N/m (mid-stroke), ``jp``, ``jc`` kg,
    ``k_rod`` N/m, ``c_rod`` N s/m, ``precharge_pa`` Pa, ``reference_c`` degC), ``"effects"``
    ({name: {param: value}} in the identification report's terms), ``"temperature"``.
    ``signals``: true values at the sample instants (``iq_true``, ``iq_applied`` A, ``v_p``,
    ``v_c`` m/s, ``x_c`` m, ``tau_q`` N (= F), ``theta_rotor`` rad, ``t_oil`` degC, and the
    unfiltered pressures ``p_*_true`` Pa and rod force ``f_rod_true`` N).
    """

    data: MeasuredData
    truth: dict[str, Any]
    config: dict[str, Any]
    signals: dict[str, np.ndarray] = field(default_factory=dict)


def rig_multisine(f_lo: float, f_hi: float, n_lines: int, rms: float,
                  rng: np.random.Generator, t: np.ndarray | None = None,
                  tries: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random-phase multisine lines: (frequencies Hz, amplitudes A, phases rad).

    ``n_lines`` log-spaced lines from ``f_lo`` to ``f_hi`` Hz, amplitudes falling as
    ``1/sqrt(f)`` (slow lines move the rotor, fast ones still excite the resonances), scaled
    so that the continuous-time rms ``sqrt(sum a^2 / 2)`` is ``rms`` A. Given the sample
    times ``t`` (s), the lowest-peak of ``tries`` phase draws is kept (as an experimenter
    does, so the pressures stay inside the sensors' range) and the amplitudes are scaled to
    ``rms`` over ``t``: the slow lines do not average out within a few seconds, so the
    infinite-time rms would misstate the record's.
    """
    f = np.geomspace(f_lo, f_hi, n_lines)
    a = 1.0 / np.sqrt(f)
    a *= rms / math.sqrt(0.5 * float(np.sum(a * a)))
    if t is None:
        return f, a, rng.uniform(0.0, 2.0 * math.pi, n_lines)
    # the crest factor is judged on every 4th sample: near enough, and 4x cheaper
    t_coarse = t[::4]
    best: tuple[float, np.ndarray] | None = None
    for _ in range(max(1, tries)):
        ph = rng.uniform(0.0, 2.0 * math.pi, n_lines)
        u = _lines_at(f, a, ph, t_coarse)
        crest = float(np.max(np.abs(u))) / math.sqrt(float(np.mean(u * u)))
        if best is None or crest < best[0]:
            best = (crest, ph)
    ph = best[1]
    u = _lines_at(f, a, ph, t)
    return f, a * (rms / math.sqrt(float(np.mean(u * u)))), ph


@njit(cache=True)
def _lines_on_grid(w: np.ndarray, a: np.ndarray, ph: np.ndarray, dt: float,
                   n: int) -> np.ndarray:
    """Sum of the lines ``a sin(w t + ph)`` at ``t = k dt``, k = 0..n-1 (rad/s, A, rad, s),
    by rotating each line's phasor one step at a time (recomputed exactly every 1024 steps,
    so the rounding does not accumulate)."""
    u = np.zeros(n)
    for m in range(w.size):
        rc = math.cos(w[m] * dt)
        rs = math.sin(w[m] * dt)
        c = 0.0
        s = 0.0
        for k in range(n):
            if k % 1024 == 0:
                c = math.cos(w[m] * k * dt + ph[m])
                s = math.sin(w[m] * k * dt + ph[m])
            u[k] += a[m] * s
            c, s = c * rc - s * rs, c * rs + s * rc
    return u


def _lines_at(f: np.ndarray, a: np.ndarray, ph: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Sum of the lines ``a sin(2 pi f t + ph)`` at the uniformly spaced times ``t`` (from 0)."""
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    return _lines_on_grid(2.0 * math.pi * f, a, ph, dt, t.size)


def _normalise_effects(effects: Mapping[str, Mapping[str, float]] | Sequence[str]
                       ) -> dict[str, dict[str, float]]:
    if isinstance(effects, str):
        effects = (effects,)
    if not isinstance(effects, Mapping):
        effects = {name: {} for name in effects}
    out: dict[str, dict[str, float]] = {}
    for name, over in effects.items():
        if name not in RIG_DEFAULT_MAGNITUDES:
            raise ValueError(f"unknown rig effect {name!r} (known: {', '.join(RIG_EFFECTS)})")
        mag = dict(RIG_DEFAULT_MAGNITUDES[name])
        for key, value in dict(over).items():
            if not RIG_REGISTRY[name].accepts(key):
                raise ValueError(f"effect {name}: unknown magnitude {key!r} "
                                 f"(known: {', '.join(RIG_DEFAULT_MAGNITUDES[name]) or 'none'})")
            mag[key] = float(value)
        for key in POSITIVE_KEYS:
            # regularisation velocities and corners divide: zero would give inf/nan
            if key in mag and not mag[key] > 0:
                raise ValueError(f"effect {name}: {key} must be > 0, got {mag[key]}")
        out[name] = mag
    return out


_pulsation_orders = pulsation_orders


def _preset_config(preset: str | Config) -> Config:
    """The configuration the rig's nominal numbers come from: a preset name, a TOML path or
    a ready :class:`~plant.config.Config`."""
    return preset if isinstance(preset, Config) else load_config(preset)


def draw_parameters(preset: str | Config = "hydra_default", seed: int = 1,
                    spread: float = 0.15) -> dict[str, float]:
    """True baseline parameters: each uniform within ``+-spread`` of the preset (``J_p``,
    ``J_c``: ``+-2/3 spread``); the precharge ``0.5 MPa +- 0.2 MPa x spread/0.15``. The draw
    order is fixed, so the values for a seed do not depend on the effects switched on
    (the precharge is kept >= 0.05 MPa for large spreads).
    Also returns the bulk modulus and pipe stiffness (``+-spread``) that ``k_s(x)`` uses."""
    if not 0.0 <= spread < 1.0:
        raise ValueError(f"spread {spread}: must be in [0, 1)")
    cfg = _preset_config(preset)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 101]))
    g = cfg.get

    def d(nominal: float, rel: float) -> float:
        return float(nominal * (1.0 + rel * rng.uniform(-1.0, 1.0)))

    gain = g("motor.force_at_rated_n") / g("motor.iq_rated_a")
    out = {
        "gain_n_per_a": d(gain, spread),
        "ds": d(g("hydraulics.ds_ns_per_m"), spread),
        "dp": d(g("hydraulics.dp_ns_per_m"), spread),
        "dc": d(g("hydraulics.dc_ns_per_m"), spread),
        "ks": d(g("hydraulics.ks_n_per_m"), spread),
        "jp": d(g("hydraulics.jp_kg"), spread * 2.0 / 3.0),
        "jc": d(g("hydraulics.jc_kg"), spread * 2.0 / 3.0),
        "k_rod": d(g("load.conrod_stiffness_n_per_m"), spread),
        "c_rod": d(g("load.conrod_damping_ns_per_m"), spread),
        "precharge_pa": max(0.05e6, float(g("hydraulics.precharge_pa")
                                          + 0.2e6 * spread / 0.15 * rng.uniform(-1.0, 1.0))),
        "bulk_modulus_pa": d(g("hydraulics.bulk_modulus_pa"), spread),
        "ks_pipe_n_per_m": d(g("hydraulics.ks_pipe_n_per_m"), spread),
    }
    return out


_ks_of_x = ks_of_x  # the physical law, for the tests of the physics


def _backlash(theta: np.ndarray, width: float) -> np.ndarray:
    """Encoder-disc angle behind a dead band of ``width`` rad (a play operator)."""
    out = np.empty_like(theta)
    pos = float(theta[0])
    half = 0.5 * width
    for i, th in enumerate(theta):
        if th - pos > half:
            pos = th - half
        elif pos - th > half:
            pos = th + half
        out[i] = pos
    return out


def _temperature_params(shape: str, seconds: float) -> np.ndarray:
    """Kernel parameters (shape id, a, b, c, record) of a temperature shape."""
    sid = _SHAPE_ID[shape]
    if shape == "constant":
        a, b, c = 25.0, 25.0, 1.0
    elif shape == "ramp":
        a, b, c = 15.0, 25.0, 1.0
    elif shape == "ramp_level":
        a, b, c = 15.0, 22.0, seconds / 3.0
    elif shape == "steps":
        a, b, c = 15.0, 22.5, seconds / 60.0
    else:
        a, b, c = 20.0, 3.0, seconds / 2.0
    return np.array([sid, a, b, c, seconds], dtype=float)


@dataclass
class _Excitation:
    """The experiment's input: multisine lines (Hz, A, rad), the free piston's position loop
    (A/m; 0 for none) with its reference (m) and feed-forward (A) per sample, the sweep, and
    a description."""

    lines_hz: np.ndarray
    amps_a: np.ndarray
    phases: np.ndarray
    kx: float
    xref: np.ndarray
    ff: np.ndarray
    sweep_m: float
    sweep_hz: float
    description: str


def _excitation(load: str, profile: str, cfg: Config, t: np.ndarray, rng_exc: np.random.Generator,
                excitation_lines: tuple[Sequence[float], Sequence[float], Sequence[float]] | None,
                position_loop_a_per_m: float | None) -> _Excitation:
    """The profile's multisine (or the given lines) and, with the piston free, the position
    loop that keeps it inside the stroke while sweeping it (see :func:`generate_rig`)."""
    n = t.size
    free = load == "free_piston"
    if excitation_lines is not None:
        lf, la, lph = (np.asarray(v, dtype=float).ravel() for v in excitation_lines)
        if not lf.size == la.size == lph.size:
            raise ValueError("excitation_lines: three sequences of the same length")
        exc_desc = f"{lf.size} given lines"
    elif profile == "slide":
        lf, la, lph = rig_multisine(0.3, 300.0, 50, 0.5, rng_exc, t)
        exc_desc = "0.5 A rms, 0.3-300 Hz, 50 lines"
    elif profile == "resonance":
        f1, a1, p1 = rig_multisine(0.3, 300.0, 50, 1.0, rng_exc, t)
        f2, a2, p2 = rig_multisine(700.0, 2000.0, 60, 4.0, rng_exc, t)
        lf, la, lph = np.r_[f1, f2], np.r_[a1, a2], np.r_[p1, p2]
        exc_desc = "1 A rms 0.3-300 Hz (50 lines) + 4 A rms 700-2000 Hz (60 lines)"
    elif free:
        lf, la, lph = rig_multisine(0.3, 2000.0, 100, 2.5, rng_exc, t)
        exc_desc = "2.5 A rms, 0.3-2000 Hz, 100 lines"
    else:
        lf, la, lph = rig_multisine(0.3, 300.0, 100, 5.0, rng_exc, t)
        exc_desc = "5 A rms, 0.3-300 Hz, 100 lines"
    kx = 0.0
    xref = np.zeros(n)
    ff = np.zeros(n)
    sweep_m, sweep_hz = 0.0, 0.0
    if free:
        kx = (POSITION_LOOP_A_PER_M[profile] if position_loop_a_per_m is None
              else position_loop_a_per_m)
        sweep_m = {"resonance": 0.030, "slide": 0.018}.get(profile, 0.014)
        sweep_hz = {"resonance": 0.5, "slide": 0.5}.get(profile, 0.125)
        if profile == "slide":
            # triangle at constant speed 4 A f; the current that holds that speed against
            # the preset's (not the true) d_p + d_c is fed forward, as an experimenter would
            phase = (sweep_hz * t + 0.25) % 1.0
            xref = sweep_m * (4.0 * np.abs(phase - 0.5) - 1.0)
            v_ref = 4.0 * sweep_m * sweep_hz * np.sign(phase - 0.5)
            d_nom = cfg.get("hydraulics.dp_ns_per_m") + cfg.get("hydraulics.dc_ns_per_m")
            k_nom = cfg.get("motor.force_at_rated_n") / cfg.get("motor.iq_rated_a")
            ff = d_nom * v_ref / k_nom
        else:
            xref = sweep_m * np.sin(2.0 * math.pi * sweep_hz * t)
        if kx == 0.0:
            xref = np.zeros(n)
    return _Excitation(lf, la, lph, float(kx), xref, ff, sweep_m, sweep_hz, exc_desc)


def _steps() -> tuple[float, float, float]:
    """The converters' steps of :data:`SENSORS`: pressure (Pa), strain (N), encoder (rad)."""
    return (SENSORS["pressure_full_scale_pa"] / 2 ** SENSORS["pressure_bits"],
            2.0 * SENSORS["strain_full_scale_n"] / 2 ** SENSORS["strain_bits"],
            2.0 * math.pi / SENSORS["encoder_counts_per_rev"])


def _sensors(zs: np.ndarray, cur: np.ndarray, temps: np.ndarray, p: np.ndarray,
             mags: dict[str, dict[str, float]], theta0: float, hum_phase: float, t: np.ndarray,
             n_press: np.ndarray, n_strain: np.ndarray, n_temp: np.ndarray
             ) -> tuple[dict[str, np.ndarray], np.ndarray, float]:
    """The logged columns from the simulated states (:data:`SENSORS`: noise, converters,
    encoders; the outside effects on the sensors), the true rotor angle, and the share of
    pressure samples beyond the converter's rail."""
    n = t.size
    p_lsb, s_lsb, enc_q = _steps()
    p_codes = 2 ** SENSORS["pressure_bits"] - 1
    s_codes = 2 ** (SENSORS["strain_bits"] - 1)
    sat_level = mags.get("sensor_saturation", {}).get("level_pa")
    press_names = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc")
    analog = [zs[:, Z_PPA], zs[:, Z_PPB], zs[:, Z_PCA], zs[:, Z_PCB],
              np.full(n, p[I_P0])]
    cols: dict[str, np.ndarray] = {"iq": cur[:, 2].copy()}
    rotor = theta0 + zs[:, Z_THP] * p[I_KCKP]
    disc = rotor
    if "backlash" in mags:
        disc = _backlash(rotor, mags["backlash"]["width_rad"])
    cols["theta_m"] = np.floor(disc / enc_q) * enc_q
    rail = 0.0
    for j, name in enumerate(press_names):
        v = analog[j] + n_press[j]
        if name == "p_pump_a" and "mains_hum" in mags:
            mh = mags["mains_hum"]
            v = v + mh["amplitude_pa"] * np.sin(2.0 * math.pi * mh["freq_hz"] * t + hum_phase)
        if sat_level is not None:
            v = np.minimum(v, sat_level)
        code = np.floor(v / p_lsb + 0.5)
        rail = max(rail, float(np.mean(code > p_codes)))
        cols[name] = np.clip(code, 0, p_codes) * p_lsb
    cols["x_piston"] = np.floor(zs[:, Z_XC] / SENSORS["piston_lsb_m"]) * SENSORS["piston_lsb_m"]
    code = np.floor((zs[:, Z_FS] + n_strain) / s_lsb + 0.5)
    cols["f_strain"] = np.clip(code, -s_codes, s_codes - 1) * s_lsb
    t_lsb = SENSORS["temperature_lsb_c"]
    cols["temp_c"] = np.floor((temps + n_temp) / t_lsb + 0.5) * t_lsb
    return cols, rotor, rail


@dataclass
class _Kernel:
    """The kernel's parameters for one record: the vector ``p`` (:mod:`rig_layout`), the
    pulsation orders, the temperature shape's parameters and its start (degC), the rotor
    angle at the encoder's zero and the mains hum's phase (rad), the effects' setup and the
    input delay (s)."""

    p: np.ndarray
    orders: np.ndarray
    tp: np.ndarray
    t_oil0: float
    theta0: float
    hum_phase: float
    setup: KernelSetup
    delay: float


def _kernel_parameters(load: str, mags: dict[str, dict[str, float]], cfg: Config,
                       truep: Mapping[str, float], kc: float, kp: float, half: float,
                       t_ref: float, temperature: str, seconds: float,
                       rng_misc: np.random.Generator) -> _Kernel:
    """The kernel's parameters from the drawn truth, the preset and the effects (each
    effect's class sets its own); two angles drawn from ``rng_misc``."""
    p = np.zeros(N_P)
    p[I_K] = truep["gain_n_per_a"]
    p[I_DS] = truep["ds"]
    p[I_DP] = truep["dp"]
    p[I_DC] = truep["dc"]
    p[I_KS] = truep["ks"]
    p[I_JP] = truep["jp"]
    p[I_JC] = truep["jc"]
    p[I_KROD] = truep["k_rod"]
    p[I_CROD] = truep["c_rod"]
    p[I_P0] = truep["precharge_pa"]
    p[I_KC] = kc
    p[I_KCKP] = kc / kp
    p[I_LOAD] = {"fixed_piston": 0, "free_piston": 1, "conrod_fixed": 2}[load]
    p[I_HALF] = half
    p[I_TREF] = t_ref
    p[I_WP] = 2.0 * math.pi * SENSORS["pressure_bandwidth_hz"]
    p[I_WS] = 2.0 * math.pi * SENSORS["strain_bandwidth_hz"]
    theta0 = float(rng_misc.uniform(0.0, 2.0 * math.pi))  # rotor angle at the encoder's zero
    hum_phase = float(rng_misc.uniform(0.0, 2.0 * math.pi))
    p[I_TH0] = theta0
    p[I_TAU_CL] = 1.0 / (2.0 * math.pi * CURRENT_LOOP_HZ)
    p[I_XLSB] = SENSORS["piston_lsb_m"]
    orders = np.zeros((0, 5))
    if "pump_pulsation" in mags:
        orders = np.array(pulsation_orders(mags["pump_pulsation"]), dtype=float).reshape(-1, 5)
    tp = _temperature_params(temperature, seconds)
    t_oil0 = float(_temperature(0.0, tp))
    p[I_T0] = t_oil0
    setup = KernelSetup(load, truep, cfg, kc, half)
    for name, effect in RIG_REGISTRY.items():  # in the registry's order: see there
        if name in mags:
            effect.set_kernel(p, mags[name], setup)
    delay = float(mags.get("input_delay", {}).get("delay_s", 0.0))
    if delay < 0 or not math.isfinite(delay):
        raise ValueError(f"input_delay: delay_s {delay} must be >= 0")
    return _Kernel(p, orders, tp, t_oil0, theta0, hum_phase, setup, delay)



def _initial_state(initial_state: Mapping[str, float] | None, load: str, p: np.ndarray,
                   kc: float, t_oil0: float, t_ref: float) -> np.ndarray:
    """The state at t = 0: the given ``theta_p, v_p, tau_q, x_c, v_c`` (a fixed piston
    stays put) and the sensor filters settled on them."""
    z0 = np.zeros(N_Z)
    if initial_state:
        names = {"theta_p": Z_THP, "v_p": Z_VP, "tau_q": Z_TAUS, "x_c": Z_XC, "v_c": Z_VC}
        for key, value in initial_state.items():
            if key not in names:
                raise ValueError(f"initial_state: unknown key {key!r} (known: {', '.join(names)})")
            z0[names[key]] = float(value)
        if load == "fixed_piston":
            z0[Z_XC] = z0[Z_VC] = 0.0
    f0 = z0[Z_TAUS]
    fc0 = f0 - p[I_DC] * math.exp(-p[I_VISC] * (t_oil0 - t_ref)) * z0[Z_VC]
    z0[Z_PPA] = p[I_P0] + max(f0, 0.0) / kc
    z0[Z_PPB] = p[I_P0] + max(-f0, 0.0) / kc
    z0[Z_PCA] = p[I_P0] + max(fc0, 0.0) / kc
    z0[Z_PCB] = p[I_P0] + max(-fc0, 0.0) / kc
    rod0 = {"fixed_piston": fc0, "free_piston": 0.0,
            "conrod_fixed": p[I_KROD] * z0[Z_XC] + p[I_CROD] * z0[Z_VC]}[load]
    z0[Z_FS] = rod0
    return z0


def generate_rig(
    load: str = "fixed_piston",
    effects: Mapping[str, Mapping[str, float]] | Sequence[str] = (),
    seconds: float = 6.0,
    seed: int = 1,
    sample_rate_hz: float = 5000.0,
    profile: str = "multisine",
    temperature: str | None = None,
    current_noise_lsb: float = 1.0,
    intersample: str = "continuous",
    spread: float = 0.15,
    preset: str | Config = "hydra_default",
    header_intersample: bool = False,
    excitation_lines: tuple[Sequence[float], Sequence[float], Sequence[float]] | None = None,
    position_loop_a_per_m: float | None = None,
    initial_state: Mapping[str, float] | None = None,
    step_s: float = STEP_S,
) -> RigResult:
    """Simulate one identification experiment on the independent rig (module docstring).

    ``effects``: names of :data:`RIG_EFFECTS` (default magnitudes) or {name: {key: value}}
    overrides of :data:`RIG_DEFAULT_MAGNITUDES`. ``temperature``: a shape of
    :data:`TEMPERATURE_SHAPES`; ``None`` takes ``"constant"``, or ``"ramp_level"`` when an
    effect needs a moving temperature (asking for ``"constant"`` with such an effect is an
    error). ``current_noise_lsb``: 1-sigma noise of the logged current in LSB of the 12-bit
    +-40 A converter. ``intersample``: ``"continuous"`` (the current varies within the
    sample, the log holds noisy samples of it) or ``"zoh"`` (the logged value, noise and all,
    is the digital command the motor gets, held over the sample). ``spread``: relative range
    of the drawn parameters. ``header_intersample`` writes ``intersample`` into the header.

    For tests of the physics: ``excitation_lines`` = (Hz, A, rad) replaces the profile's
    multisine (a 0 Hz line with phase pi/2 is a step at t = 0; empty sequences give no
    multisine), ``position_loop_a_per_m`` replaces the free piston's loop gain (0 = open
    loop; default :data:`POSITION_LOOP_A_PER_M`), ``initial_state`` sets ``theta_p, v_p,
    tau_q, x_c, v_c`` at t = 0; ``step_s`` is the nominal Runge-Kutta step (s).

    Raises ValueError for an unknown load, effect, magnitude, profile, temperature shape or
    intersample mode, and for a profile that needs the free piston.
    """
    if load not in LOAD_CASES:
        raise ValueError(f"unknown load {load!r} (known: {', '.join(LOAD_CASES)})")
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    if profile != "multisine" and load != "free_piston":
        raise ValueError(f"profile {profile!r} needs load free_piston")
    if intersample not in INTERSAMPLE:
        raise ValueError(f"unknown intersample {intersample!r} (known: continuous, zoh)")
    if current_noise_lsb < 0 or not math.isfinite(current_noise_lsb):
        raise ValueError(f"current noise {current_noise_lsb} LSB: must be >= 0")
    if not (seconds > 0 and sample_rate_hz > 0 and step_s > 0):
        raise ValueError("seconds, sample rate and step must be > 0")
    mags = _normalise_effects(effects)
    needs_temp = [e for e in NEEDS_TEMPERATURE if e in mags]
    if temperature is None:
        temperature = "ramp_level" if needs_temp else "constant"
    if temperature not in TEMPERATURE_SHAPES:
        raise ValueError(f"unknown temperature shape {temperature!r} "
                         f"(known: {', '.join(TEMPERATURE_SHAPES)})")
    if temperature == "constant" and needs_temp:
        raise ValueError(f"effect {needs_temp[0]} needs a moving temperature "
                         f"(not 'constant'; e.g. ramp_level)")

    cfg = _preset_config(preset)
    truep = draw_parameters(cfg, seed, spread)
    kc = float(cfg.get("hydraulics.kc_m2"))
    kp = float(cfg.get("hydraulics.kp_m3_per_rad"))
    half = 0.5 * float(cfg.get("hydraulics.stroke_m"))
    t_ref = float(cfg.get("effects.oil_temperature.reference_c"))
    seq = np.random.SeedSequence([int(seed), 202])
    rng_exc, rng_noise, rng_misc = (np.random.default_rng(s) for s in seq.spawn(3))

    fs = float(sample_rate_hz)
    ts = 1.0 / fs
    n = int(round(seconds * fs))
    if n < 10:
        raise ValueError(f"record of {n} samples: too short")
    t = np.arange(n) * ts

    # --- parameters of the kernel ---------------------------------------------------------
    kern = _kernel_parameters(load, mags, cfg, truep, kc, kp, half, t_ref, temperature,
                              seconds, rng_misc)
    p, orders, tp, t_oil0 = kern.p, kern.orders, kern.tp, kern.t_oil0
    theta0, hum_phase, setup, delay = kern.theta0, kern.hum_phase, kern.setup, kern.delay

    # --- excitation -----------------------------------------------------------------------
    exc = _excitation(load, profile, cfg, t, rng_exc, excitation_lines, position_loop_a_per_m)
    lf, la, lph, kx, xref, ff = exc.lines_hz, exc.amps_a, exc.phases, exc.kx, exc.xref, exc.ff

    # --- noise, drawn in a fixed order whatever the options -------------------------------
    i_lsb = 2.0 * SENSORS["current_full_scale_a"] / 2 ** SENSORS["current_bits"]
    i_codes = float(2 ** (SENSORS["current_bits"] - 1))
    n_iq = rng_noise.standard_normal(n) * current_noise_lsb * i_lsb
    n_press = rng_noise.standard_normal((5, n)) * SENSORS["pressure_noise_pa"]
    n_strain = rng_noise.standard_normal(n) * SENSORS["strain_noise_n"]
    n_temp = rng_noise.standard_normal(n) * SENSORS["temperature_noise_c"]

    # --- simulate -------------------------------------------------------------------------
    z0 = _initial_state(initial_state, load, p, kc, t_oil0, t_ref)
    zs = np.zeros((n, N_Z))
    temps = np.zeros(n)
    cur = np.zeros((n, 3))
    _simulate(p, orders, tp, 2.0 * math.pi * lf, la, lph, n, ts, float(step_s),
              intersample == "zoh", delay, float(kx), xref, ff, n_iq, i_lsb, i_codes, z0, zs,
              temps, cur)

    # --- sensors --------------------------------------------------------------------------
    cols, rotor, rail = _sensors(zs, cur, temps, p, mags, theta0, hum_phase, t, n_press,
                                 n_strain, n_temp)
    p_lsb, s_lsb, enc_q = _steps()

    header = {"source": f"eha-hil identify-synth --realism rig (seed {seed})"}
    if header_intersample:
        header["intersample"] = intersample
    label = "+".join(mags) or "null"
    data = MeasuredData(path=f"<rig {load} {label} seed {seed}>", load=load,
                        sample_rate_hz=fs, t=t, columns=cols, header=header)

    # --- truth ----------------------------------------------------------------------------
    force = zs[:, Z_TAUS] + zs[:, Z_TAUM]
    r_visc = np.exp(-p[I_VISC] * (temps - t_ref))
    f_cyl = force - p[I_DC] * r_visc * zs[:, Z_VC]
    f_rod = {"fixed_piston": f_cyl, "free_piston": np.zeros(n),
             "conrod_fixed": p[I_KROD] * zs[:, Z_XC] + p[I_CROD] * zs[:, Z_VC]}[load]
    params = {k: truep[k] for k in ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc",
                                    "k_rod", "c_rod", "precharge_pa")}
    params["ks"] = float(p[I_KS])
    params["reference_c"] = t_ref
    rec = RigRecord(zs, temps, p, cols, setup, delay, p_lsb, hum_phase)
    eff_truth: dict[str, dict[str, float]] = {}
    for name, mag in mags.items():
        eff_truth.update(RIG_REGISTRY[name].truth(mag, rec))
    truth = {
        "parameters": params,
        "effects": eff_truth,
        "temperature": {"shape": temperature, "start_c": float(temps[0]),
                        "end_c": float(temps[-1]), "mean_c": float(np.mean(temps)),
                        "reference_c": t_ref},
    }
    noise_rms = math.sqrt((current_noise_lsb * i_lsb) ** 2 + i_lsb ** 2 / 12.0)
    config = {
        "load": load, "profile": profile, "seconds": seconds, "seed": seed,
        "sample_rate_hz": fs,
        "preset": preset if isinstance(preset, str) else " + ".join(cfg.sources),
        "spread": spread,
        "integrator": f"classical RK4, step <= {step_s:g} s, split at the input's kinks",
        "intersample": intersample,
        "current_noise_lsb": current_noise_lsb, "current_lsb_a": i_lsb,
        "current_error_rms_a": noise_rms if intersample == "continuous" else 0.0,
        "current_loop_hz": CURRENT_LOOP_HZ, "position_loop_a_per_m": kx,
        "sweep_m": exc.sweep_m, "sweep_hz": exc.sweep_hz,
        "excitation": exc.description, "excitation_rms_a": float(math.sqrt(0.5 * np.sum(la * la))),
        "temperature": temperature, "temperature_law": TEMPERATURE_SHAPES[temperature],
        "sensors": dict(SENSORS), "pressure_lsb_pa": p_lsb, "strain_lsb_n": s_lsb,
        "encoder_lsb_rad": enc_q, "pressure_rail_fraction": rail,
        "friction_law": "F (2/pi) atan(v/eps); seal level F_c + (F_s - F_c) exp(-(v/v_s)^2)",
        "effects": {k: dict(v) for k, v in mags.items()},
        "initial_rotor_angle_rad": theta0,
        "x_range_m": (float(zs[:, Z_XC].min()), float(zs[:, Z_XC].max())),
        # no end stops are modelled: a record that reaches them is not physical
        "beyond_stroke": bool(np.abs(zs[:, Z_XC]).max() > half),
    }
    signals = {
        "iq_true": cur[:, 0].copy(), "iq_applied": cur[:, 1].copy(),
        "v_p": zs[:, Z_VP].copy(), "tau_q": force, "x_c": zs[:, Z_XC].copy(),
        "v_c": zs[:, Z_VC].copy(), "theta_p": zs[:, Z_THP].copy(), "theta_rotor": rotor,
        "t_oil": temps,
        "p_pump_a_true": p[I_P0] + np.maximum(force, 0.0) / kc,
        "p_pump_b_true": p[I_P0] + np.maximum(-force, 0.0) / kc,
        "p_cyl_a_true": p[I_P0] + np.maximum(f_cyl, 0.0) / kc,
        "p_cyl_b_true": p[I_P0] + np.maximum(-f_cyl, 0.0) / kc,
        "f_rod_true": f_rod,
    }
    return RigResult(data, truth, config, signals)


__all__ = ["INTERSAMPLE", "LIBRARY_EFFECTS", "OUTSIDE_EFFECTS", "PROFILES",
           "RIG_DEFAULT_MAGNITUDES", "RIG_EFFECTS", "RigResult", "SENSORS",
           "TEMPERATURE_SHAPES", "draw_parameters", "generate_rig", "rig_multisine"]
