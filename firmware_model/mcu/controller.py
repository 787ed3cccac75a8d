"""The actuator controller the MCU runs at 5 kHz, in float32.

Force feedback ``f_fb`` (N, piston force) is, by ``mcu.force_feedback``:
* "pressure": f_pres = k_c (p_cyl_a - p_cyl_b);
* "strain": strain-gauge feedback for rod-seal friction compensation (thesis 4.4). The loop
  stays closed on the collocated, stiff pressure force f_pres, and a piston-side friction
  observer adds the force the seal takes, F^_seal = LP(f_pres - f_strain), to the pressure
  force reference: tau_ref' = tau_ref + F^_seal (first-order LP, cutoff
  ``seal_observer_hz``). Closing the PD directly on f_strain instead only divides the seal
  friction by 1 + K_p (F7, against the observer at 10 Hz: 5.9 N against 4.4 N). Integral
  action on the strain error (tau_ref - f_strain), which would also remove the pressure
  loop's own tracking error, destabilises the low-gain position loop of F7 even at
  0.5 Hz: low-passed, it feeds the pump's inertial force back as negative damping on the
  ~2.5 Hz mode the 10 N/mm loop makes with the reflected pump inertia. ``f_strain`` =
  cos(alpha) * strain-gauge force (Eq. 6.5);
* "complementary": f_fil = f_pres + HP(f_strain - f_pres) (Eq. 4.4), a first-order
  high-pass with cutoff ``complementary_cutoff_hz``.

Current-based controller (Fig. 5.2, ``controller = "current"``), pump force command tau_p:

    tau_p = tau_ref + K_p (tau_ref - f_fb) - K_d d/dt f_fb - r
    i_q,ref = tau_p / K_t,eq,   v_q,ff = omega_m K_t / 1.5   (back-EMF of the dq model)

The derivative acts on the measurement (no kick on command steps) through a first-order
filter. ``r`` is a momentum-based observer of the pump side's disturbance (friction,
displacement ripple): with P = J_p v_p, r = K_o (P - P_0 - sum (tau_p,meas - tau_q + r) dt),
where tau_p,meas = K_t,eq i_q (measured) and tau_q = k_c (p_pump_a - p_pump_b); subtracting
it cancels what the model J_p dv_p/dt = tau_p - tau_q leaves out.

Velocity-based controller (Fig. 5.1, ``controller = "velocity"``): a PI force loop gives a
pump velocity reference, a PI velocity loop gives tau_p; the pump's friction and inertia are
handled by the velocity loop, not by the force loop.

Commands: force (tau_ref, N) or position (tau_ref = K_pos (x_ref - x), the low-gain local
position loop of thesis 4.4). Limits: |tau_ref| <= min(force limit, k_c * pressure limit),
|i_q,ref| <= current limit. All state and arithmetic are ``numpy.float32``.
"""

from __future__ import annotations

import math

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.mcu.filters import (
    DerivativeFilter,
    HighPassFilter,
    LowPassFilter,
    MomentumObserver,
    PIController,
)
from firmware_model.mcu.measure import Measurements

F32 = np.float32
ZERO = F32(0.0)

FEEDBACKS = ("pressure", "strain", "complementary")
LIMIT_FORCE = 1
LIMIT_CURRENT = 2
LIMIT_PRESSURE = 4
V_FF_MAX = F32(32.767)


def _clamp(x: np.float32, lim: np.float32) -> np.float32:
    if x > lim:
        return lim
    if x < -lim:
        return -lim
    return x


