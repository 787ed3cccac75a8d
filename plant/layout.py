"""Index layout of the flat arrays the compiled plant kernel works on.

The per-tick path must not look anything up by string, so parameters, states, inputs and
outputs live in float64 arrays addressed by these module constants (numba freezes them at
compile time). The name tuples give the same layout to people, logs and plots.
"""

from __future__ import annotations

from enum import IntEnum

# --- parameters (P_*), filled once by plant.model.build_params --------------------------
PARAM_NAMES = (
    "jp", "jc", "dp", "dc", "ds", "ks_avg", "ks_fluid_gain", "side_volume0", "kc",
    "ks_pipe", "half_stroke", "kc_over_kp", "precharge",
    "kt_eq", "pole_pairs", "resistance", "inductance", "flux_linkage",
    "vdc", "dead_frac", "duty_min", "duty_max", "dead_current",
    "load_kind", "k_rod", "c_rod", "m_cart", "c_cart", "x_anchor",
    "puls_on", "puls_order", "puls_amp", "puls_phase", "puls_torque", "puls_torque_rel",
    "pc_on", "pc_force", "pc_eps",
    "sf_on", "sf_coulomb", "sf_static", "sf_vs", "sf_eps",
    "ksx_on",
    "temp_on", "t_ref", "visc_coeff", "heat_cap", "cool_g",
    "drift_on", "drift_k", "rod_tau",
    "noise_on", "noise_p", "noise_f", "noise_t",
    "quant_on", "q_motor", "q_piston", "q_pressure", "q_strain", "q_temp",
    "h_sub", "n_sub", "numerics",
    "air_on", "air_a",
)
(P_JP, P_JC, P_DP, P_DC, P_DS, P_KS_AVG, P_KS_FLUID_GAIN, P_SIDE_V0, P_KC,
 P_KS_PIPE, P_HALF_STROKE, P_KC_OVER_KP, P_PRECHARGE,
 P_KT_EQ, P_POLE_PAIRS, P_R, P_L, P_FLUX,
 P_VDC, P_DEAD_FRAC, P_DUTY_MIN, P_DUTY_MAX, P_DEAD_CURRENT,
 P_LOAD_KIND, P_K_ROD, P_C_ROD, P_M_CART, P_C_CART, P_X_ANCHOR,
 P_PULS_ON, P_PULS_ORDER, P_PULS_AMP, P_PULS_PHASE, P_PULS_TORQUE, P_PULS_TORQUE_REL,
 P_PC_ON, P_PC_FORCE, P_PC_EPS,
 P_SF_ON, P_SF_COULOMB, P_SF_STATIC, P_SF_VS, P_SF_EPS,
 P_KSX_ON,
 P_TEMP_ON, P_T_REF, P_VISC_COEFF, P_HEAT_CAP, P_COOL_G,
 P_DRIFT_ON, P_DRIFT_K, P_ROD_TAU,
 P_NOISE_ON, P_NOISE_P, P_NOISE_F, P_NOISE_T,
 P_QUANT_ON, P_Q_MOTOR, P_Q_PISTON, P_Q_PRESSURE, P_Q_STRAIN, P_Q_TEMP,
 P_H_SUB, P_N_SUB, P_NUMERICS,
 P_AIR_ON, P_AIR_A) = range(len(PARAM_NAMES))
N_PARAMS = len(PARAM_NAMES)

# Load kinds, as stored in P_LOAD_KIND.
LOAD_FIXED, LOAD_FREE, LOAD_CONROD, LOAD_CART = 0, 1, 2, 3
LOAD_KINDS = ("fixed", "free", "conrod", "cart")

# --- integrated states (S_*), SI units --------------------------------------------------
STATE_NAMES = (
    "theta_p_m",      # pump position seen from the piston, m
    "v_p_m_s",        # pump velocity seen from the piston, m/s
    "tau_q_n",        # pressure force k_c * p (pump side), N
    "theta_c_m",      # piston position about mid-stroke, m
    "v_c_m_s",        # piston velocity, m/s
    "x_cart_m",       # cart position (cart load), m
    "v_cart_m_s",     # cart velocity, m/s
    "i_d_a",          # d-axis current, A
    "i_q_a",          # q-axis current, A
    "t_oil_c",        # oil temperature, degC
    "t_rod_c",        # connecting-rod (strain gauge) temperature, degC
    "e_in_j",         # energy in: electrical at the terminals (duty mode) or tau_p work, J
    "e_diss_j",       # energy dissipated, J
    "e_ext_j",        # work done on the load by the external force, J
)
(S_THP, S_VP, S_TQ, S_THC, S_VC, S_XL, S_VL, S_ID, S_IQ, S_TOIL, S_TROD,
 S_EIN, S_EDISS, S_EEXT) = range(len(STATE_NAMES))
