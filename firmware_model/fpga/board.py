"""The driver board's per-tick logic, compiled: sensors in, protections, enable state
machine, FOC current loop, PWM compare counts and the upstream memory out.

One tick of :func:`control_tick` is one 50 us PWM period. Inputs are the raw words the
sensor masters delivered (``raw``, see :data:`layout.RAW_NAMES`) and the downstream memory
(``down``) as the LVDS endpoint last stored it; outputs are the compare counts in the state
array and the refreshed upstream memory (``up``). All arrays are int64 holding values of the
declared widths; :class:`DriverBoard` wraps them for Python callers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.fixed import clamp, mul_shift, sat_s, sat_u, wrap_s, wrap_u
from firmware_model.fpga.foc import (
    V_LIMIT_Q15,
    clarke,
    inv_park,
    park,
    pi_step,
    q_limit,
    sin_cos,
    svpwm,
)
from firmware_model.fpga.layout import (
    C_ADC_MID,
    C_ADC_SHIFT,
    C_I_TO_MA,
    C_KI_SHIFT,
    C_KP_SHIFT,
    C_MA_TO_I,
    C_MV_TO_V,
    C_POLE_PAIRS,
    C_PWM_TOP,
    C_SPEED_WINDOW,
    C_SSI_SHIFT,
    C_V_LIMIT,
    C_V_TO_MV,
    C_WD_TICKS,
    CTRL_CLEAR_FAULT,
    CTRL_ENABLE,
    D_ANGLE_OFFSET,
    D_CONTROL,
    D_CURRENT_LIMIT,
    D_ID_REF,
    D_IQ_REF,
    D_KI,
    D_KP,
    D_MODE,
    D_SEQUENCE,
    D_TRIP_CURRENT,
    D_VD_REF,
    D_VQ_FF,
    D_VQ_REF,
    DOWN_WORDS,
    F_DUTY_A,
    F_DUTY_B,
    F_DUTY_C,
    F_ERR_BISS,
    F_ERR_LINK_CRC,
    F_ERR_SSI,
    F_ERR_STRAIN,
    F_ID,
    F_INTEG_D,
    F_INTEG_Q,
    F_IQ,
    F_LATCHED,
    F_OC_TRIPS,
    F_PREV_CONTROL,
    F_PWM_ON,
    F_RING_POS,
    F_SINCE_VALID,
    F_STATE,
    F_STATUS_EXTRA,
    F_STRAIN_SAMPLES,
    F_THETA_E,
    F_TICK,
    F_VD,
    F_VQ,
    F_WD_TRIPS,
    MODE_CURRENT,
    MODE_VOLTAGE,
    R_ABI,
    R_BISS,
    R_BISS_OK,
    R_HALL,
    R_IA,
    R_IB,
    R_P_ACC,
    R_SSI,
    R_SSI_OK,
    R_STRAIN,
    R_STRAIN_NEW,
    R_STRAIN_OK,
    R_TEMP,
    RING_BASE,
    ST_ENABLE_REFUSED,
    ST_ENABLED,
    ST_ENCODER_ERROR,
    ST_FAULT,
    ST_LINK_LOST,
    ST_LINK_OK,
    ST_OVER_CURRENT,
    ST_STRAIN_ERROR,
    STATE_DISABLED,
    STATE_ENABLED,
    STATE_FAULT,
    U_ABI,
    U_ERR_BISS,
    U_ERR_LINK_CRC,
    U_ERR_SSI,
    U_ERR_STRAIN,
    U_HALL,
    U_IA,
    U_IB,
    U_ID,
    U_IQ,
    U_OC_TRIPS,
    U_P_ACC,
    U_PISTON_HI,
    U_PISTON_LO,
    U_SEQ_ECHO,
    U_SPEED,
    U_SSI,
    U_STATE,
    U_STATUS,
    U_STRAIN_HI,
    U_TEMPERATURE,
    U_THETA_E,
    U_TICK,
    U_VD_OUT,
    U_VQ_OUT,
    U_WD_TRIPS,
)

#: Fixed shifts of the PI gain multipliers (the registers hold the multipliers).
KP_SHIFT = 12
KI_SHIFT = 16
#: Bits of the current ADC.
CURRENT_ADC_BITS = 12


def _k15(x: float) -> int:
    """A constant factor as a multiplier for ``mul_shift(.., k, 15)``."""
    return round(x * (1 << 15))


def board_params(cal: FirmwareCalibration) -> np.ndarray:
    """The constant parameter array of the board (``layout.C_*``) from its calibration."""
    cal = calibration(cal)
    f = cal.fpga
    c = np.zeros(B.N_PARAMS, dtype=np.int64)
    c[C_POLE_PAIRS] = cal.pole_pairs
    c[C_SSI_SHIFT] = 16 - cal.ssi_bits
    c[C_ADC_MID] = 1 << (CURRENT_ADC_BITS - 1)
    c[C_ADC_SHIFT] = 16 - CURRENT_ADC_BITS
    c[C_PWM_TOP] = pwm_top(cal)
    c[C_V_LIMIT] = V_LIMIT_Q15
    c[C_KP_SHIFT] = KP_SHIFT
    c[C_KI_SHIFT] = KI_SHIFT
    i_lsb_ma = 1000.0 * f["current_full_scale_a"] / 32768.0      # mA per s16 current LSB
    v_lsb_mv = 1000.0 * cal.dc_bus_v / 32768.0    # mV per s16 voltage LSB
    c[C_MA_TO_I] = _k15(1.0 / i_lsb_ma)
    c[C_I_TO_MA] = _k15(i_lsb_ma)
    c[C_MV_TO_V] = _k15(1.0 / v_lsb_mv)
    c[C_V_TO_MV] = _k15(v_lsb_mv)
    c[C_WD_TICKS] = max(1, round(f["watchdog_s"] / (cal.tick_ns * 1e-9)))
    c[C_SPEED_WINDOW] = f["speed_window_ticks"]
    return c


def pwm_top(cal: FirmwareCalibration) -> int:
    """Compare counts of half a carrier period: f_clk / (2 f_pwm) (centre-aligned)."""
    cal = calibration(cal)
    top = cal.fpga["clock_hz"] / (2.0 * cal.pwm_hz)
    return int(round(top))


def gain_registers(cal: FirmwareCalibration) -> tuple[int, int]:
    """(kp, ki) register values for the configured PI gains in V/A and V/(A s).

    In the s16 units the PI sees (current LSB I_FS/2^15, voltage LSB V_dc/2^15):
    kp_reg = Kp (I_FS/V_dc) 2^12, ki_reg = Ki T_s (I_FS/V_dc) 2^16, each saturated to u16.
    """
    cal = calibration(cal)
    f = cal.fpga
    ratio = f["current_full_scale_a"] / cal.dc_bus_v
    ts = cal.tick_ns * 1e-9
    kp = round(f["current_kp_v_per_a"] * ratio * (1 << KP_SHIFT))
    ki = round(f["current_ki_v_per_a_s"] * ts * ratio * (1 << KI_SHIFT))
    return min(kp, 0xFFFF), min(ki, 0xFFFF)


def calibrated_offset(cal: FirmwareCalibration) -> int:
    """The angle_offset register value that aligns the SSI with the rotor's d axis.

    What the PC's calibration table holds: -p * (SSI zero's mounting angle), 2^16 per
    electrical turn, rounded. The encoder reads count = (theta_m + mount) N / 2 pi.
    """
    cal = calibration(cal)
    pp = cal.pole_pairs
    mount = cal.ssi_mount_rad
    return round(-pp * mount * 65536.0 / (2.0 * math.pi)) & 0xFFFF


def down_defaults(cal: FirmwareCalibration) -> np.ndarray:
    """Reset contents of the downstream memory: limits and gains from the configuration,
    everything else zero (disabled, mode off, offset not yet calibrated)."""
    cal = calibration(cal)
    d = np.zeros(B.DOWN_WORDS, dtype=np.int64)
    d[D_CURRENT_LIMIT] = min(0xFFFF, round(cal.fpga["current_limit_a"] * 1000.0))
    d[D_TRIP_CURRENT] = min(0xFFFF, round(cal.fpga["trip_current_a"] * 1000.0))
    d[D_KP], d[D_KI] = gain_registers(cal)
    return d


@njit(cache=True)
def receive_word(st, down, addr, data, crc_ok):
    """LVDS endpoint, downstream side: store one received word or discard it.

    A word that failed its CRC is counted and dropped; a good word is stored at its
    address (addresses beyond the memory are ignored) and restarts the link watchdog.
    """
    if not crc_ok:
        st[F_ERR_LINK_CRC] = sat_u(st[F_ERR_LINK_CRC] + 1, 16)
        return
    if 0 <= addr < DOWN_WORDS:
        down[addr] = data & 0xFFFF
    st[F_SINCE_VALID] = 0


@njit(cache=True, inline="always")
def _count(st, k):
    st[k] = sat_u(st[k] + 1, 16)


@njit(cache=True, inline="always")
def _u16(x):
    return x & 0xFFFF


@njit(cache=True)
def control_tick(c, st, down, up, raw):
    """One 50 us tick of the board: see the module docstring. Returns the PWM-on flag."""
    tick = st[F_TICK]
    extra = 0

    # --- motor angle: SSI absolute angle, pole pairs and the calibrated offset ----------
    if raw[R_SSI_OK] != 0:
        theta_e = wrap_u(((raw[R_SSI] * c[C_POLE_PAIRS]) << c[C_SSI_SHIFT])
                         + down[D_ANGLE_OFFSET], 16)
        st[F_THETA_E] = theta_e
    else:
        theta_e = st[F_THETA_E]  # hold the last good angle
        _count(st, F_ERR_SSI)
        extra |= ST_ENCODER_ERROR
    if raw[R_BISS_OK] == 0:
        _count(st, F_ERR_BISS)
        extra |= ST_ENCODER_ERROR

    # --- speed: ABI count difference over a window of ticks (M method) -------------------
    window = c[C_SPEED_WINDOW]
    abi = wrap_u(raw[R_ABI], 16)
    if tick == 0:
        for k in range(window):
            st[RING_BASE + k] = abi
    pos = st[F_RING_POS]
    speed = wrap_s(abi - st[RING_BASE + pos], 16)
    st[RING_BASE + pos] = abi
    st[F_RING_POS] = (pos + 1) & (window - 1)

    # --- phase currents: 12-bit offset-binary codes -> s16 Q1.15 of I_FS ------------------
    i_a = (raw[R_IA] - c[C_ADC_MID]) << c[C_ADC_SHIFT]
    i_b = (raw[R_IB] - c[C_ADC_MID]) << c[C_ADC_SHIFT]
    i_c = -i_a - i_b
    i_alpha, i_beta = clarke(i_a, i_b)
    s, co = sin_cos(theta_e)
    i_d, i_q = park(i_alpha, i_beta, s, co)
    st[F_ID] = i_d
    st[F_IQ] = i_q

    # --- protections ----------------------------------------------------------------------
    trip = mul_shift(down[D_TRIP_CURRENT], c[C_MA_TO_I], 15)
    over_current = abs(i_a) >= trip or abs(i_b) >= trip or abs(i_c) >= trip
    link_ok = st[F_SINCE_VALID] < c[C_WD_TICKS]
    state = st[F_STATE]
    latched = st[F_LATCHED]
    if over_current and (latched & ST_OVER_CURRENT) == 0:
        latched |= ST_OVER_CURRENT
        _count(st, F_OC_TRIPS)
    if state == STATE_ENABLED and not link_ok and (latched & ST_LINK_LOST) == 0:
        latched |= ST_LINK_LOST
        _count(st, F_WD_TRIPS)
    if link_ok:
        extra |= ST_LINK_OK

    # --- enable state machine -------------------------------------------------------------
    control = down[D_CONTROL]
    mode = down[D_MODE]
    enable = (control & CTRL_ENABLE) != 0 and (mode == MODE_CURRENT or mode == MODE_VOLTAGE)
    clear = (control & CTRL_CLEAR_FAULT) != 0 and (st[F_PREV_CONTROL] & CTRL_CLEAR_FAULT) == 0
    st[F_PREV_CONTROL] = control
    if state == STATE_ENABLED:
        if latched != 0:
            state = STATE_FAULT
        elif not enable:
            state = STATE_DISABLED
    elif state == STATE_FAULT:
        if clear and not enable and not over_current and link_ok:
            latched = 0
            state = STATE_DISABLED
    else:
        if clear and not over_current:
            latched = 0
        if enable:
            if latched != 0 or over_current or not link_ok or (extra & ST_ENCODER_ERROR) != 0:
                extra |= ST_ENABLE_REFUSED
            else:
                state = STATE_ENABLED
                st[F_INTEG_D] = 0
                st[F_INTEG_Q] = 0
    st[F_STATE] = state
    st[F_LATCHED] = latched

    # --- current loop and modulation ------------------------------------------------------
    top = c[C_PWM_TOP]
    v_lim = c[C_V_LIMIT]
    if state == STATE_ENABLED:
        if mode == MODE_CURRENT:
            i_lim = min(mul_shift(down[D_CURRENT_LIMIT], c[C_MA_TO_I], 15), 32767)
            iq_ref = clamp(mul_shift(wrap_s(down[D_IQ_REF], 16), c[C_MA_TO_I], 15), -i_lim, i_lim)
            id_ref = clamp(mul_shift(wrap_s(down[D_ID_REF], 16), c[C_MA_TO_I], 15), -i_lim, i_lim)
            ff = sat_s(mul_shift(wrap_s(down[D_VQ_FF], 16), c[C_MV_TO_V], 15), 16)
            kp = down[D_KP]
            ki = down[D_KI]
            v_d, integ = pi_step(id_ref - i_d, st[F_INTEG_D], kp, c[C_KP_SHIFT], ki,
                                 c[C_KI_SHIFT], 0, v_lim)
            st[F_INTEG_D] = integ
            v_q, integ = pi_step(iq_ref - i_q, st[F_INTEG_Q], kp, c[C_KP_SHIFT], ki,
                                 c[C_KI_SHIFT], ff, q_limit(v_d, v_lim))
            st[F_INTEG_Q] = integ
        else:
            v_d = clamp(mul_shift(wrap_s(down[D_VD_REF], 16), c[C_MV_TO_V], 15), -v_lim, v_lim)
            q_lim = q_limit(v_d, v_lim)
            v_q = clamp(mul_shift(wrap_s(down[D_VQ_REF], 16), c[C_MV_TO_V], 15), -q_lim, q_lim)
        v_alpha, v_beta = inv_park(v_d, v_q, s, co)
        d_a, d_b, d_c = svpwm(v_alpha, v_beta, top)
        pwm_on = 1
    else:
        v_d = 0
        v_q = 0
        d_a = d_b = d_c = top >> 1
        pwm_on = 0
        st[F_INTEG_D] = 0
        st[F_INTEG_Q] = 0
    st[F_DUTY_A] = d_a
    st[F_DUTY_B] = d_b
    st[F_DUTY_C] = d_c
    st[F_PWM_ON] = pwm_on
    st[F_VD] = v_d
    st[F_VQ] = v_q

    # --- strain: a new AD7195 conversion was read this tick --------------------------------
    if raw[R_STRAIN_NEW] != 0:
        if raw[R_STRAIN_OK] != 0:
            n = (st[F_STRAIN_SAMPLES] + 1) & 0xFF
            st[F_STRAIN_SAMPLES] = n
            code = raw[R_STRAIN]
            up[B.U_STRAIN_LO] = code & 0xFFFF
            up[U_STRAIN_HI] = ((code >> 16) & 0xFF) | (n << 8)
        else:
            _count(st, F_ERR_STRAIN)
            extra |= ST_STRAIN_ERROR
    else:
        # No conversion this tick (4.8 kHz against 20 kHz): the bit keeps saying how the
        # latest read went, rather than flicker off between conversions.
        extra |= st[F_STATUS_EXTRA] & ST_STRAIN_ERROR
    st[F_STATUS_EXTRA] = extra

    # --- upstream memory ------------------------------------------------------------------
    status = extra | latched
    if latched != 0 or state == STATE_FAULT:
        status |= ST_FAULT
    if state == STATE_ENABLED:
        status |= ST_ENABLED
    up[U_STATUS] = status
    up[U_STATE] = state
    if raw[R_SSI_OK] != 0:
        up[U_SSI] = raw[R_SSI]
    up[U_ABI] = abi
    up[U_SPEED] = _u16(speed)
    up[U_THETA_E] = theta_e
    if raw[R_BISS_OK] != 0:
        up[U_PISTON_LO] = raw[R_BISS] & 0xFFFF
        up[U_PISTON_HI] = (raw[R_BISS] >> 16) & 0xFFFF
    i_to_ma = c[C_I_TO_MA]
    up[U_IQ] = _u16(sat_s(mul_shift(i_q, i_to_ma, 15), 16))
    up[U_ID] = _u16(sat_s(mul_shift(i_d, i_to_ma, 15), 16))
    up[U_IA] = _u16(sat_s(mul_shift(i_a, i_to_ma, 15), 16))
    up[U_IB] = _u16(sat_s(mul_shift(i_b, i_to_ma, 15), 16))
    for j in range(5):  # the five pressure channels, in the same order in both layouts
        up[U_P_ACC + j] = raw[R_P_ACC + j]
    up[U_TEMPERATURE] = raw[R_TEMP]
    up[U_HALL] = raw[R_HALL]
    v_to_mv = c[C_V_TO_MV]
    up[U_VD_OUT] = _u16(sat_s(mul_shift(v_d, v_to_mv, 15), 16))
    up[U_VQ_OUT] = _u16(sat_s(mul_shift(v_q, v_to_mv, 15), 16))
    up[U_ERR_SSI] = st[F_ERR_SSI]
    up[U_ERR_BISS] = st[F_ERR_BISS]
    up[U_ERR_STRAIN] = st[F_ERR_STRAIN]
    up[U_ERR_LINK_CRC] = st[F_ERR_LINK_CRC]
    up[U_OC_TRIPS] = st[F_OC_TRIPS]
    up[U_WD_TRIPS] = st[F_WD_TRIPS]
    up[U_SEQ_ECHO] = down[D_SEQUENCE]
    up[U_TICK] = tick & 0xFFFF

    st[F_SINCE_VALID] = min(st[F_SINCE_VALID] + 1, 1 << 30)
    st[F_TICK] = tick + 1
    return pwm_on
