"""The EHA plant as an object: builds the kernel's arrays from a configuration and steps it.

>>> from plant.config import load_config
>>> plant = Plant(load_config("hydra_linear"))
>>> plant.set_current(18.0)
>>> _ = plant.advance(2000)    # 0.1 s at 50 us ticks
>>> round(plant.y[L.Y_TAU_Q])    # pressure force at stall, N
1761
"""

from __future__ import annotations

import math

import numpy as np

from plant import kernel
from plant import layout as L
from plant.blocks.hydraulics import P_ATM_PA
from plant.config import Config

# Stability margins for the RK4 sub-step h: h*omega for oscillatory modes and h*rate for
# real (damping) modes. RK4 is stable to about 2.8 on both axes; these keep it accurate.
_OSC_MARGIN = 0.5
_REAL_MARGIN = 1.5


def motor_torque_constant(cfg: Config) -> float:
    """K_t in Nm/A, from 18 A q-axis <-> 2150 N piston force and the pump ratio k_p/k_c."""
    kp = cfg.get("hydraulics.kp_m3_per_rad")
    kc = cfg.get("hydraulics.kc_m2")
    return cfg.get("motor.force_at_rated_n") * (kp / kc) / cfg.get("motor.iq_rated_a")


def stiffness_range(cfg: Config) -> tuple[float, float]:
    """(min, max) of k_s(x) over the stroke by Eq. 2.25-2.27, N/m."""
    p = build_params(cfg, substeps=1)
    xs = np.linspace(-p[L.P_HALF_STROKE], p[L.P_HALF_STROKE], 201)
    p[L.P_KSX_ON] = 1.0
    ks = [kernel.series_stiffness(p, float(x)) for x in xs]
    return min(ks), max(ks)


def _flag(section: dict) -> float:
    return 1.0 if section["enabled"] else 0.0


def choose_substeps(p: np.ndarray, tick_s: float) -> int:
    """RK4 sub-steps per tick so that the stiffest mode stays inside the accuracy margins."""
    kc = p[L.P_KC]
    v0 = p[L.P_SIDE_V0]
    ks_max = p[L.P_KS_AVG]
    if p[L.P_KSX_ON] > 0.5:
        k_end = p[L.P_KS_FLUID_GAIN] * (1.0 / v0 + 1.0 / (v0 + 2 * kc * p[L.P_HALF_STROKE]))
        ks_max = max(ks_max, k_end * p[L.P_KS_PIPE] / (k_end + p[L.P_KS_PIPE]))
    # Viscous terms get larger when the oil is cold; allow 40 degC below reference.
    cold = math.exp(p[L.P_VISC_COEFF] * 40.0) if p[L.P_TEMP_ON] > 0.5 else 1.0
    omega = math.sqrt(ks_max / p[L.P_JP])
    # The dead-time error fading over +/- dead_current acts like a resistor at low current.
    r_dead = p[L.P_DEAD_FRAC] * p[L.P_VDC] / p[L.P_DEAD_CURRENT]
    rates = [
        ks_max / (p[L.P_DS] / cold),
        p[L.P_DP] * cold / p[L.P_JP],
        (p[L.P_R] + r_dead) / p[L.P_L],
    ]
    if p[L.P_LOAD_KIND] != L.LOAD_FIXED:
        k_load = p[L.P_K_ROD] if p[L.P_LOAD_KIND] in (L.LOAD_CONROD, L.LOAD_CART) else 0.0
        omega = max(omega, math.sqrt((ks_max + k_load) / p[L.P_JC]))
        rates.append(p[L.P_DC] * cold / p[L.P_JC])
        if k_load > 0.0:
            # The rod's damper on the piston: a stiff real mode once c_rod / J_c nears
            # the tick rate (a hip rod path of 2e4 N s/m is 6.8e4 1/s).
            rates.append(p[L.P_C_ROD] / p[L.P_JC])
        if p[L.P_SF_ON] > 0.5:
            rates.append(max(p[L.P_SF_STATIC], p[L.P_SF_COULOMB]) / (p[L.P_SF_EPS] * p[L.P_JC]))
    if p[L.P_PC_ON] > 0.5:
        rates.append(p[L.P_PC_FORCE] / (p[L.P_PC_EPS] * p[L.P_JP]))
    n = max(
        1,
        math.ceil(tick_s * omega / _OSC_MARGIN),
        math.ceil(tick_s * max(rates) / _REAL_MARGIN),
    )
    return int(n)


