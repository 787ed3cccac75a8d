"""The MCU's filters and loop blocks as small float32 classes (in the manner of SimpleFOC's
``LowPassFilter`` and ``PIDController``): each holds its coefficients and its state as
``numpy.float32`` and updates in one call, as the Cortex-M4's FPU would compute it.

Coefficients are computed once in float64 and rounded to float32, as a firmware build
would from ``#define``d constants.
"""

from __future__ import annotations

import math

import numpy as np

F32 = np.float32
ZERO = F32(0.0)
NAN = F32(math.nan)


class LowPassFilter:
    """First order: ``y += a (u - y)``, a = 1 - exp(-2 pi f_c dt) (exact for a step)."""

    __slots__ = ("a", "y")

    def __init__(self, cutoff_hz: float, dt: float) -> None:
        self.a = F32(1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt))
        self.reset()

    def reset(self) -> None:
        self.y = ZERO

    def __call__(self, u: np.float32) -> np.float32:
        self.y += self.a * (u - self.y)
        return self.y


class HighPassFilter:
    """First order, discrete: ``y = a (y + u - u_prev)``, a = 1 / (1 + 2 pi f_c dt); the
    first sample starts it at rest (no step response to the initial value)."""

    __slots__ = ("a", "u_prev", "y")

    def __init__(self, cutoff_hz: float, dt: float) -> None:
        self.a = F32(1.0 / (1.0 + 2.0 * math.pi * cutoff_hz * dt))
        self.reset()

    def reset(self) -> None:
        self.y = ZERO
        self.u_prev = NAN

    def __call__(self, u: np.float32) -> np.float32:
        if self.u_prev != self.u_prev:  # first sample
            self.u_prev = u
        self.y = self.a * (self.y + u - self.u_prev)
        self.u_prev = u
        return self.y


class DerivativeFilter:
    """A derivative through a first-order low-pass: ``y += a ((u - u_prev) / dt - y)``, a as
    in :class:`LowPassFilter`. ``u_prev`` starts at zero."""

    __slots__ = ("a", "dt", "u_prev", "y")

    def __init__(self, cutoff_hz: float, dt: float) -> None:
        self.a = F32(1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt))
        self.dt = F32(dt)
        self.reset()

    def reset(self) -> None:
        self.y = ZERO
        self.u_prev = ZERO

    def __call__(self, u: np.float32) -> np.float32:
        self.y += self.a * ((u - self.u_prev) / self.dt - self.y)
        self.u_prev = u
        return self.y


class PIController:
    """``out = kp e + integral``; :meth:`integrate` adds ``ki e dt`` (the caller skips it
    while the output is saturated: no wind-up)."""

    __slots__ = ("dt", "integral", "ki", "kp")

    def __init__(self, kp: float, ki: float, dt: float) -> None:
        self.kp = F32(kp)
        self.ki = F32(ki)
        self.dt = F32(dt)
        self.reset()

    def reset(self) -> None:
        self.integral = ZERO

    def __call__(self, e: np.float32) -> np.float32:
        return self.kp * e + self.integral

    def integrate(self, e: np.float32) -> None:
        self.integral += self.ki * e * self.dt


class MomentumObserver:
    """Disturbance observer of one inertia from its momentum: with P = J v,
    ``r = k_o (P - P_0 - sum (tau_in - tau_out + r) dt)``; r converges to the force the
    model ``J dv/dt = tau_in - tau_out`` leaves out (friction, ripple) with bandwidth k_o.
    P_0 is taken at the first update."""

    __slots__ = ("dt", "j", "ko", "p0", "r", "total")

    def __init__(self, inertia: float, bandwidth_hz: float, dt: float) -> None:
        self.j = F32(inertia)
        self.ko = F32(2.0 * math.pi * bandwidth_hz)
        self.dt = F32(dt)
        self.reset()

    def reset(self) -> None:
        self.total = ZERO
        self.p0 = NAN
        self.r = ZERO

    def __call__(self, v: np.float32, tau_in: np.float32, tau_out: np.float32) -> np.float32:
        momentum = self.j * v
        if self.p0 != self.p0:
            self.p0 = momentum
        self.total += (tau_in - tau_out + self.r) * self.dt
        self.r = self.ko * (momentum - self.p0 - self.total)
        return self.r
