"""The compiled per-tick path of the EHA plant (numba).

Model (thesis Eq. 2.28-2.31, piston-equivalent coordinates), with the effects of
``effects.*`` switched by flags in the parameter array:

    J_p dv_p/dt = tau_p - d_p v_p - F_cp(v_p) - g(theta) tau_q       pump
    d tau_q/dt  = k_s(x) (g(theta) v_p - tau_q / d_s - v_c)          leakage + elasticity
    J_c dv_c/dt = tau_q - d_c v_c - F_seal(v_c) - f_rod + f_ext      piston

``tau_q`` (= k_c p, N) is a state, so Eq. 2.29-2.30 become one rate equation; with a
constant k_s this is exactly the thesis's model. ``g = 1 + a sin(N theta_rotor + phi)`` is
the trochoid's displacement ripple; it scales flow and reaction torque alike, so the pump
still converts power losslessly. ``d_p, d_s, d_c`` scale with oil viscosity mu(T).

The blocks that make up the right-hand side (motor, inverter, pump, hydraulics, load,
thermal) are in :mod:`plant.blocks`, each with its equations; :func:`derivatives` sums them.
:mod:`plant.reference` writes the linear model out readably, and a test holds the two equal.
The sensors' noise and resolution are not physics: :mod:`plant.sensors.readings`.

Integration: classic RK4 over ``n_sub`` equal sub-steps per tick, inputs held (the PWM
average is constant over a carrier period). ``plant.model`` picks ``n_sub`` from the
stiffest mode so that h * omega stays below 0.5.

Everything here works on flat float64 arrays addressed by :mod:`plant.layout` constants:
no allocation per tick, no string lookups, no Python objects. The per-tick functions are
compiled with :data:`plant.blocks.TICK` (no reference counting: see there).
"""

from __future__ import annotations

from numba import njit

from plant.blocks import TICK

# series_stiffness: read as kernel.series_stiffness by plant.model and hil.identify.
from plant.blocks.hydraulics import line_stiffness, pressure_force, series_stiffness  # noqa: F401
from plant.blocks.load import end_stops, piston_and_load, rod_force
from plant.blocks.motor_dq import drive, phase_angles
from plant.blocks.pump import pump, ripple_and_friction
from plant.blocks.thermal import energy_and_heat, viscosity_ratio
from plant.layout import (
    IN_ID_REF,
    IN_IQ_REF,
    IN_MODE,
    IN_TAU_REF,
    LOAD_CART,
    LOAD_CONROD,
    LOAD_FIXED,
    N_STATES,
    P_DC,
    P_DP,
    P_DRIFT_K,
    P_DRIFT_ON,
    P_DS,
    P_H_SUB,
    P_JC,
    P_JP,
    P_K_ROD,
    P_KC,
    P_KC_OVER_KP,
    P_KT_EQ,
    P_L,
    P_LOAD_KIND,
    P_M_CART,
    P_N_SUB,
    P_NUMERICS,
    P_POLE_PAIRS,
    P_PRECHARGE,
    P_T_REF,
    P_X_ANCHOR,
    S_EDISS,
    S_EEXT,
    S_EIN,
    S_ID,
    S_IQ,
    S_THC,
    S_THP,
    S_TOIL,
    S_TQ,
    S_TROD,
    S_VC,
    S_VL,
    S_VP,
    S_XL,
    Y_E_DISS,
    Y_E_EXT,
    Y_E_IN,
    Y_E_STORED,
    Y_F_ROD,
    Y_F_STRAIN,
    Y_IA,
    Y_IB,
    Y_IC,
    Y_ID,
    Y_IQ,
    Y_OMEGA_M,
    Y_P_ACC,
    Y_P_CYL_A,
    Y_P_CYL_B,
    Y_P_PUMP_A,
    Y_P_PUMP_B,
    Y_T_OIL,
    Y_T_ROD,
    Y_TAU_P,
    Y_TAU_Q,
    Y_TEMP,
    Y_THETA_M,
    Y_V_PISTON,
    Y_VP,
    Y_X_CART,
    Y_X_PISTON,
    DriveMode,
)
from plant.sensors.readings import sense


