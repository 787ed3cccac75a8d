"""The driver board's per-tick logic, compiled: sensors in, protections
(:mod:`~firmware_model.fpga.protections`), enable state machine
(:mod:`~firmware_model.fpga.enable`), FOC current loop (:mod:`~firmware_model.fpga.foc`), PWM
compare counts and the upstream memory out. Constants and boot values:
:mod:`firmware_model.fpga.params`.

One tick of :func:`control_tick` is one 50 us PWM period. Inputs are the raw words the
sensor masters delivered (``raw``, see :data:`layout.RAW_NAMES`) and the downstream memory
(``down``) as the LVDS endpoint last stored it; outputs are the compare counts in the state
array and the refreshed upstream memory (``up``). All arrays are int64 holding values of the
declared widths; :class:`DriverBoard` wraps them for Python callers.
"""

from __future__ import annotations

from numba import njit

from firmware_model.fpga import layout as B
from firmware_model.fpga.enable import enable_state_machine
from firmware_model.fpga.fixed import clamp, mul_shift, sat_s, wrap_s, wrap_u
from firmware_model.fpga.foc import (
    clarke,
    inv_park,
    park,
    pi_step,
    q_limit,
    sin_cos,
    svpwm,
)
from firmware_model.fpga.layout import (
    ANALOG_RAW,
    ANALOG_UP,
    C_ADC_MID,
    C_ADC_SHIFT,
    C_I_TO_MA,
    C_KI_SHIFT,
    C_KP_SHIFT,
    C_MA_TO_I,
    C_MV_TO_V,
    C_POLE_PAIRS,
    C_PWM_TOP,
    C_RTL_TICK,
    C_SPEED_WINDOW,
    C_SSI_SHIFT,
    C_V_LIMIT,
    C_V_TO_MV,
    D_ANGLE_OFFSET,
    D_CURRENT_LIMIT,
    D_ID_REF,
    D_IQ_REF,
    D_KI,
    D_KP,
    D_SEQUENCE,
    D_VD_REF,
    D_VQ_FF,
    D_VQ_REF,
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
    R_ABI,
    R_BISS,
    R_BISS_OK,
    R_HALL,
    R_IA,
    R_IB,
    R_SSI,
    R_SSI_OK,
    R_STRAIN,
    R_STRAIN_NEW,
    R_STRAIN_OK,
    RING_BASE,
    ST_ENABLED,
    ST_ENCODER_ERROR,
    ST_FAULT,
    ST_STRAIN_ERROR,
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
    U_PISTON_HI,
    U_PISTON_LO,
    U_SEQ_ECHO,
    U_SPEED,
    U_SSI,
    U_STATE,
    U_STATUS,
    U_STRAIN_HI,
    U_THETA_E,
    U_TICK,
    U_VD_OUT,
    U_VQ_OUT,
    U_WD_TRIPS,
    BoardMode,
)
from firmware_model.fpga.protections import count, protections
from firmware_model.fpga.rtl_abi import rtl_loop_tick


@njit(cache=True, inline="always")
def _u16(x):
    return x & 0xFFFF


# No runtime (``_nrt=False``, as the plant's tick): the tick allocates nothing, and with the
# runtime the compiled tick kept reference counts on its arrays (atomics) or not, depending
# on what else had been compiled in the same process: 95 or 25 ns a tick, same source.
@njit(cache=True, _nrt=False)
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
        count(st, F_ERR_SSI)
        extra |= ST_ENCODER_ERROR
    if raw[R_BISS_OK] == 0:
        count(st, F_ERR_BISS)
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

    # --- protections and the enable state machine ---------------------------------------
    latched, extra, over_current, link_ok = protections(
        c, st, down, i_a, i_b, i_c, st[F_STATE], st[F_LATCHED], extra)
    state, latched, extra, mode = enable_state_machine(st, down, st[F_STATE], latched, extra,
                                                       over_current, link_ok)

    # --- current loop and modulation ------------------------------------------------------
    top = c[C_PWM_TOP]
    v_lim = c[C_V_LIMIT]
    enabled = state == STATE_ENABLED
    on_rtl = c[C_RTL_TICK] != 0
    if on_rtl:
        # The loop's RTL: it runs (enable high) in current mode only, and holds its
        # integrators (no clock edge) while the board drives voltages.
        current = enabled and mode == BoardMode.CURRENT
        i_d, i_q, v_d, v_q, d_a, d_b, d_c = rtl_loop_tick(
            c, st, down, raw[R_IA], raw[R_IB], theta_e, 1 if current else 0,
            0 if enabled and not current else 1)
        st[F_ID] = i_d
        st[F_IQ] = i_q
    if enabled:
        if mode != BoardMode.CURRENT:
            v_d = clamp(mul_shift(wrap_s(down[D_VD_REF], 16), c[C_MV_TO_V], 15), -v_lim, v_lim)
            q_lim = q_limit(v_d, v_lim)
            v_q = clamp(mul_shift(wrap_s(down[D_VQ_REF], 16), c[C_MV_TO_V], 15), -q_lim, q_lim)
            v_alpha, v_beta = inv_park(v_d, v_q, s, co)
            d_a, d_b, d_c = svpwm(v_alpha, v_beta, top)
        elif not on_rtl:
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
            v_alpha, v_beta = inv_park(v_d, v_q, s, co)
            d_a, d_b, d_c = svpwm(v_alpha, v_beta, top)
        pwm_on = 1
    else:
        if not on_rtl:  # (the RTL, enable low, gives the same: nothing applied, legs at top/2)
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
            count(st, F_ERR_STRAIN)
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
    for j in range(ANALOG_UP.size):  # the analog inputs' ADC codes, as the masters read them
        up[ANALOG_UP[j]] = raw[ANALOG_RAW[j]]
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
