"""The thesis's linear EHA (Eq. 2.28-2.31, every effect off), written out for reading.

Piston-equivalent coordinates, SI units. States: pump position and velocity (theta_p,
v_p), pressure force tau_q = k_c p, piston position and velocity (x_c, v_c); input: the
pump force tau_p (the motor's torque seen from the piston) and an external force on a free
piston.

    J_p dv_p/dt = tau_p - d_p v_p - tau_q                      pump
    d tau_q/dt  = k_s (v_p - tau_q / d_s - v_c)                leakage d_s, elasticity k_s
    J_c dv_c/dt = tau_q - d_c v_c + f_ext                      piston (free; held: v_c = 0)

A piston held through a rod path instead (``load.kind = "conrod"``: the testbed's beam,
guide, bearings and rod to a fixed end, thesis 5.4) has the rod's spring and damper on it:
``f_ext = -k_rod (x_c - x_anchor) - c_rod v_c``, in series with k_s for the pressure.

This is the same model the compiled kernel (:mod:`plant.kernel`, :mod:`plant.blocks`)
integrates when every effect is off and the pump force is given (``DriveMode.FORCE``);
``tests/plant/test_reference.py`` holds the two equal. :class:`EntrainedAir` writes out the
one effect that changes k_s itself with the state (``effects.entrained_air``), which the
derivatives take through their ``ks`` argument (``tests/plant/test_entrained_air.py``).
:meth:`LinearEha.state_space` gives the matrices, e.g. for the analytic transfer functions
d_s k_s / G1(s) of F1.
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
    k_rod: float = 0.0     # N/m, rod path to a fixed end (0: none)
    c_rod: float = 0.0     # N/(m/s), its damping
    x_anchor: float = 0.0  # m, piston position at which the rod path is unloaded

    @classmethod
    def from_config(cls, cfg: Config) -> LinearEha:
        """Table 2.1's parameters; the rod path's when ``load.kind`` is "conrod"."""
        h = cfg.section("hydraulics")
        rod = {}
        if cfg.get("load.kind") == "conrod":
            rod = {"k_rod": cfg.get("load.conrod_stiffness_n_per_m"),
                   "c_rod": cfg.get("load.conrod_damping_ns_per_m"),
                   "x_anchor": cfg.get("load.x0_m")}
        return cls(jp=h["jp_kg"], jc=h["jc_kg"], dp=h["dp_ns_per_m"], dc=h["dc_ns_per_m"],
                   ds=h["ds_ns_per_m"], ks=h["ks_n_per_m"], **rod)

    def derivatives(self, state: np.ndarray, tau_p: float, f_ext: float = 0.0,
                    piston_free: bool = True, ks: float | None = None) -> np.ndarray:
        """d/dt of ``state`` (in :data:`STATES` order); ``ks``: the series stiffness at
        this state when an effect sets it (:class:`EntrainedAir`), else the constant."""
        _theta_p, v_p, tau_q, x_c, v_c = state
        if not piston_free:
            v_c = 0.0
        if ks is None:
            ks = self.ks
        f_rod = self.k_rod * (x_c - self.x_anchor) + self.c_rod * v_c
        dv_p = (tau_p - self.dp * v_p - tau_q) / self.jp
        dtau_q = ks * (v_p - tau_q / self.ds - v_c)
        dv_c = (tau_q - self.dc * v_c - f_rod + f_ext) / self.jc if piston_free else 0.0
        return np.array([v_p, dv_p, dtau_q, v_c, dv_c])

    def state_space(self, piston_free: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) of dx/dt = A x + B [tau_p, f_ext] in :data:`STATES` order (x_c counted
        from the rod path's anchor when there is one)."""
        a = np.zeros((5, 5))
        b = np.zeros((5, 2))
        a[0, 1] = 1.0
        a[1, 1], a[1, 2] = -self.dp / self.jp, -1.0 / self.jp
        b[1, 0] = 1.0 / self.jp
        a[2, 1], a[2, 2] = self.ks, -self.ks / self.ds
        if piston_free:
            a[2, 4] = -self.ks
            a[3, 4] = 1.0
            a[4, 2], a[4, 4] = 1.0 / self.jc, -(self.dc + self.c_rod) / self.jc
            a[4, 3] = -self.k_rod / self.jc
            b[4, 1] = 1.0 / self.jc
        return a, b


#: Atmospheric pressure, Pa.
ATMOSPHERE_PA = 101325.0


@dataclass(frozen=True)
class EntrainedAir:
    """Undissolved air in the oil: the series stiffness k_s at a piston position and a
    pressure force (Eq. 2.25-2.27 with each side's fluid softened by its air).

    Side i holds oil of volume V_i and, at atmospheric pressure, air of alpha V_i. At the
    side's absolute pressure p_i the air (isothermal) has the volume alpha V_i p_atm / p_i,
    so its compliance is alpha V_i p_atm / p_i^2 beside the oil's V_i / kappa:

        k_i = k_c^2 / (V_i / kappa + alpha V_i p_atm / p_i^2)

    The check valves hold the low side at the accumulator's precharge, the high side is
    above it by tau_q / k_c. The two sides add (Eq. 2.27), and the pipe is in series
    (Eq. 2.25). Without ``ks_position`` the sides are the constant average's fluid part,
    half each.
    """

    fraction: float        # alpha, air by volume at atmospheric pressure
    bulk_modulus: float    # kappa, Pa
    kc: float              # m^2
    side_volume0: float    # dead + pipe volume per side, m^3
    half_stroke: float     # m
    ks_pipe: float         # N/m
    ks_avg: float          # N/m
    precharge: float       # gauge, Pa
    ks_position: bool

    @classmethod
    def from_config(cls, cfg: Config) -> EntrainedAir:
        h = cfg.section("hydraulics")
        return cls(cfg.get("effects.entrained_air.volume_fraction"), h["bulk_modulus_pa"],
                   h["kc_m2"], h["dead_volume_m3"] + h["pipe_volume_m3"], h["stroke_m"] / 2,
                   h["ks_pipe_n_per_m"], h["ks_n_per_m"], h["precharge_pa"],
                   cfg.get("effects.ks_position.enabled"))

    def side_pressures(self, tau_q: float) -> tuple[float, float]:
        """Absolute pressures of side 1 and side 2, Pa."""
        low = self.precharge + ATMOSPHERE_PA
        dp = tau_q / self.kc
        return low + max(dp, 0.0), low + max(-dp, 0.0)

    def side_softening(self, pressure: float) -> float:
        """(oil + air compliance) / oil compliance of a side at absolute ``pressure``."""
        return 1.0 + self.fraction * self.bulk_modulus * ATMOSPHERE_PA / pressure ** 2

    def stiffness(self, x_c: float, tau_q: float) -> float:
        """k_s in N/m at piston position ``x_c`` and pressure force ``tau_q``."""
        p1, p2 = self.side_pressures(tau_q)
        if self.ks_position:
            v1 = self.side_volume0 + self.kc * (self.half_stroke + x_c)
            v2 = self.side_volume0 + self.kc * (self.half_stroke - x_c)
            gain = self.bulk_modulus * self.kc ** 2
            k_fluid = gain / (v1 * self.side_softening(p1)) + gain / (v2 * self.side_softening(p2))
        else:
            k_side = 0.5 / (1.0 / self.ks_avg - 1.0 / self.ks_pipe)
            k_fluid = k_side / self.side_softening(p1) + k_side / self.side_softening(p2)
        return 1.0 / (1.0 / k_fluid + 1.0 / self.ks_pipe)
