"""The driver board's protections, compiled into its tick: over-current trip and link
watchdog. Both latch a fault bit (cleared only by CLEAR_FAULT, see
:mod:`firmware_model.fpga.enable`) and count their trips in saturating 16-bit counters."""

from __future__ import annotations

from numba import njit

from firmware_model.fpga.fixed import mul_shift, sat_u
from firmware_model.fpga.layout import (
    C_MA_TO_I,
    C_WD_TICKS,
    D_TRIP_CURRENT,
    F_OC_TRIPS,
    F_SINCE_VALID,
    F_WD_TRIPS,
    ST_LINK_LOST,
    ST_LINK_OK,
    ST_OVER_CURRENT,
    STATE_ENABLED,
)


@njit(cache=True, inline="always")
def count(st, k):
    """Count one event in the saturating 16-bit counter ``st[k]``."""
    st[k] = sat_u(st[k] + 1, 16)


@njit(cache=True, inline="always")
def protections(c, st, down, i_a, i_b, i_c, state, latched, extra):
    """Over-current (any phase at or above the trip register) and link watchdog (no valid
    downstream word for ``C_WD_TICKS`` while enabled). Returns ``(latched, extra,
    over_current, link_ok)``: the latched fault bits, the status bits of this tick."""
    trip = mul_shift(down[D_TRIP_CURRENT], c[C_MA_TO_I], 15)
    over_current = abs(i_a) >= trip or abs(i_b) >= trip or abs(i_c) >= trip
    link_ok = st[F_SINCE_VALID] < c[C_WD_TICKS]
    if over_current and (latched & ST_OVER_CURRENT) == 0:
        latched |= ST_OVER_CURRENT
        count(st, F_OC_TRIPS)
    if state == STATE_ENABLED and not link_ok and (latched & ST_LINK_LOST) == 0:
        latched |= ST_LINK_LOST
        count(st, F_WD_TRIPS)
    if link_ok:
        extra |= ST_LINK_OK
    return latched, extra, over_current, link_ok
