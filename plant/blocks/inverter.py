"""The inverter as an average-value model: leg voltage (d - 1/2) V_dc over a PWM period,
less the dead-time error sign(i) t_dead f_pwm V_dc (faded linearly for |i| below
``dead_time_current_a``, where the ripple makes the current change sign within a period),
duty cycles clamped to the inverter's limits."""

from __future__ import annotations

from numba import njit

from plant.layout import (
    IN_DA,
    IN_DB,
    IN_DC,
    P_DEAD_CURRENT,
    P_DEAD_FRAC,
    P_DUTY_MAX,
    P_DUTY_MIN,
    P_VDC,
)


@njit(cache=True, inline="always")
def dead_time_error(p, i):
    """Leg-voltage error in V from dead time: -sign(i) t_d f_pwm V_dc, faded near i = 0."""
    s = i / p[P_DEAD_CURRENT]
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    return -s * p[P_DEAD_FRAC] * p[P_VDC]


@njit(cache=True, inline="always")
def clamp_duty(p, d):
    if d < p[P_DUTY_MIN]:
        return p[P_DUTY_MIN]
    if d > p[P_DUTY_MAX]:
        return p[P_DUTY_MAX]
    return d


@njit(cache=True, inline="always")
def leg_voltages(p, u, i_a, i_b, i_c):
    """Average leg voltages (v_a, v_b, v_c) in V against the DC-bus midpoint."""
    vdc = p[P_VDC]
    v_a = (clamp_duty(p, u[IN_DA]) - 0.5) * vdc + dead_time_error(p, i_a)
    v_b = (clamp_duty(p, u[IN_DB]) - 0.5) * vdc + dead_time_error(p, i_b)
    v_c = (clamp_duty(p, u[IN_DC]) - 0.5) * vdc + dead_time_error(p, i_c)
    return v_a, v_b, v_c