#: Most RK4 sub-steps per tick (as ``sim.substeps`` allows): beyond it a simulated second
#: takes hours. A configuration whose stiffness needs more is refused, naming the keys.
MAX_SUBSTEPS = 1000

#: Sub-steps the compiled loop runs per call of :meth:`Plant.advance` before Python gets
#: control back (a few ms): Ctrl-C is seen between two calls, also on a long advance.
CHUNK_SUBSTEPS = 100_000

def bounded_substeps(p: np.ndarray, tick_s: float, cfg: Config) -> int:
    """:func:`choose_substeps`, or ConfigError (one line) when it exceeds MAX_SUBSTEPS."""
    n = choose_substeps(p, tick_s)
    if n <= MAX_SUBSTEPS:
        return n
    from plant.config import ConfigError

    raise ConfigError(
        f"{' + '.join(cfg.sources)}: needs {n:,} RK4 sub-steps per {tick_s * 1e6:g} us tick "
        f"(at most {MAX_SUBSTEPS}): a mode far too fast for the tick (the masses, "
        "stiffnesses, dampings, inductance and friction smoothing set it); change that "
        f"value, or set sim.substeps (1..{MAX_SUBSTEPS}) to accept a coarser integration")


def check_config(cfg: Config) -> None:
    """ConfigError (one line) if ``cfg`` cannot be simulated in bounded work (see
    :func:`bounded_substeps`): for commands that build their plants later, in workers."""
    build_params(cfg)


