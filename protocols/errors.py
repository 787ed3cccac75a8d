"""The one family of exceptions every codec in :mod:`protocols` may raise.

A decoder given arbitrary bits or bytes raises only these (never ``IndexError``,
``struct.error`` and the like), so a caller can count and discard a bad frame with a
single ``except CodecError``.
"""

from __future__ import annotations


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
