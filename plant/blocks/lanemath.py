"""exp, sin/cos and tanh of the plant's arithmetic recipe 3 (``sim.plant_numerics = 3``),
and the natural log recipe 4 adds for its sensor noise (:func:`log4`): written out in
additions, multiplications, divisions, ``floor`` and integer bit moves, so that a loop over
actuators compiles to vector instructions (four doubles at a time with AVX2) and every
lane gives the same bits as the scalar call. libm's functions are calls
the compiler cannot widen; a vector math library (SVML) would widen them but round
differently from libm and from each other, so the recipe owns its functions instead.

Each is the classic argument reduction and polynomial (the coefficients are fdlibm's
minimax fits, Sun Microsystems 1993): accurate to about one unit in the last place over the
ranges the plant uses; sin/cos reduce by pi/2 in three parts (Cody and Waite), exact for
``|x| < 2**19 pi/2`` (8e5 rad of electrical angle; beyond, the reduction loses a bit per
doubling of |x|). No branch depends on the value except through selects (``a if c else
b`` on values both computed), which the compiler turns into blend instructions.

Compiled with the plant's options: no fast-math, so no contraction of a multiply and add
and no reassociation (the same operations in the same order in every lane).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from firmware_model.lane_int import bits as _bits
from firmware_model.lane_int import from_bits as _from_bits

#: Inlined where called; numpy's error model: a division here never has a zero divisor,
#: and the check numba would add is a branch that stops a loop from vectorising.
MATH = {"cache": True, "inline": "always", "error_model": "numpy"}


@intrinsic
def pick(typingctx, c, a, b):
    """``a if c else b`` for two float64 already computed, as one LLVM ``select``: numba
    compiles a conditional expression into a branch, and where one side costs more than
    LLVM will speculate (a division, a row loaded only on one side) the branch stays and
    the loop over the lanes around it is not vectorised. Same bits as the branch."""
    if c != types.boolean or a != types.float64 or b != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.select(args[0], args[1], args[2])

    return types.float64(types.boolean, types.float64, types.float64), codegen


# exp: x = k ln2 + r, |r| <= ln2 / 2; ln2 in two parts, the first with 32 bits so k ln2_hi
# is exact for |k| < 2**20.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e+00
_P1 = 1.66666666666666019037e-01
_P2 = -2.77777777770155933842e-03
_P3 = 6.61375632143793436117e-05
_P4 = -1.65339022054652515390e-06
_P5 = 4.13813679705723846039e-08
#: 1.5 * 2**52: adding it to an integral double leaves the integer in the low mantissa bits.
_SHIFTER = 6755399441055744.0
_EXP_MIN = -708.0   # below: 0 (the result would be subnormal)
_EXP_MAX = 709.0    # above: inf


@njit(**MATH)
def exp3(x):
    """e**x (recipe 3)."""
    xc = _EXP_MIN if x < _EXP_MIN else (_EXP_MAX if x > _EXP_MAX else x)
    k = np.floor(xc * _INV_LN2 + 0.5)
    hi = xc - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    e_r = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    # 2**k from k's integer bits: (k + 1023) << 52 (k in [-1022, 1023] after the clamp).
    scale = _from_bits((_bits(k + _SHIFTER) - _bits(_SHIFTER) + 1023) << 52)
    y = e_r * scale
    return 0.0 if x < _EXP_MIN else (np.inf if x > _EXP_MAX else y)


# sin/cos on |r| <= pi/4, fdlibm's __kernel_sin / __kernel_cos polynomials.
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
# pi/2 in three parts of 33 bits each: k * part is exact for |k| < 2**20.
_PIO2_1 = 1.57079632673412561417e+00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_INV_PIO2 = 6.36619772367581382433e-01


@njit(**MATH)
def sincos3(x):
    """(sin x, cos x) (recipe 3), one argument reduction for both."""
    k = np.floor(x * _INV_PIO2 + 0.5)
    r = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_3
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (
        _C4 + z * (_C5 + z * _C6))))))
    q = _bits(k + _SHIFTER) - _bits(_SHIFTER)  # the quadrant, mod 4
    # Two-way selects on the quadrant's bits (a four-way choice on q compiles to a switch,
    # which the loop vectoriser does not take).
    odd = (q & 1) != 0
    sin_x = c if odd else s
    cos_x = s if odd else c
    sin_x = -sin_x if (q & 2) != 0 else sin_x
    cos_x = -cos_x if ((q + 1) & 2) != 0 else cos_x
    return sin_x, cos_x


@njit(**MATH)
def sin3(x):
    """sin x (recipe 3): :func:`sincos3`'s first value."""
    return sincos3(x)[0]


_TANH_SMALL = 0.0009765625  # 2**-10: below, the odd series to x**5 (error < x**7)
_TANH_BIG = 22.0            # above, tanh is 1 to double precision


@njit(**MATH)
def tanh3(x):
    """tanh x (recipe 3): (1 - e**-2|x|) / (1 + e**-2|x|) with x's sign; the odd series
    near 0, where that quotient would cancel."""
    a = x if x >= 0.0 else -x
    t = exp3(-2.0 * (a if a < _TANH_BIG else _TANH_BIG))
    q = (1.0 - t) / (1.0 + t)
    z = x * x
    small = x - x * z * (1.0 / 3.0 - z * (2.0 / 15.0))
    big = q if x >= 0.0 else -q
    return small if a < _TANH_SMALL else big


# log: x = 2**k (1 + f), 1 + f in [sqrt(2)/2, sqrt(2)); s = f / (2 + f); fdlibm's __ieee754_log
# polynomial in s**2 (Lg1..Lg7).
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
#: The bits of a double just below sqrt(2)/2 (its high 32 bits; the low ones zero), and what
#: moves them to 1.0's: adding it carries into the exponent exactly when the mantissa is at
#: least sqrt(2)/2's, which picks k so that 1 + f lands in [sqrt(2)/2, sqrt(2)).
_HALF_SQRT2_BITS = 0x3FE6A09E00000000
_TO_ONE = 0x3FF0000000000000 - _HALF_SQRT2_BITS
_MANTISSA = 0x000FFFFFFFFFFFFF


@njit(**MATH)
def log4(x):
    """ln x (recipe 4) for a positive normal double x (the noise's uniforms: 2**-52 .. 1);
    within about one ulp of libm's. Not for 0, negative, subnormal, inf or nan."""
    t = _bits(x) + _TO_ONE
    k = (t >> 52) - 1023
    f = _from_bits((t & _MANTISSA) + _HALF_SQRT2_BITS) - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    r = t2 + t1
    dk = _from_bits(k + _bits(_SHIFTER)) - _SHIFTER  # k as a double, exactly (|k| < 2**51)
    return s * (hfsq + r) + dk * _LN2_LO - hfsq + f + dk * _LN2_HI


# --- the recipe's choice, for the scalar blocks ---------------------------------------------
@njit(cache=True, inline="always")
def exp_r(x, numerics):
    """e**x by the plant recipe ``numerics``: libm's before recipe 3."""
    return exp3(x) if numerics >= 3.0 else math.exp(x)


@njit(cache=True, inline="always")
def sin_r(x, numerics):
    """sin x by the plant recipe ``numerics``."""
    return sin3(x) if numerics >= 3.0 else math.sin(x)


@njit(cache=True, inline="always")
def tanh_r(x, numerics):
    """tanh x by the plant recipe ``numerics``."""
    return tanh3(x) if numerics >= 3.0 else math.tanh(x)


__all__ = ["exp3", "exp_r", "log4", "pick", "sin3", "sin_r", "sincos3", "tanh3", "tanh_r"]