@njit(**TICK)
def derivatives(x, p, u, dx):
    """Write dx/dt of every integrated state into ``dx`` (see :mod:`plant.layout`): the
    blocks of :mod:`plant.blocks`, motor and inverter, pump, hydraulics, piston and load,
    heat and energy."""
    r = viscosity_ratio(p, x[S_TOIL])
    dp = p[P_DP] * r
    ds = p[P_DS] * r
    dc = p[P_DC] * r
    vp = x[S_VP]
    vc = x[S_VC]
    tq = x[S_TQ]
    kc_kp = p[P_KC_OVER_KP]
    theta_rotor = x[S_THP] * kc_kp
    mode = int(u[IN_MODE])
    tau_p, p_elec, p_copper = drive(x, p, u, dx, mode, theta_rotor, vp, kc_kp)
    g, f_cp = ripple_and_friction(p, vp, theta_rotor, tq)
    pump(p, dx, tau_p, vp, dp, f_cp, g, tq)
    pressure_force(x, p, dx, g, vp, ds, vc, tq)
    f_seal, loss_load, p_ext = piston_and_load(x, p, u, dx, tq, vc, dc)
    heat_oil = dp * vp * vp + f_cp * vp + tq * tq / ds + dc * vc * vc + f_seal * vc
    energy_and_heat(x, p, u, dx, mode, heat_oil, tau_p, vp, p_elec, p_copper, loss_load,
                    p_ext)


@njit(**TICK)
def rk4_tick(x, p, u, work):
    """Advance the states ``x`` by one tick: ``n_sub`` RK4 sub-steps of ``h_sub`` s."""
    h = p[P_H_SUB]
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    xt = work[4]
    n_sub = int(p[P_N_SUB])
    fixed = p[P_LOAD_KIND] == LOAD_FIXED
    for _ in range(n_sub):
        derivatives(x, p, u, k1)
        for i in range(N_STATES):
            xt[i] = x[i] + 0.5 * h * k1[i]
        derivatives(xt, p, u, k2)
        for i in range(N_STATES):
            xt[i] = x[i] + 0.5 * h * k2[i]
        derivatives(xt, p, u, k3)
        for i in range(N_STATES):
            xt[i] = x[i] + h * k3[i]
        derivatives(xt, p, u, k4)
        for i in range(N_STATES):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        if not fixed:
            end_stops(p, x)


@njit(**TICK)
def stored_energy(x, p, u):
    """Kinetic + elastic + magnetic energy held by the plant, J."""
    e = 0.5 * p[P_JP] * x[S_VP] ** 2 + 0.5 * p[P_JC] * x[S_VC] ** 2
    e += x[S_TQ] ** 2 / (2.0 * line_stiffness(p, x[S_THC], x[S_TQ]))
    kind = p[P_LOAD_KIND]
    if kind == LOAD_CONROD:
        e += 0.5 * p[P_K_ROD] * (x[S_THC] - p[P_X_ANCHOR]) ** 2
    elif kind == LOAD_CART:
        e += 0.5 * p[P_K_ROD] * (x[S_THC] - x[S_XL]) ** 2 + 0.5 * p[P_M_CART] * x[S_VL] ** 2
    if int(u[IN_MODE]) == DriveMode.DUTY:
        e += 0.75 * p[P_L] * (x[S_ID] ** 2 + x[S_IQ] ** 2)
    return e


@njit(**TICK)
def outputs(x, p, u, rng, y):
    """Fill the output row ``y``: the physical values, then what the sensors read of them
    (:func:`plant.sensors.readings.sense`: noise and converter resolution, when those
    effects are on)."""
    physical_outputs(x, p, u, y)
    sense(p, rng, y)


