"""The driver board's enable state machine, compiled into its tick.

States ``disabled -> enabled -> fault``: ENABLE (a level in the control register) with a
mode that drives the bridge enables, unless a fault is latched, a phase is over the trip
level, the link is down or the encoder failed (then ENABLE_REFUSED); any latched fault
moves an enabled board to ``fault``; CLEAR_FAULT (a rising edge) clears the latch, from
``fault`` only with ENABLE low and the cause gone. Entering ``enabled`` resets the PI
integrators.
"""

from __future__ import annotations

from numba import njit

from firmware_model.fpga.layout import (
    CTRL_CLEAR_FAULT,
    CTRL_ENABLE,
    D_CONTROL,
    D_MODE,
    F_INTEG_D,
    F_INTEG_Q,
    F_LATCHED,
    F_PREV_CONTROL,
    F_STATE,
    ST_ENABLE_REFUSED,
    ST_ENCODER_ERROR,
    STATE_DISABLED,
    STATE_ENABLED,
    STATE_FAULT,
    BoardMode,
)


@njit(cache=True, inline="always")
def enable_state_machine(st, down, state, latched, extra, over_current, link_ok):
    """One step of the state machine; stores and returns ``(state, latched, extra, mode)``
    (``mode``: the mode register as read this tick)."""
    control = down[D_CONTROL]
    mode = down[D_MODE]
    enable = (control & CTRL_ENABLE) != 0 and (mode == BoardMode.CURRENT
                                              or mode == BoardMode.VOLTAGE)
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
    return state, latched, extra, mode