def build_params(cfg: Config, substeps: int | None = None) -> np.ndarray:
    """Flatten a configuration into the kernel's parameter array (done once, not per tick)."""
    h = cfg.section("hydraulics")
    m = cfg.section("motor")
    inv = cfg.section("inverter")
    load = cfg.section("load")
    eff = cfg.section("effects")
    p = np.zeros(L.N_PARAMS)
    kc = h["kc_m2"]
    kp = h["kp_m3_per_rad"]
    p[L.P_JP] = h["jp_kg"]
    p[L.P_JC] = h["jc_kg"]
    p[L.P_DP] = h["dp_ns_per_m"]
    p[L.P_DC] = h["dc_ns_per_m"]
    p[L.P_DS] = h["ds_ns_per_m"]
    p[L.P_KS_AVG] = h["ks_n_per_m"]
    p[L.P_KS_FLUID_GAIN] = h["bulk_modulus_pa"] * kc * kc
    p[L.P_SIDE_V0] = h["dead_volume_m3"] + h["pipe_volume_m3"]
    p[L.P_KC] = kc
    p[L.P_KS_PIPE] = h["ks_pipe_n_per_m"]
    p[L.P_HALF_STROKE] = h["stroke_m"] / 2.0
    p[L.P_KC_OVER_KP] = kc / kp
    p[L.P_PRECHARGE] = h["precharge_pa"]

    kt = motor_torque_constant(cfg)
    p[L.P_KT_EQ] = kt * kc / kp
    p[L.P_POLE_PAIRS] = m["pole_pairs"]
    p[L.P_R] = m["resistance_ohm"]
    p[L.P_L] = m["inductance_h"]
    p[L.P_FLUX] = kt / (1.5 * m["pole_pairs"])

    p[L.P_VDC] = inv["dc_bus_v"]
    p[L.P_DEAD_FRAC] = inv["dead_time_s"] * inv["pwm_hz"]
    p[L.P_DUTY_MIN] = inv["duty_min"]
    p[L.P_DUTY_MAX] = inv["duty_max"]
    p[L.P_DEAD_CURRENT] = max(inv["dead_time_current_a"], 1e-6)

    p[L.P_LOAD_KIND] = L.LOAD_KINDS.index(load["kind"])
    p[L.P_K_ROD] = load["conrod_stiffness_n_per_m"]
    p[L.P_C_ROD] = load["conrod_damping_ns_per_m"]
    p[L.P_M_CART] = load["cart_mass_kg"]
    p[L.P_C_CART] = load["cart_damping_ns_per_m"]
    p[L.P_X_ANCHOR] = load["x0_m"]

    e = eff["pulsation"]
    p[L.P_PULS_ON] = _flag(e)
    p[L.P_PULS_ORDER] = e["order"]
    p[L.P_PULS_AMP] = e["amplitude"]
    p[L.P_PULS_PHASE] = e["phase_rad"]
    p[L.P_PULS_TORQUE] = e["torque_n"]
    p[L.P_PULS_TORQUE_REL] = e["torque_amplitude"]
    e = eff["pump_coulomb"]
    p[L.P_PC_ON] = _flag(e)
    p[L.P_PC_FORCE] = e["force_n"]
    p[L.P_PC_EPS] = e["velocity_eps_m_per_s"]
    e = eff["seal_friction"]
    p[L.P_SF_ON] = _flag(e)
    p[L.P_SF_COULOMB] = e["coulomb_n"]
    p[L.P_SF_STATIC] = e["static_n"]
    p[L.P_SF_VS] = e["stribeck_velocity_m_per_s"]
    p[L.P_SF_EPS] = e["velocity_eps_m_per_s"]
    p[L.P_KSX_ON] = _flag(eff["ks_position"])
    e = eff["entrained_air"]
    p[L.P_AIR_ON] = _flag(e)
    p[L.P_AIR_A] = e["volume_fraction"] * h["bulk_modulus_pa"] * P_ATM_PA
    e = eff["oil_temperature"]
    p[L.P_TEMP_ON] = _flag(e)
    p[L.P_T_REF] = e["reference_c"]
    p[L.P_VISC_COEFF] = e["viscosity_coeff_per_c"]
    p[L.P_HEAT_CAP] = e["heat_capacity_j_per_k"]
    p[L.P_COOL_G] = e["cooling_w_per_k"]
    e = eff["strain_drift"]
    p[L.P_DRIFT_ON] = _flag(e)
    p[L.P_DRIFT_K] = e["n_per_c"]
    p[L.P_ROD_TAU] = e["rod_time_constant_s"]
    e = eff["sensor_noise"]
    p[L.P_NOISE_ON] = _flag(e)
    p[L.P_NOISE_P] = e["pressure_pa"]
    p[L.P_NOISE_F] = e["strain_n"]
    p[L.P_NOISE_T] = e["temperature_c"]
    e = eff["quantisation"]
    p[L.P_QUANT_ON] = _flag(e)
    p[L.P_Q_MOTOR] = 2.0 * math.pi / e["motor_counts_per_rev"]
    # A zero LSB would divide by zero; treat it as "this channel is not quantised".
    p[L.P_Q_PISTON] = e["piston_lsb_m"] or 1e-300
    p[L.P_Q_PRESSURE] = e["pressure_lsb_pa"] or 1e-300
    p[L.P_Q_STRAIN] = e["strain_lsb_n"] or 1e-300
    p[L.P_Q_TEMP] = e["temperature_lsb_c"] or 1e-300

    tick_s = cfg.get("sim.tick_ns") * 1e-9
    n_sub = substeps or cfg.get("sim.substeps") or bounded_substeps(p, tick_s, cfg)
    p[L.P_N_SUB] = n_sub
    p[L.P_H_SUB] = tick_s / n_sub
    p[L.P_NUMERICS] = cfg.get("sim.plant_numerics")
    return p


