"""The one family of exceptions every codec in :mod:`protocols` may raise.

A decoder given arbitrary bits or bytes raises only these (never ``IndexError``,
``struct.error`` and the like), so a caller can count and discard a bad frame with a
single ``except CodecError``. The input checks below are the one place where the codecs
turn a wrong argument (type, size, range) into such an error.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator, Mapping, Sequence

import numpy as np


class CodecError(ValueError):
    """Base class: the input is not a valid frame or value for this codec."""


class FrameError(CodecError):
    """Wrong length, missing start/ack bits, illegal field value or similar framing fault."""


class CrcError(CodecError):
    """The frame's check code does not match its contents."""


class RangeError(CodecError):
    """A value to encode lies outside what the field can carry."""


def finite_number(x: object, what: str) -> float:
    """``x`` as a finite float, or :class:`RangeError` naming ``what``."""
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError) as exc:
        raise RangeError(f"{what}: {x!r} is not a number") from exc
    if v != v or v in (float("inf"), float("-inf")):
        raise RangeError(f"{what}: {v} is not finite")
    return v


# -- input checks -----------------------------------------------------------------------------
# Every public entry point of the codecs runs its arguments through these, so that a wrong
# type or an absurd size is a one-line CodecError naming the argument instead of a
# TypeError from deep inside, a silent wrong answer (bytes(5) is five zero bytes) or a loop
# that allocates without end (a negative bit count).

def as_int(x: object, what: str, lo: int | None = None, hi: int | None = None,
           error: type[CodecError] = RangeError) -> int:
    """``x`` as a Python int (ints, bools and numpy integers; not floats) within
    ``lo..hi`` (either may be None: unbounded), else ``error`` naming ``what``."""
    if x.__class__ is not int:
        try:
            x = operator.index(x)  # type: ignore[arg-type]
        except TypeError:
            raise error(f"{what}: {_show(x)} is not an integer") from None
    if (lo is not None and x < lo) or (hi is not None and x > hi):  # type: ignore[operator]
        bounds = f"{lo}..{hi}" if lo is not None and hi is not None else (
            f">= {lo}" if lo is not None else f"<= {hi}")
        raise error(f"{what}: {_show(x)} is not {bounds}")
    return x  # type: ignore[return-value]


def as_bytes(x: object, what: str, error: type[CodecError] = FrameError) -> bytes:
    """``x`` as bytes if it is bytes-like (bytes, bytearray, memoryview, a buffer), else
    ``error``. An int is refused (``bytes(n)`` would be n zero bytes), and so is a str
    (text has no byte form without an encoding)."""
    if x.__class__ is bytes:
        return x  # type: ignore[return-value]
    if isinstance(x, str):
        raise error(f"{what}: a str is not bytes (encode it, or use bytes.fromhex)")
    try:
        return memoryview(x).tobytes()  # type: ignore[arg-type]
    except TypeError:
        raise error(f"{what}: {_show(x)} is not bytes-like") from None


def as_sequence(x: object, what: str, error: type[CodecError] = FrameError) -> Sequence:
    """``x`` if it is a sized, indexable sequence (list, tuple, numpy array, bytes), else
    ``error``. A str and a mapping are refused: indexing them gives characters or keys."""
    if isinstance(x, str | Mapping) or not isinstance(x, Sequence | np.ndarray):
        raise error(f"{what}: {_show(x)} is not a sequence")
    return x  # type: ignore[return-value]


def as_iterable(x: object, what: str, error: type[CodecError] = FrameError) -> Iterator:
    """An iterator over ``x`` (any iterable but a str or a mapping), else ``error``."""
    if isinstance(x, str | Mapping):
        raise error(f"{what}: {_show(x)} is not a sequence")
    try:
        return iter(x)  # type: ignore[call-overload]
    except TypeError:
        raise error(f"{what}: {_show(x)} is not iterable") from None


def as_int_array(x: object, what: str, lo: int | None = None, hi: int | None = None,
                 error: type[CodecError] = RangeError) -> np.ndarray:
    """``x`` as a numpy integer (or bool) array with every value within ``lo..hi``, else
    ``error``. Float arrays are refused rather than truncated (NaN would cast to garbage);
    Python ints beyond int64 end up as uint64 where they fit."""
    try:
        a = np.asarray(x)
        if a.dtype.kind == "O" and a.size:
            a = np.asarray(x, dtype=np.uint64)  # ints above int64: fine if they fit u64
    except (TypeError, ValueError, OverflowError):
        raise error(f"{what}: {_show(x)} is not an array of integers") from None
    if a.dtype.kind not in "biu" and not (a.size == 0 and a.dtype.kind in "fO"):
        raise error(f"{what}: {_show(x)} is not an array of integers (dtype {a.dtype})")
    if a.size and a.dtype.kind != "b":
        if lo is not None and (a.dtype.kind == "i" or lo > 0) and int(a.min()) < lo:
            raise error(f"{what}: value {int(a.min())} is below {lo}")
        if hi is not None and int(a.max()) > hi:
            raise error(f"{what}: value {int(a.max())} is above {hi}")
    return a


def as_bit(x: object, what: str, error: type[CodecError] = FrameError) -> int:
    """``x`` as a logic level 0 or 1 (ints, bools, numpy integers), else ``error``."""
    if x.__class__ is int and (x == 0 or x == 1):
        return x  # type: ignore[return-value]
    v = as_int(x, what, error=error)
    if v not in (0, 1):
        raise error(f"{what}: level {v} is neither 0 nor 1")
    return v


def _show(x: object) -> str:
    """A short repr for a message (a huge int or a long buffer would flood the line)."""
    text = repr(x)
    return text if len(text) <= 40 else f"{text[:37]}..."
