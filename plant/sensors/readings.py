"""What the plant's sensor outputs read: noise and converter resolution, kept out of the
physics (:func:`plant.kernel.physical_outputs` gives the true values).

``effects.sensor_noise`` adds Gaussian noise to the five pressures, the strain force and the
oil temperature (in that order, from the plant's own xorshift64* stream, so the same seed
gives the same noise). How the standard normal samples are drawn is part of the plant's
arithmetic recipe (``sim.plant_numerics``): recipe 4 takes them in Box-Muller pairs, both
samples used, from the recipe's own log, sin/cos and the square root
(:mod:`plant.blocks.lanemath`: a fixed count of operations per sample, so a loop over
actuators vectorises and every lane gives the scalar call's bits, :mod:`plant.lane_outputs`);
recipes 2 and 3 take them in pairs from Marsaglia's polar method (no trigonometric call;
both samples of a pair used; a rejection loop whose trip count differs from draw to draw),
recipe 1 one sample of each Box-Muller pair with libm's functions (the noise of logs
recorded before; about three times the cost). All are exact standard normal distributions;
only the realisation differs.
``effects.quantisation`` floors the encoders' angle and position to
their counts and rounds the converters' values to their LSB.

These are the plant's sensor outputs as the identification and the plant-only analyses see
them. In the full stack the sensor chips (:mod:`plant.sensors.harness`) then turn these
readings into codes; with ``effects.quantisation`` on that is a second rounding, which the
chips' epsilon before each floor keeps harmless for the encoders. It is kept so that runs
stay bit-identical to the logs and figures recorded before the sensors had a module of their
own; ``--set effects.quantisation.enabled=false`` gives the chips the unrounded values.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.blocks.lanemath import _from_bits, log4, sincos3
from plant.layout import (
    P_NOISE_F,
    P_NOISE_ON,
    P_NOISE_P,
    P_NOISE_T,
    P_NUMERICS,
    P_Q_MOTOR,
    P_Q_PISTON,
    P_Q_PRESSURE,
    P_Q_STRAIN,
    P_Q_TEMP,
    P_QUANT_ON,
    Y_F_STRAIN,
    Y_P_ACC,
    Y_P_CYL_A,
    Y_P_CYL_B,
    Y_P_PUMP_A,
    Y_P_PUMP_B,
    Y_TEMP,
    Y_THETA_M,
    Y_X_PISTON,
)


@njit(cache=True, inline="always")
def xorshift(s):
    """The next state of the plant's xorshift64* stream (``s`` a uint64)."""
    s ^= s >> np.uint64(12)
    s ^= s << np.uint64(25)
    s ^= s >> np.uint64(27)
    return s


@njit(cache=True, inline="always")
def _next_uniform(rng):
    """xorshift64* -> float in (0, 1]. ``rng`` is a uint64 array of length 1."""
    s = xorshift(rng[0])
    rng[0] = s
    r = s * np.uint64(0x2545F4914F6CDD1D)
    return (float(r >> np.uint64(11)) + 1.0) * (1.0 / 9007199254740992.0)


@njit(cache=True, inline="always")
def _gauss(rng):
    """Standard normal sample (Box-Muller, one of the pair)."""
    u1 = _next_uniform(rng)
    u2 = _next_uniform(rng)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True, inline="always")
def _gauss_pair(rng):
    """Two independent standard normal samples (Marsaglia's polar method: a uniform point
    in the unit disc, accepted with probability pi/4, scaled by sqrt(-2 ln s / s))."""
    while True:
        a = 2.0 * _next_uniform(rng) - 1.0
        b = 2.0 * _next_uniform(rng) - 1.0
        s = a * a + b * b
        if 0.0 < s < 1.0:
            f = math.sqrt(-2.0 * math.log(s) / s)
            return a * f, b * f


#: 1.0's bits: OR-ed with 52 random mantissa bits they give a double in [1, 2).
_ONE_BITS = 0x3FF0000000000000
_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def unit4(s):
    """Recipe 4's uniform in (0, 1] from the stream state ``s`` (a uint64): the top 52 bits
    of xorshift64*'s output as the mantissa of a double in [1, 2), taken from 2 (exact: the
    multiples of 2**-52 in (0, 1]). Bit moves and one subtraction, no integer conversion."""
    r = s * np.uint64(0x2545F4914F6CDD1D)
    return 2.0 - _from_bits(np.int64(r >> np.uint64(12)) | _ONE_BITS)