def _splitmix64(seed: int) -> int:
    """Spread a small integer seed over 64 bits (never 0, which xorshift cannot leave)."""
    z = (seed + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    z ^= z >> 31
    return z or 1


class Plant:
    """Fixed-step EHA plant: motor, inverter, pump, hydraulics, cylinder, load, sensors.

    Inputs are held over each tick; ``y`` holds the outputs after the latest tick, indexed
    by :mod:`plant.layout` ``Y_*`` constants (names in ``L.OUTPUT_NAMES``).
    """

    def __init__(self, cfg: Config, substeps: int | None = None) -> None:
        self.config = cfg
        self.params = build_params(cfg, substeps)
        self.tick_ns: int = cfg.get("sim.tick_ns")
        self.tick_s = self.tick_ns * 1e-9
        self.x = np.zeros(L.N_STATES)
        x0 = cfg.get("load.x0_m")
        self.x[L.S_THC] = x0
        self.x[L.S_XL] = x0
        self.x[L.S_TOIL] = cfg.get("effects.oil_temperature.initial_c")
        ambient = cfg.get("effects.oil_temperature.ambient_c")
        self.x[L.S_TROD] = ambient
        self.u = np.zeros(L.N_INPUTS)
        self.u[L.IN_MODE] = L.DriveMode.CURRENT
        self.u[L.IN_T_AMB] = ambient
        self.y = np.zeros(L.N_OUTPUTS)
        self.rng = np.array([_splitmix64(cfg.get("sim.seed"))], dtype=np.uint64)
        self._work = np.zeros((5, L.N_STATES))
        self._no_rec = np.zeros((0, L.N_OUTPUTS))
        self.tick = 0
        kernel.outputs(self.x, self.params, self.u, self.rng, self.y)

    @property
    def substeps(self) -> int:
        """RK4 sub-steps per tick in use."""
        return int(self.params[L.P_N_SUB])

    @property
    def time_s(self) -> float:
        """Simulated time reached, s."""
        return self.tick * self.tick_s

    # --- inputs -----------------------------------------------------------------------
    def set_duty(self, duty_a: float, duty_b: float, duty_c: float) -> None:
        """Drive the inverter with phase duty cycles 0..1 (average over a PWM period)."""
        u = self.u
        u[L.IN_MODE] = L.DriveMode.DUTY
        u[L.IN_DA] = duty_a
        u[L.IN_DB] = duty_b
        u[L.IN_DC] = duty_c

    def set_current(self, iq_a: float, id_a: float = 0.0) -> None:
        """Ideal current source: the dq currents follow these values exactly, A."""
        u = self.u
        u[L.IN_MODE] = L.DriveMode.CURRENT
        u[L.IN_IQ_REF] = iq_a
        u[L.IN_ID_REF] = id_a

    def set_gates_off(self) -> None:
        """Open all inverter gates: no current, no motor torque (``DriveMode.OFF``)."""
        self.u[L.IN_MODE] = L.DriveMode.OFF

    def set_force(self, tau_p_n: float) -> None:
        """Ideal pump force input tau_p (piston-equivalent), N."""
        self.u[L.IN_MODE] = L.DriveMode.FORCE
        self.u[L.IN_TAU_REF] = tau_p_n

    def set_external_force(self, f_n: float) -> None:
        """External force on the load body (free piston or cart), +x, N."""
        self.u[L.IN_F_EXT] = f_n

    def set_ambient(self, t_c: float) -> None:
        """Ambient / coolant temperature, degC."""
        self.u[L.IN_T_AMB] = t_c

    # --- stepping -----------------------------------------------------------------------
    def advance(
        self, n_ticks: int, rec: np.ndarray | None = None, row0: int = 0, every: int = 1
    ) -> int:
        """Advance ``n_ticks`` ticks; optionally record every ``every``-th tick into ``rec``.

        Returns the next free row of ``rec``.
        """
        rows = self._no_rec if rec is None else rec
        if n_ticks * self.substeps <= CHUNK_SUBSTEPS:  # the scheduler's case: one call
            row = kernel.advance(
                self.x, self.params, self.u, n_ticks, self.y, rows, row0, every, self.tick,
                self.rng, self._work,
            )
            self.tick += n_ticks
            return row
        # in chunks of CHUNK_SUBSTEPS: Ctrl-C is seen within a few ms (recording goes by
        # the absolute tick, so the chunks give the same rows and bits as one call)
        chunk = max(1, CHUNK_SUBSTEPS // self.substeps)
        row = row0
        done = 0
        while done < n_ticks:
            n = min(chunk, n_ticks - done)
            row = kernel.advance(
                self.x, self.params, self.u, n, self.y, rows, row, every, self.tick,
                self.rng, self._work,
            )
            self.tick += n
            done += n
        return row

    def output(self, name: str) -> float:
        """Latest value of an output by name (convenience; not for per-tick use)."""
        return float(self.y[L.OUTPUT_NAMES.index(name)])


__all__ = ["MAX_SUBSTEPS", "Plant", "bounded_substeps", "build_params", "check_config",
           "choose_substeps", "motor_torque_constant"]
