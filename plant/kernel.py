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

The motor is a surface-magnet machine in the dq frame (amplitude-invariant transform):

    L di_d/dt = v_d - R i_d + w_e L i_q
    L di_q/dt = v_q - R i_q - w_e L i_d - w_e psi
    torque    = 1.5 p psi i_q                       (motor Nm; times k_c/k_p -> piston N)

fed by an average-value inverter: leg voltage (d - 1/2) V_dc less the dead-time error
sign(i) t_dead f_pwm V_dc. In ``DriveMode.CURRENT`` the currents follow their references exactly;
in ``DriveMode.FORCE`` tau_p is given directly; in ``DriveMode.OFF`` the gates are open and the
currents are zero.

Integration: classic RK4 over ``n_sub`` equal sub-steps per tick, inputs held (the PWM
average is constant over a carrier period). ``plant.model`` picks ``n_sub`` from the
stiffest mode so that h * omega stays below 0.5.

Everything here works on flat float64 arrays addressed by :mod:`plant.layout` constants:
no allocation per tick, no string lookups, no Python objects.
"""

from __future__ import annotations

import math

from numba import njit

from plant.layout import (
    IN_DA,
    IN_DB,
    IN_DC,
    IN_F_EXT,
    IN_ID_REF,
    IN_IQ_REF,
    IN_MODE,
    IN_T_AMB,
    IN_TAU_REF,
    LOAD_CART,
    LOAD_CONROD,
    LOAD_FIXED,
    LOAD_FREE,
    N_STATES,
    P_C_CART,
    P_C_ROD,
    P_COOL_G,
    P_DC,
    P_DEAD_CURRENT,
    P_DEAD_FRAC,
    P_DP,
    P_DRIFT_K,
    P_DRIFT_ON,
    P_DS,
    P_DUTY_MAX,
    P_DUTY_MIN,
    P_FLUX,
    P_H_SUB,
    P_HALF_STROKE,
    P_HEAT_CAP,
    P_JC,
    P_JP,
    P_K_ROD,
    P_KC,
    P_KC_OVER_KP,
    P_KS_AVG,
    P_KS_FLUID_GAIN,
    P_KS_PIPE,
    P_KSX_ON,
    P_KT_EQ,
    P_L,
    P_LOAD_KIND,
    P_M_CART,
    P_N_SUB,
    P_PC_EPS,
    P_PC_FORCE,
    P_PC_ON,
    P_POLE_PAIRS,
    P_PRECHARGE,
    P_PULS_AMP,
    P_PULS_ON,
    P_PULS_ORDER,
    P_PULS_PHASE,
    P_PULS_TORQUE,
    P_PULS_TORQUE_REL,
    P_R,
    P_ROD_TAU,
    P_SF_COULOMB,
    P_SF_EPS,
    P_SF_ON,
    P_SF_STATIC,
    P_SF_VS,
    P_SIDE_V0,
    P_T_REF,
    P_TEMP_ON,
    P_VDC,
    P_VISC_COEFF,
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

TWO_PI_3 = 2.0 * math.pi / 3.0
SQRT3 = math.sqrt(3.0)


@njit(cache=True, inline="always")
def viscosity_ratio(p, t_oil):
    """mu(T)/mu(T_ref): 1 when the oil-temperature effect is off."""
    if p[P_TEMP_ON] > 0.5:
        return math.exp(-p[P_VISC_COEFF] * (t_oil - p[P_T_REF]))
    return 1.0


@njit(cache=True, inline="always")
def series_stiffness(p, x_c):
    """k_s in N/m: Eq. 2.25-2.27 at piston position x_c when ks_position is on."""
    if p[P_KSX_ON] > 0.5:
        kc = p[P_KC]
        v1 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] + x_c)
        v2 = p[P_SIDE_V0] + kc * (p[P_HALF_STROKE] - x_c)
        k_fluid = p[P_KS_FLUID_GAIN] * (1.0 / v1 + 1.0 / v2)
        return k_fluid * p[P_KS_PIPE] / (k_fluid + p[P_KS_PIPE])
    return p[P_KS_AVG]


@njit(cache=True, inline="always")
def seal_friction(p, v):
    """Rod-seal friction force in N opposing v: Coulomb + Stribeck, tanh-regularised."""
    if p[P_SF_ON] > 0.5:
        vs = v / p[P_SF_VS]
        level = p[P_SF_COULOMB] + (p[P_SF_STATIC] - p[P_SF_COULOMB]) * math.exp(-vs * vs)
        return level * math.tanh(v / p[P_SF_EPS])
    return 0.0


@njit(cache=True, inline="always")
def _rod_force(p, x):
    """Force the rod (or the fixing) takes from the piston, N; compression positive."""
    kind = p[P_LOAD_KIND]
    if kind == LOAD_CONROD:
        return p[P_K_ROD] * (x[S_THC] - p[P_X_ANCHOR]) + p[P_C_ROD] * x[S_VC]
    if kind == LOAD_CART:
        return p[P_K_ROD] * (x[S_THC] - x[S_XL]) + p[P_C_ROD] * (x[S_VC] - x[S_VL])
    return 0.0


@njit(cache=True, inline="always")
def _dead_time_error(p, i):
    """Leg-voltage error in V from dead time: -sign(i) t_d f_pwm V_dc, faded near i = 0."""
    s = i / p[P_DEAD_CURRENT]
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    return -s * p[P_DEAD_FRAC] * p[P_VDC]


@njit(cache=True, inline="always")
def _clamp_duty(p, d):
    if d < p[P_DUTY_MIN]:
        return p[P_DUTY_MIN]
    if d > p[P_DUTY_MAX]:
        return p[P_DUTY_MAX]
    return d


@njit(cache=True)
def derivatives(x, p, u, dx):
    """Write dx/dt of every integrated state into ``dx`` (see :mod:`plant.layout`)."""
    r = viscosity_ratio(p, x[S_TOIL])
    dp = p[P_DP] * r
    ds = p[P_DS] * r
    dc = p[P_DC] * r
    vp = x[S_VP]
    vc = x[S_VC]
    tq = x[S_TQ]
    kc_kp = p[P_KC_OVER_KP]
    pole_pairs = p[P_POLE_PAIRS]
    theta_rotor = x[S_THP] * kc_kp

    # --- motor and inverter ---
    mode = int(u[IN_MODE])
    p_elec = 0.0
    p_copper = 0.0
    if mode == DriveMode.DUTY:
        i_d = x[S_ID]
        i_q = x[S_IQ]
        th = pole_pairs * theta_rotor
        c = math.cos(th)
        s = math.sin(th)
        c2 = math.cos(th - TWO_PI_3)
        s2 = math.sin(th - TWO_PI_3)
        i_a = i_d * c - i_q * s
        i_b = i_d * c2 - i_q * s2
        i_c = -i_a - i_b
        vdc = p[P_VDC]
        v_a = (_clamp_duty(p, u[IN_DA]) - 0.5) * vdc + _dead_time_error(p, i_a)
        v_b = (_clamp_duty(p, u[IN_DB]) - 0.5) * vdc + _dead_time_error(p, i_b)
        v_c = (_clamp_duty(p, u[IN_DC]) - 0.5) * vdc + _dead_time_error(p, i_c)
        # Clarke (amplitude invariant); the common-mode voltage of a star winding drops out.
        v_alpha = (2.0 * v_a - v_b - v_c) / 3.0
        v_beta = (v_b - v_c) / SQRT3
        v_d = v_alpha * c + v_beta * s
        v_q = -v_alpha * s + v_beta * c
        w_e = pole_pairs * vp * kc_kp
        res = p[P_R]
        ind = p[P_L]
        dx[S_ID] = (v_d - res * i_d + w_e * ind * i_q) / ind
        dx[S_IQ] = (v_q - res * i_q - w_e * ind * i_d - w_e * p[P_FLUX]) / ind
        p_elec = 1.5 * (v_d * i_d + v_q * i_q)
        p_copper = 1.5 * res * (i_d * i_d + i_q * i_q)
        tau_p = p[P_KT_EQ] * i_q
    elif mode == DriveMode.CURRENT:
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = p[P_KT_EQ] * u[IN_IQ_REF]
    elif mode == DriveMode.OFF:
        # Gates off: the winding current has already decayed through the diodes (see
        # DriveMode.OFF in plant.layout), so there is no torque.
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = 0.0
    else:
        dx[S_ID] = 0.0
        dx[S_IQ] = 0.0
        tau_p = u[IN_TAU_REF]

    # --- pump ---
    g = 1.0
    f_cp = 0.0
    if p[P_PC_ON] > 0.5:
        f_cp = p[P_PC_FORCE] * math.tanh(vp / p[P_PC_EPS])
    if p[P_PULS_ON] > 0.5:
        ripple = math.sin(p[P_PULS_ORDER] * theta_rotor + p[P_PULS_PHASE])
        g = 1.0 + p[P_PULS_AMP] * ripple
        # Meshing torque ripple: a load torque that depends on where the teeth mesh, a
        # constant part and one proportional to the pressure force the pump works against
        # (chamber pressures at the port edges, trapped volumes, tooth contact forces all
        # scale with the pressure). It stays in f_cp, so its work is booked with the pump
        # losses (zero on average).
        f_cp += (p[P_PULS_TORQUE] + p[P_PULS_TORQUE_REL] * tq) * ripple
    dx[S_THP] = vp
    dx[S_VP] = (tau_p - dp * vp - f_cp - g * tq) / p[P_JP]

    # --- leakage damper and series elasticity ---
    ks = series_stiffness(p, x[S_THC])
    dx[S_TQ] = ks * (g * vp - tq / ds - vc)

    # --- piston and load ---
    kind = p[P_LOAD_KIND]
    f_seal = seal_friction(p, vc)
    f_ext = u[IN_F_EXT]
    loss_load = 0.0
    p_ext = 0.0
    if kind == LOAD_FIXED:
        dx[S_THC] = 0.0
        dx[S_VC] = 0.0
        dx[S_XL] = 0.0
        dx[S_VL] = 0.0
    else:
        f_rod = _rod_force(p, x)
        dx[S_THC] = vc
        dx[S_VC] = (tq - dc * vc - f_seal - f_rod + (f_ext if kind == LOAD_FREE else 0.0)) / p[
            P_JC
        ]
        if kind == LOAD_CART:
            vl = x[S_VL]
            dx[S_XL] = vl
            dx[S_VL] = (f_rod + f_ext - p[P_C_CART] * vl) / p[P_M_CART]
            rel = vc - vl
            loss_load = p[P_C_ROD] * rel * rel + p[P_C_CART] * vl * vl
            p_ext = f_ext * vl
        else:
            dx[S_XL] = 0.0
            dx[S_VL] = 0.0
            if kind == LOAD_CONROD:
                loss_load = p[P_C_ROD] * vc * vc
            elif kind == LOAD_FREE:
                p_ext = f_ext * vc

    # --- energy and heat ---
    heat_oil = dp * vp * vp + f_cp * vp + tq * tq / ds + dc * vc * vc + f_seal * vc
    if mode == DriveMode.DUTY:
        dx[S_EIN] = p_elec
    else:
        dx[S_EIN] = tau_p * vp
    dx[S_EDISS] = heat_oil + loss_load + p_copper
    dx[S_EEXT] = p_ext
    t_amb = u[IN_T_AMB]
    if p[P_TEMP_ON] > 0.5:
        dx[S_TOIL] = (heat_oil - p[P_COOL_G] * (x[S_TOIL] - t_amb)) / p[P_HEAT_CAP]
    else:
        dx[S_TOIL] = 0.0
    dx[S_TROD] = (t_amb - x[S_TROD]) / p[P_ROD_TAU]


@njit(cache=True)
def _end_stops(p, x):
    """Inelastic end stops at +/- stroke/2: hold the piston, drop its outward velocity."""
    half = p[P_HALF_STROKE]
    v = x[S_VC]
    if (x[S_THC] > half and v > 0.0) or (x[S_THC] < -half and v < 0.0):
        # The impact's kinetic energy is lost; book it so the energy balance still closes.
        x[S_EDISS] += 0.5 * p[P_JC] * v * v
        x[S_VC] = 0.0
    if x[S_THC] > half:
        x[S_THC] = half
    elif x[S_THC] < -half:
        x[S_THC] = -half


@njit(cache=True)
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
            _end_stops(p, x)


@njit(cache=True)
def stored_energy(x, p, u):
    """Kinetic + elastic + magnetic energy held by the plant, J."""
    e = 0.5 * p[P_JP] * x[S_VP] ** 2 + 0.5 * p[P_JC] * x[S_VC] ** 2
    e += x[S_TQ] ** 2 / (2.0 * series_stiffness(p, x[S_THC]))
    kind = p[P_LOAD_KIND]
    if kind == LOAD_CONROD:
        e += 0.5 * p[P_K_ROD] * (x[S_THC] - p[P_X_ANCHOR]) ** 2
    elif kind == LOAD_CART:
        e += 0.5 * p[P_K_ROD] * (x[S_THC] - x[S_XL]) ** 2 + 0.5 * p[P_M_CART] * x[S_VL] ** 2
    if int(u[IN_MODE]) == DriveMode.DUTY:
        e += 0.75 * p[P_L] * (x[S_ID] ** 2 + x[S_IQ] ** 2)
    return e


@njit(cache=True)
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
    i_a = i_d * math.cos(th) - i_q * math.sin(th)
    i_b = i_d * math.cos(th - TWO_PI_3) - i_q * math.sin(th - TWO_PI_3)

    tq = x[S_TQ]
    vc = x[S_VC]
    f_cyl = tq - p[P_DC] * r * vc  # k_c * cylinder differential pressure
    kind = p[P_LOAD_KIND]
    if kind == LOAD_FIXED:
        f_rod = f_cyl
    else:
        f_rod = _rod_force(p, x)

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


@njit(cache=True)
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