class ActuatorController:
    """One actuator's force/pressure controller (float32 state)."""

    def __init__(self, cal: FirmwareCalibration) -> None:
        cal = calibration(cal)
        m = cal.mcu
        kc = cal.kc_m2
        dt = m["period_ticks"] * cal.tick_ns * 1e-9
        kt = cal.kt_nm_per_a
        self.dt = F32(dt)
        #: The period as the calibration gives it [s] (float64): a tunable's coefficient
        #: (:mod:`firmware_model.mcu.tunables`) is computed from it as at construction.
        self.dt_s = dt
        self.velocity_based = m["controller"] == "velocity"
        self.feedback = m["force_feedback"]
        self.kt_eq = F32(cal.kt_eq_n_per_a)
        self.kp = F32(m["kp_force"])
        self.kd = F32(m["kd_force_s"])
        self.derivative = DerivativeFilter(m["derivative_filter_hz"], dt)
        self.observer = MomentumObserver(cal.jp_kg, m["friction_observer_hz"], dt)
        self.bemf = F32(kt / 1.5) if m["backemf_ff"] else ZERO
        self.velocity_pi = PIController(m["vel_kp_n_per_m_s"], m["vel_ki_n_per_m"], dt)
        self.force_pi = PIController(m["vel_force_kp_m_s_per_n"], m["vel_force_ki_m_per_n"],
                                     dt)
        self.highpass = HighPassFilter(m["complementary_cutoff_hz"], dt)  # Eq. 4.4
        self.seal_observer = LowPassFilter(m["seal_observer_hz"], dt)
        self.k_pos = F32(m["position_kp_n_per_m"])
        length, offset = m["conrod_length_m"], m["conrod_offset_m"]
        self.cos_alpha = F32(math.sqrt(1.0 - (offset / length) ** 2) if length > 0 else 1.0)
        self.kc = kc
        self.force_limit, self.pressure_limit = m["force_limit_n"], m["pressure_limit_pa"]
        self.f_lim = F32(min(m["force_limit_n"], kc * m["pressure_limit_pa"]))
        self.p_lim = F32(m["pressure_limit_pa"])
        self.i_lim = F32(m["current_limit_a"])
        self.reset()

    def reset(self) -> None:
        """Zero every state (at enable)."""
        for block in (self.derivative, self.observer, self.velocity_pi, self.force_pi,
                      self.highpass, self.seal_observer):
            block.reset()
        self.f_strain = ZERO
        self.i_limited = False
        self.tau_p = ZERO
        self.tau_used = ZERO
        self.f_fb = ZERO
        self.f_fil = ZERO
        self.limits = 0

    def strain_force(self, m: Measurements) -> np.float32:
        """The piston-axis force the strain gauge reads: its raw force times cos(alpha) of
        the rod's angle, N."""
        return self.cos_alpha * m.f_strain_raw

    def feedback_force(self, m: Measurements) -> np.float32:
        """Update the complementary filter; return the force the loop is closed on, N."""
        if m.strain_samples == 0:
            # No AD7195 conversion read yet: its register still says code 0 (-3000 N).
            self.f_fil = m.f_pres
            return m.f_pres
        f_strain = self.strain_force(m)
        self.f_fil = m.f_pres + self.highpass(f_strain - m.f_pres)
        if self.feedback == "pressure":
            return m.f_pres
        self.f_strain = f_strain
        return self.f_fil if self.feedback == "complementary" else m.f_pres

    def step(self, m: Measurements, tau_ref: np.float32) -> tuple[np.float32, np.float32]:
        """One 5 kHz step: (i_q reference in A, v_q feed-forward in V)."""
        self.limits = 0
        lim = self.f_lim
        if tau_ref > lim or tau_ref < -lim:
            tau_ref = _clamp(tau_ref, lim)
            self.limits |= LIMIT_FORCE
        self.tau_used = tau_ref
        if (m.p_cyl_a > self.p_lim or m.p_cyl_b > self.p_lim or m.p_pump_a > self.p_lim
                or m.p_pump_b > self.p_lim):
            self.limits |= LIMIT_PRESSURE
        f = self.feedback_force(m)
        self.f_fb = f
        if self.feedback == "strain" and m.strain_samples:
            # Piston-side friction observer (F^_seal, see the module docstring), held while
            # the current is limited (its estimate is then not what the loop applied).
            if not self.i_limited:
                self.seal_observer(m.f_pres - self.f_strain)
        seal = self.seal_observer.y
        e = tau_ref + seal - f
        if self.velocity_based:
            tau_p = self.velocity_pi(self.force_pi(e) - m.v_pump)
        else:
            d = self.derivative(f)
            tau_p = tau_ref + seal + self.kp * e - self.kd * d - self.observer.r
        i_ref = tau_p / self.kt_eq
        saturated = i_ref > self.i_lim or i_ref < -self.i_lim
        self.i_limited = saturated
        if saturated:
            i_ref = _clamp(i_ref, self.i_lim)
            self.limits |= LIMIT_CURRENT
        if self.velocity_based:
            # Integrate only while the current is not limited (no wind-up).
            if not saturated:
                self.force_pi.integrate(e)
                self.velocity_pi.integrate(self.force_pi(e) - m.v_pump)
        else:
            self.observer(m.v_pump, self.kt_eq * m.iq, m.tau_q)
        self.tau_p = i_ref * self.kt_eq
        # The board's register holds +/-32.767 V; clamp rather than let the word wrap.
        return i_ref, _clamp(self.bemf * m.omega_m, V_FF_MAX)