@njit(cache=True, inline="always")
def physical_outputs(x, p, u, y):
    """The output row's physical values (truth; no noise, no quantisation)."""
    kc = p[P_KC]
    kc_kp = p[P_KC_OVER_KP]
    r = viscosity_ratio(p, x[S_TOIL])
    mode = int(u[IN_MODE])
    if mode == DriveMode.CURRENT:
        i_q = u[IN_IQ_REF]
        i_d = u[IN_ID_REF]
        tau_p = p[P_KT_EQ] * i_q
    elif mode == DriveMode.FORCE:
        tau_p = u[IN_TAU_REF]
        i_q = tau_p / p[P_KT_EQ]
        i_d = 0.0
    else:
        i_q = x[S_IQ]
        i_d = x[S_ID]
        tau_p = p[P_KT_EQ] * i_q
    theta_rotor = x[S_THP] * kc_kp
    th = p[P_POLE_PAIRS] * theta_rotor
    c, s, c2, s2 = phase_angles(th, p[P_NUMERICS])
    i_a = i_d * c - i_q * s
    i_b = i_d * c2 - i_q * s2

    tq = x[S_TQ]
    vc = x[S_VC]
    f_cyl = tq - p[P_DC] * r * vc  # k_c * cylinder differential pressure
    kind = p[P_LOAD_KIND]
    if kind == LOAD_FIXED:
        f_rod = f_cyl
    else:
        f_rod = rod_force(p, x)

    pre = p[P_PRECHARGE]
    dp_pump = tq / kc
    dp_cyl = f_cyl / kc
    # Check valves keep the low side at the accumulator precharge.
    y[Y_P_ACC] = pre
    y[Y_P_PUMP_A] = pre + (dp_pump if dp_pump > 0.0 else 0.0)
    y[Y_P_PUMP_B] = pre + (-dp_pump if dp_pump < 0.0 else 0.0)
    y[Y_P_CYL_A] = pre + (dp_cyl if dp_cyl > 0.0 else 0.0)
    y[Y_P_CYL_B] = pre + (-dp_cyl if dp_cyl < 0.0 else 0.0)
    f_strain = f_rod
    if p[P_DRIFT_ON] > 0.5:
        f_strain += p[P_DRIFT_K] * (x[S_TROD] - p[P_T_REF])
    y[Y_F_STRAIN] = f_strain
    y[Y_TEMP] = x[S_TOIL]
    y[Y_THETA_M] = theta_rotor
    y[Y_OMEGA_M] = x[S_VP] * kc_kp
    y[Y_X_PISTON] = x[S_THC]
    y[Y_V_PISTON] = vc
    y[Y_TAU_P] = tau_p
    y[Y_TAU_Q] = tq
    y[Y_F_ROD] = f_rod
    y[Y_IQ] = i_q
    y[Y_ID] = i_d
    y[Y_IA] = i_a
    y[Y_IB] = i_b
    y[Y_IC] = -i_a - i_b
    y[Y_VP] = x[S_VP]
    y[Y_T_OIL] = x[S_TOIL]
    y[Y_T_ROD] = x[S_TROD]
    y[Y_X_CART] = x[S_XL]
    y[Y_E_IN] = x[S_EIN]
    y[Y_E_DISS] = x[S_EDISS]
    y[Y_E_EXT] = x[S_EEXT]
    y[Y_E_STORED] = stored_energy(x, p, u)


@njit(cache=True, inline="always")
def gates_off(x):
    """Enter DriveMode.OFF: the phase currents are zero from here on."""
    x[S_ID] = 0.0
    x[S_IQ] = 0.0


@njit(**TICK)
def advance(x, p, u, n_ticks, y, rec, row0, every, tick0, rng, work):
    """Advance ``n_ticks`` ticks with inputs ``u`` held; return the next free record row.

    After each tick the output row ``y`` is refreshed; when ``rec`` has rows, ticks whose
    index (``tick0`` + k + 1, the tick just reached) is a multiple of ``every`` are copied
    into ``rec[row]`` for row = ``row0``, ``row0 + 1``, ...
    """
    if int(u[IN_MODE]) == DriveMode.CURRENT:
        x[S_IQ] = u[IN_IQ_REF]
        x[S_ID] = u[IN_ID_REF]
    elif int(u[IN_MODE]) == DriveMode.OFF:
        gates_off(x)
    row = row0
    n_rows = rec.shape[0]
    n_out = y.shape[0]
    for k in range(n_ticks):
        rk4_tick(x, p, u, work)
        outputs(x, p, u, rng, y)
        if n_rows > 0 and (tick0 + k + 1) % every == 0 and row < n_rows:
            for j in range(n_out):
                rec[row, j] = y[j]
            row += 1
    return row