N_STATES = len(STATE_NAMES)

# --- inputs (IN_*), held over a tick ------------------------------------------------------
# (IN_, not U_: U_* are the driver board's upstream registers in firmware_model.fpga.layout.)


class DriveMode(IntEnum):
    """How the plant's motor is driven this tick (input ``IN_MODE``); numba compiles the
    members to constants."""

    DUTY = 0      # phase duty cycles from the driver board, average-value inverter
    CURRENT = 1   # ideal current source: i_q, i_d follow their references exactly
    FORCE = 2     # ideal pump force tau_p, no motor
    #: All six gates open (driver board tripped or disabled). The winding current then
    #: flows back to the bus through the free-wheeling diodes against about V_dc, so it
    #: dies within L i / V_dc (40 uH * 18 A / 48 V = 15 us), inside one 50 us tick: the
    #: model sets it to zero at once. Not modelled: the diode-rectifier regime, where a
    #: back-EMF above V_dc (line-line) drives current into the bus; at 48 V that needs
    #: > 0.35 m/s of piston speed.
    OFF = 3


INPUT_NAMES = (
    "mode",           # a DriveMode, stored as float
    "duty_a", "duty_b", "duty_c",  # phase duty cycles 0..1 (DriveMode.DUTY)
    "iq_ref_a", "id_ref_a",        # ideal currents (DriveMode.CURRENT)
    "tau_p_ref_n",    # ideal pump force, piston-equivalent N (DriveMode.FORCE)
    "f_ext_n",        # external force on the load body (free piston or cart), +x, N
    "t_amb_c",        # ambient / coolant temperature, degC
)
(IN_MODE, IN_DA, IN_DB, IN_DC, IN_IQ_REF, IN_ID_REF, IN_TAU_REF, IN_F_EXT, IN_T_AMB) = range(
    len(INPUT_NAMES))
N_INPUTS = len(INPUT_NAMES)

# --- outputs (Y_*), one row per tick --------------------------------------------------------
OUTPUT_NAMES = (
    # sensors at the physical level (with noise/quantisation when those effects are on)
    "theta_m",        # motor angle, rad, unwrapped
    "omega_m",        # motor speed, rad/s
    "x_piston",       # piston position, m
    "p_acc", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b",  # gauge pressures, Pa
    "f_strain",       # connecting-rod force from the strain gauge, N
    "temp_c",         # oil temperature sensor, degC
    # truth, for analysis and for the driver-board model's current sensing
    "v_piston",       # m/s
    "tau_p",          # motor force seen from the piston, N
    "tau_q",          # pump-side pressure force k_c p, N
    "f_rod",          # true connecting-rod / load force, N
    "i_q", "i_d",     # A
    "i_a", "i_b", "i_c",  # phase currents, A
    "v_p",            # pump velocity seen from the piston, m/s
    "t_oil",          # degC
    "x_cart",         # m
    "e_in", "e_diss", "e_ext", "e_stored",  # J
    "t_rod",          # connecting-rod (strain gauge) temperature, degC
)
(Y_THETA_M, Y_OMEGA_M, Y_X_PISTON, Y_P_ACC, Y_P_PUMP_A, Y_P_PUMP_B, Y_P_CYL_A, Y_P_CYL_B,
 Y_F_STRAIN, Y_TEMP, Y_V_PISTON, Y_TAU_P, Y_TAU_Q, Y_F_ROD, Y_IQ, Y_ID, Y_IA, Y_IB, Y_IC,
 Y_VP, Y_T_OIL, Y_X_CART, Y_E_IN, Y_E_DISS, Y_E_EXT, Y_E_STORED, Y_T_ROD) = range(
    len(OUTPUT_NAMES))
N_OUTPUTS = len(OUTPUT_NAMES)
