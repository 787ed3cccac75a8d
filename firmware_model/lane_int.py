"""int64 <-> float64 conversions and an integer select for the kernels' vector lanes, in
operations every x86-64 vector width has.

The packed int64 <-> float64 conversions (``vcvtqq2pd``, ``vcvttpd2qq``) exist only with
AVX-512DQ. Without them (AVX2, e.g. AMD znver3) LLVM converts a vector of int64 lane by
lane: each lane extracted, a scalar ``vcvtsi2sd``/``vcvttsd2si``, inserted back; and its
cost model then often leaves the whole loop scalar. Here instead:

* adding 1.5 * 2**52 to an integral float64 ``|x| < 2**51`` puts ``x`` in the low mantissa
  bits: its bits minus those of 1.5 * 2**52 are ``x`` as an int64, and back
  (:func:`integral_to_int`, :func:`trunc_to_int`, :func:`small_int_to_float`): the caller
  knows or checks the range;
* any int64 to float64 (:func:`int_to_float`): its high 32 bits (signed) and its low 32
  bits each exactly as a float64 by the same trick, then ``hi * 2**32`` (exact) ``+ lo``:
  one rounding, to nearest even, as the conversion rounds, so the same bits for every
  int64.

A float64 add and an integer add (or and/or) per conversion: on AVX-512 about what the one
packed conversion costs, so a loop written this way is not slower there.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def bits(typingctx, x):
    """The IEEE-754 bits of a float64, as an int64 (a register move, no conversion)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def from_bits(typingctx, n):
    """The float64 with the IEEE-754 bits ``n`` (an int64)."""
    if n != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


@intrinsic
def pick_int(typingctx, c, a, b):
    """``a if c else b`` for two integers of one type already computed, as one LLVM
    ``select`` (numba compiles a conditional expression into a branch, which LLVM does not
    always turn back into a select)."""
    if c != types.boolean or not isinstance(a, types.Integer) or a != b:
        return None

    def codegen(context, builder, signature, args):
        return builder.select(args[0], args[1], args[2])

    return a(types.boolean, a, b), codegen


_SHIFTER = 6755399441055744.0        # 1.5 * 2**52
_SHIFTER_BITS = 0x4338000000000000   # its bits
_TWO52 = 4503599627370496.0
_TWO52_BITS = 0x4330000000000000
_TWO32 = 4294967296.0
#: Bound below which :func:`integral_to_int`, :func:`trunc_to_int` and
#: :func:`small_int_to_float` are exact.
INT_EXACT = 2251799813685248.0       # 2**51


@njit(cache=True, inline="always")
def integral_to_int(x):
    """``np.int64(x)`` of an integral float64 ``x`` with ``|x| <`` :data:`INT_EXACT`."""
    return bits(x + _SHIFTER) - _SHIFTER_BITS


@njit(cache=True, inline="always")
def trunc_to_int(x):
    """``np.int64(x)`` (towards zero) of a float64 ``x`` with ``|x| <`` :data:`INT_EXACT`."""
    return bits(np.trunc(x) + _SHIFTER) - _SHIFTER_BITS


@njit(cache=True, inline="always")
def small_int_to_float(n):
    """``np.float64(n)`` of an int64 ``n`` with ``|n| < 2**51``."""
    return from_bits(n + _SHIFTER_BITS) - _SHIFTER


@njit(cache=True, inline="always")
def int_to_float(n):
    """``np.float64(n)`` of any int64 ``n``, bit for bit (module doc)."""
    hi = from_bits((n >> 32) + _SHIFTER_BITS) - _SHIFTER
    lo = from_bits((n & 0xFFFFFFFF) | _TWO52_BITS) - _TWO52
    return hi * _TWO32 + lo


__all__ = ["INT_EXACT", "bits", "from_bits", "int_to_float", "integral_to_int", "pick_int",
           "small_int_to_float", "trunc_to_int"]
