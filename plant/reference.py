"""The thesis's linear EHA (Eq. 2.28-2.31, every effect off), written out for reading.

Piston-equivalent coordinates, SI units. States: pump position and velocity (theta_p,
v_p), pressure force tau_q = k_c p, piston position and velocity (x_c, v_c); input: the
pump force tau_p (the motor's torque seen from the piston) and an external force on a free
piston.

    J_p dv_p/dt = tau_p - d_p v_p - tau_q                      pump
    d tau_q/dt  = k_s (v_p - tau_q / d_s - v_c)                leakage d_s, elasticity k_s
    J_c dv_c/dt = tau_q - d_c v_c + f_ext                      piston (free; held: v_c = 0)

This is the same model the compiled kernel (:mod:`plant.kernel`, :mod:`plant.blocks`)
integrates when every effect is off and the pump force is given (``DriveMode.FORCE``);
``tests/plant/test_reference.py`` holds the two equal. :meth:`LinearEha.state_space` gives
the matrices, e.g. for the analytic transfer functions d_s k_s / G1(s) of F1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plant.config import Config

#: State order of :meth:`LinearEha.derivatives` and :meth:`LinearEha.state_space`.
STATES = ("theta_p", "v_p", "tau_q", "x_c", "v_c")


@dataclass(frozen=True)
class LinearEha:
    """Thesis Table 2.1's parameters, piston-equivalent."""

    jp: float   # kg, pump + rotor inertia
    jc: float   # kg, piston + beam
    dp: float   # N/(m/s), pump friction
    dc: float   # N/(m/s), piston-side friction
    ds: float   # N/(m/s), internal-leakage series damper
    ks: float   # N/m, series elasticity (its average)

    @classmethod
    def from_config(cls, cfg: Config) -> LinearEha:
        h = cfg.section("hydraulics")
        return cls(jp=h["jp_kg"], jc=h["jc_kg"], dp=h["dp_ns_per_m"], dc=h["dc_ns_per_m"],
                   ds=h["ds_ns_per_m"], ks=h["ks_n_per_m"])

    def derivatives(self, state: np.ndarray, tau_p: float, f_ext: float = 0.0,
                    piston_free: bool = True) -> np.ndarray:
        """d/dt of ``state`` (in :data:`STATES` order)."""
        _theta_p, v_p, tau_q, _x_c, v_c = state
        if not piston_free:
            v_c = 0.0
        dv_p = (tau_p - self.dp * v_p - tau_q) / self.jp
        dtau_q = self.ks * (v_p - tau_q / self.ds - v_c)
        dv_c = (tau_q - self.dc * v_c + f_ext) / self.jc if piston_free else 0.0
        return np.array([v_p, dv_p, dtau_q, v_c, dv_c])

    def state_space(self, piston_free: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) of dx/dt = A x + B [tau_p, f_ext] in :data:`STATES` order."""
        a = np.zeros((5, 5))
        b = np.zeros((5, 2))
        a[0, 1] = 1.0
        a[1, 1], a[1, 2] = -self.dp / self.jp, -1.0 / self.jp
        b[1, 0] = 1.0 / self.jp
        a[2, 1], a[2, 2] = self.ks, -self.ks / self.ds
        if piston_free:
            a[2, 4] = -self.ks
            a[3, 4] = 1.0
            a[4, 2], a[4, 4] = 1.0 / self.jc, -self.dc / self.jc
            b[4, 1] = 1.0 / self.jc
        return a, b
