"""Hall sensors of the BLDC motor: 3-bit sector code <-> electrical angle sector.

Convention (120-degree sensor spacing, the usual arrangement): the code is
``Ha << 2 | Hb << 1 | Hc`` and, for an electrical angle theta (after subtracting the
mounting offset), Ha is high for theta in [0, 180) deg, Hb in [120, 300) deg and Hc in
[240, 420) deg. Sector k covers [60 k, 60 (k + 1)) deg, which gives the six-step sequence

    sector   0    1    2    3    4    5
    code    101  100  110  010  011  001

for increasing angle. Codes 000 and 111 cannot occur with 120-degree sensors: they mean a
broken wire, a missing supply or a failed sensor, and decode as :class:`FrameError`.
"""

from __future__ import annotations

import math

import numpy as np

from protocols.bits import as_index
from protocols.errors import FrameError, RangeError, as_int_array, finite_number

#: Hall code per sector, sector 0 first (increasing electrical angle).
SEQUENCE: tuple[int, ...] = (0b101, 0b100, 0b110, 0b010, 0b011, 0b001)
#: Sector per code; -1 marks the invalid codes 000 and 111.
SECTOR_OF_CODE: tuple[int, ...] = tuple(SEQUENCE.index(c) if c in SEQUENCE else -1
                                        for c in range(8))
SECTOR_RAD = math.pi / 3

_SECTOR_NP = np.asarray(SECTOR_OF_CODE, dtype=np.int8)
_CODE_NP = np.asarray(SEQUENCE, dtype=np.uint8)


def sector_from_angle(theta_e_rad: float, offset_rad: float = 0.0) -> int:
    """Sector 0..5 of an electrical angle in radians (any real value, wraps)."""
    if theta_e_rad.__class__ is not float or offset_rad.__class__ is not float:
        theta_e_rad = finite_number(theta_e_rad, "electrical angle")
        offset_rad = finite_number(offset_rad, "offset_rad")
    x = (theta_e_rad - offset_rad) / SECTOR_RAD
    if not math.isfinite(x):
        raise RangeError(f"electrical angle {theta_e_rad!r} is not finite")
    return int(math.floor(x)) % 6


def sector_center_rad(sector: int) -> float:
    """Electrical angle at the middle of a sector, radians in [0, 2 pi)."""
    return (_sector(sector) + 0.5) * SECTOR_RAD


def _sector(sector: object) -> int:
    """``sector`` as an int in 0..5, else RangeError."""
    try:
        s = as_index(sector, "sector")
    except FrameError:
        raise RangeError(f"sector {sector!r} is not an integer") from None
    if not 0 <= s <= 5:
        raise RangeError(f"sector {s} outside 0..5")
    return s


def encode(sector: int) -> int:
    """3-bit Hall code of a sector (0..5)."""
    return SEQUENCE[_sector(sector)]


def decode(code: object) -> int:
    """Sector 0..5 of a 3-bit Hall code; FrameError for 000, 111 or a non-3-bit value."""
    c = as_index(code, "hall code")
    if not 0 <= c <= 7:
        raise FrameError(f"hall code {c} is not 3 bits")
    s = SECTOR_OF_CODE[c]
    if s < 0:
        raise FrameError(f"hall code {c:03b} is invalid (sensor or wiring fault)")
    return s


def code_from_angle(theta_e_rad: float, offset_rad: float = 0.0) -> int:
    """Hall code the sensors show at an electrical angle (radians)."""
    return SEQUENCE[sector_from_angle(theta_e_rad, offset_rad)]


def sector_step(previous_code: object, code: object) -> int:
    """Direction of a change between two reads: +1, -1 or 0 sectors.

    A jump of two or three sectors between consecutive reads means a missed edge or a
    glitch and raises :class:`FrameError`, as do invalid codes.
    """
    d = (decode(code) - decode(previous_code)) % 6
    if d == 0:
        return 0
    if d == 1:
        return 1
    if d == 5:
        return -1
    raise FrameError(f"hall jumped {d} sectors between reads")


def sectors_from_angle_array(theta_e_rad: np.ndarray, offset_rad: float = 0.0) -> np.ndarray:
    """Vectorised :func:`sector_from_angle` (int64); RangeError for non-finite angles."""
    try:
        theta = np.asarray(theta_e_rad, dtype=np.float64)
    except (TypeError, ValueError):
        raise RangeError(f"electrical angles: {type(theta_e_rad).__name__} is not an array "
                         "of numbers") from None
    x = (theta - finite_number(offset_rad, "offset_rad")) / SECTOR_RAD
    if not np.all(np.isfinite(x)):
        raise RangeError("an electrical angle is not finite")
    # The modulo before the cast: a huge angle would overflow int64 (its sector is
    # meaningless at that size, but must not come out of a wrapped integer).
    return (np.floor(x) % 6).astype(np.int64)


def encode_array(sectors: np.ndarray) -> np.ndarray:
    """Vectorised :func:`encode` -> uint8 codes."""
    return _CODE_NP[as_int_array(sectors, "sectors", 0, 5)]


def decode_array(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`decode`: (sector int8, valid bool); sector is -1 where invalid.

    :class:`FrameError` if ``codes`` is not an array of integers (a code outside 0..7 is
    merely invalid).
    """
    c = as_int_array(codes, "hall codes", error=FrameError)
    if c.dtype.kind == "u" and c.dtype.itemsize == 8:
        c = np.minimum(c, 8)  # above int64: invalid anyway, and would wrap negative
    c = c.astype(np.int64)
    in_range = (c >= 0) & (c <= 7)
    sector = np.where(in_range, _SECTOR_NP[np.clip(c, 0, 7)], -1).astype(np.int8)
    return sector, sector >= 0
