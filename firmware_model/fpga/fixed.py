"""Integer helpers with explicit width: wrap-around, saturation and rounding shifts.

All FPGA arithmetic goes through these so that every place where a value can leave its
register width says what happens there. They are compiled with numba (int64 inside) and
also run as plain Python on Python ints (``fn.py_func``) with identical results, because no
intermediate value in this model exceeds 50 bits.

Rounding conventions (C's ``/`` truncates toward zero, ``>>`` floors; we never use ``/``):
* :func:`shr_floor` is an arithmetic right shift (floor), as a bare ``>>`` in HDL;
* :func:`shr_round` adds half an LSB first (round half up), one adder in hardware.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def wrap_s(x: int, bits: int) -> int:
    """Two's-complement wrap of ``x`` into a signed ``bits``-wide register."""
    m = 1 << bits
    x &= m - 1
    if x >= (m >> 1):
        x -= m
    return x


@njit(cache=True, inline="always")
def wrap_u(x: int, bits: int) -> int:
    """Wrap ``x`` into an unsigned ``bits``-wide register (modulo 2**bits)."""
    return x & ((1 << bits) - 1)


@njit(cache=True, inline="always")
def sat_s(x: int, bits: int) -> int:
    """Saturate ``x`` to a signed ``bits``-wide register: -2**(bits-1) .. 2**(bits-1)-1."""
    hi = (1 << (bits - 1)) - 1
    if x > hi:
        return hi
    lo = -hi - 1
    if x < lo:
        return lo
    return x


@njit(cache=True, inline="always")
def sat_u(x: int, bits: int) -> int:
    """Saturate ``x`` to an unsigned ``bits``-wide register: 0 .. 2**bits-1."""
    if x < 0:
        return 0
    hi = (1 << bits) - 1
    if x > hi:
        return hi
    return x


@njit(cache=True, inline="always")
def clamp(x: int, lo: int, hi: int) -> int:
    """Saturate ``x`` to ``lo .. hi``."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@njit(cache=True, inline="always")
def shr_floor(x: int, s: int) -> int:
    """Arithmetic right shift: floor(x / 2**s)."""
    return x >> s


@njit(cache=True, inline="always")
def shr_round(x: int, s: int) -> int:
    """Right shift rounding half up: floor(x / 2**s + 1/2). ``s`` must be >= 1."""
    return (x + (1 << (s - 1))) >> s


@njit(cache=True, inline="always")
def mul_shift(x: int, k: int, s: int) -> int:
    """``x * k / 2**s`` rounded half up: a constant multiply as multiplier + shifter."""
    return (x * k + (1 << (s - 1))) >> s


@njit(cache=True)
def isqrt(n: int) -> int:
    """floor(sqrt(n)) for 0 <= n < 2**32, by the 16-step digit-by-digit method of hardware."""
    if n <= 0:
        return 0
    root = 0
    bit = 1 << 30
    while bit > n:
        bit >>= 2
    while bit != 0:
        if n >= root + bit:
            n -= root + bit
            root = (root >> 1) + bit
        else:
            root >>= 1
        bit >>= 2
    return root


__all__ = ["clamp", "isqrt", "mul_shift", "sat_s", "sat_u", "shr_floor", "shr_round",
           "wrap_s", "wrap_u"]
