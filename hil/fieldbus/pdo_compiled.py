"""Compiled twins of the process-data conversions (:mod:`hil.fieldbus.pdo`) for the
per-cycle path: SI value to counts, little-endian integers in a byte image, and the master's
output records of every actuator written in one call.

``pdo`` stays the readable reference; these take the same float64 steps in the same order
(no fast-math), so they give the same counts and bytes (``tests/fieldbus/test_master_batch.py``
compares :meth:`Master.set_actuators` with the per-actuator ``set_actuator``; the robot
engine's records are compared with the per-actuator path's in ``tests/hil/test_robot.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hil.fieldbus import pdo

#: Byte offsets in an actuator's output record.
_O_MODE, _O_FLAGS, _O_COMMAND, _O_KPOS, _O_KPF = (
    pdo.ACTUATOR_OUT_DTYPE.fields[f.name][1] for f in pdo.ACTUATOR_OUT)


@njit(cache=True, nogil=True)
def le(image, at, n_bytes, signed):
    """The little-endian integer of ``n_bytes`` at ``image[at]``."""
    v = 0
    for b in range(n_bytes):
        v |= np.int64(image[at + b]) << (8 * b)
    if signed and v >= np.int64(1) << (8 * n_bytes - 1):
        v -= np.int64(1) << (8 * n_bytes)
    return v


@njit(cache=True, nogil=True)
def put(image, at, n_bytes, v):
    """``v`` as a little-endian integer of ``n_bytes`` at ``image[at]``."""
    for b in range(n_bytes):
        image[at + b] = (v >> (8 * b)) & 0xFF


@njit(cache=True, nogil=True)
def counts(value, lsb, lo, hi):
    """:func:`hil.fieldbus.pdo.to_counts` (the same float64 steps): rounded half away from
    zero, saturated to [lo, hi]."""
    c = value / lsb
    r = np.trunc(c + 0.5) if c >= 0 else -np.trunc(-c + 0.5)
    # saturated while a float (an integer value; lo and hi are exact in float64), so that
    # a value beyond the int64 range saturates as pdo's Python integers do
    return np.int64(min(max(r, np.float64(lo)), np.float64(hi)))


@njit(cache=True, nogil=True)
def put_commands(image, starts, mode, flags, values, lsb, lo, hi):
    """Every actuator's output record (at byte ``starts[j]`` of ``image``): ``mode``,
    ``flags``, ``values[j]`` in counts of ``lsb`` saturated to [lo, hi], no gains. False
    (nothing written) if a value is not finite."""
    for j in range(values.shape[0]):
        if not math.isfinite(values[j]):
            return False
    for j in range(values.shape[0]):
        o = starts[j]
        image[o + _O_MODE] = mode
        image[o + _O_FLAGS] = flags
        put(image, o + _O_COMMAND, 4, counts(values[j], lsb, lo, hi))
        put(image, o + _O_KPOS, 2, 0)
        put(image, o + _O_KPF, 2, 0)
    return True