@njit(cache=True, inline="always", error_model="numpy")
def gauss_pair4(s):
    """Two independent standard normal samples of recipe 4 from the stream state ``s`` (a
    uint64): (next state, g1, g2). Box-Muller from two uniforms u1, u2 in (0, 1]:
    sqrt(-2 ln u1) (cos 2 pi u2, sin 2 pi u2), with :func:`~plant.blocks.lanemath.log4` and
    :func:`~plant.blocks.lanemath.sincos3`; no branch, a fixed count of operations (the
    largest |sample|: sqrt(2 ln 2**52) = 8.5)."""
    s = xorshift(s)
    u1 = unit4(s)
    s = xorshift(s)
    u2 = unit4(s)
    rad = math.sqrt(-2.0 * log4(u1))
    sn, cs = sincos3(_TWO_PI * u2)
    return s, rad * cs, rad * sn


@njit(cache=True, inline="always", error_model="numpy")
def gauss7_4(s):
    """Recipe 4's seven samples of one tick from the stream state ``s``: (next state, the
    five pressures', the strain force's and the temperature's samples), four pairs (the
    last one's second sample unused, as the polar method's)."""
    s, g0, g1 = gauss_pair4(s)
    s, g2, g3 = gauss_pair4(s)
    s, g4, g5 = gauss_pair4(s)
    s, g6, _ = gauss_pair4(s)
    return s, g0, g1, g2, g3, g4, g5, g6


@njit(cache=True, inline="always")
def _quantise(v, lsb):
    return math.floor(v / lsb + 0.5) * lsb


@njit(cache=True, inline="always")
def _add_noise(p, y, sp, g0, g1, g2, g3, g4, g5, g6):
    """Add a tick's seven unit normal samples to the output row ``y``: ``sp`` [Pa] times
    g0-g4 to the five pressures, the strain force's and the temperature's sizes times g5
    and g6 (recipes 2-4; recipe 1 draws its samples one by one, in this order)."""
    y[Y_P_ACC] += sp * g0
    y[Y_P_PUMP_A] += sp * g1
    y[Y_P_PUMP_B] += sp * g2
    y[Y_P_CYL_A] += sp * g3
    y[Y_P_CYL_B] += sp * g4
    y[Y_F_STRAIN] += p[P_NOISE_F] * g5
    y[Y_TEMP] += p[P_NOISE_T] * g6


@njit(cache=True, inline="always")
def sense(p, rng, y):
    """Turn the physical values in the output row ``y`` into what the sensors read."""
    if p[P_NOISE_ON] > 0.5 and p[P_NUMERICS] >= 4.0:
        sp = p[P_NOISE_P]
        s, g0, g1, g2, g3, g4, g5, g6 = gauss7_4(rng[0])
        rng[0] = s
        _add_noise(p, y, sp, g0, g1, g2, g3, g4, g5, g6)
    elif p[P_NOISE_ON] > 0.5 and p[P_NUMERICS] >= 2.0:
        sp = p[P_NOISE_P]
        g0, g1 = _gauss_pair(rng)
        g2, g3 = _gauss_pair(rng)
        g4, g5 = _gauss_pair(rng)
        g6, _ = _gauss_pair(rng)
        _add_noise(p, y, sp, g0, g1, g2, g3, g4, g5, g6)
    elif p[P_NOISE_ON] > 0.5:
        sp = p[P_NOISE_P]
        y[Y_P_ACC] += sp * _gauss(rng)
        y[Y_P_PUMP_A] += sp * _gauss(rng)
        y[Y_P_PUMP_B] += sp * _gauss(rng)
        y[Y_P_CYL_A] += sp * _gauss(rng)
        y[Y_P_CYL_B] += sp * _gauss(rng)
        y[Y_F_STRAIN] += p[P_NOISE_F] * _gauss(rng)
        y[Y_TEMP] += p[P_NOISE_T] * _gauss(rng)
    if p[P_QUANT_ON] > 0.5:
        # Encoders floor to their count; converters round to their nearest code.
        y[Y_THETA_M] = math.floor(y[Y_THETA_M] / p[P_Q_MOTOR]) * p[P_Q_MOTOR]
        y[Y_X_PISTON] = math.floor(y[Y_X_PISTON] / p[P_Q_PISTON]) * p[P_Q_PISTON]
        lsb = p[P_Q_PRESSURE]
        y[Y_P_ACC] = _quantise(y[Y_P_ACC], lsb)
        y[Y_P_PUMP_A] = _quantise(y[Y_P_PUMP_A], lsb)
        y[Y_P_PUMP_B] = _quantise(y[Y_P_PUMP_B], lsb)
        y[Y_P_CYL_A] = _quantise(y[Y_P_CYL_A], lsb)
        y[Y_P_CYL_B] = _quantise(y[Y_P_CYL_B], lsb)
        y[Y_F_STRAIN] = _quantise(y[Y_F_STRAIN], p[P_Q_STRAIN])
        y[Y_TEMP] = _quantise(y[Y_TEMP], p[P_Q_TEMP])
