"""BiSS-C single-cycle data of the Renishaw RESOLUTE absolute encoder (piston position).

Frame (value level), MSB first, after the Ack bits::

    Start(1)=1 | CDS(1)=0 | position(n) | nE(1) | nW(1) | CRC(6)

* ``position``: natural binary, MSB first; ``n`` = 26 (rotary, counts per turn) or
  26/32/36 for the linear 5 nm scale (part-number dependent, configurable).
* ``nE``/``nW``: error and warning, ACTIVE LOW (0 = error/warning present).
* CRC: x^6 + x + 1, init 0, MSB first, over position + nE + nW, sent inverted.

Line level: the master's samples of SLO on successive MA rising edges look like
``1...1 (ready) 0...0 (Ack, >= 1 bit) 1 (Start) 0 (CDS) ... CRC ... 0...0 (timeout)``;
:meth:`BissCodec.encode_line` builds that and :meth:`BissCodec.decode_line` finds the frame
in it. A decoded frame reports error and warning; a CRC mismatch raises :class:`CrcError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from protocols.bits import Layout, as_index, check, const, value
from protocols.crc import CRC6_BISS
from protocols.errors import (
    FrameError,
    RangeError,
    as_bit,
    as_int,
    as_int_array,
    as_sequence,
    finite_number,
)

#: Position word lengths this codec accepts (RESOLUTE part numbers: 18, 26, 32, 36 bit).
POSITION_BITS = (18, 26, 32, 36)
#: Linear RESOLUTE scale pitch per count, metres (5 nm).
LINEAR_COUNT_M = 5e-9
#: Most ready, Ack or timeout bits :meth:`BissCodec.encode_line` builds (a real line has a
#: few; the cap turns a wrong count into an error instead of a huge tuple).
MAX_LINE_BITS = 1 << 16


class BissReading(NamedTuple):
    """One decoded BiSS frame: position in counts, error and warning as True = present."""

    position: int
    error: bool
    warning: bool


def frame_layout(position_bits: int) -> Layout:
    """The declared BiSS-C single-cycle frame for a ``position_bits``-bit encoder."""
    return Layout(f"BiSS-C/{position_bits}", [
        const("start", 1, 1, "Start bit, always 1 (follows the Ack zeros)"),
        const("cds", 1, 0, "CDS (control data slave), 0: no register communication"),
        value("position", position_bits, "position, natural binary, MSB first"),
        value("n_error", 1, "nE, active low: 0 = error (position may be invalid)"),
        value("n_warning", 1, "nW, active low: 0 = warning (e.g. scale dirty)"),
        check("crc", CRC6_BISS, ("position", "n_error", "n_warning"),
              "CRC-6 x^6+x+1 over position..nW, init 0, sent inverted"),
    ])


class BissCodec:
    """Encoder (device side) and decoder (master side) of one RESOLUTE variant.

    ``position_bits``: 26 for the rotary encoder (counts per turn); 26, 32 or 36 for the
    linear 5 nm scale (default 26 here; set it from the part number).
    """

    __slots__ = ("position_bits", "layout")

    def __init__(self, position_bits: int = 26) -> None:
        if position_bits not in POSITION_BITS:
            raise RangeError(f"position_bits must be one of {POSITION_BITS}")
        self.position_bits = position_bits
        self.layout = frame_layout(position_bits)

    def __repr__(self) -> str:
        return f"BissCodec(position_bits={self.position_bits})"

    @property
    def frame_bits(self) -> int:
        """Bits from Start to the last CRC bit."""
        return self.layout.width

    # -- value level ----------------------------------------------------------------------
    def encode(self, position: int, error: bool = False, warning: bool = False) -> int:
        """Frame word (Start..CRC) for a position in counts and the two status flags
        (bool or 0/1; anything else is a :class:`RangeError`, not a truth value)."""
        if error.__class__ is not bool or warning.__class__ is not bool:
            error = as_bit(error, "BiSS error flag", RangeError)
            warning = as_bit(warning, "BiSS warning flag", RangeError)
        return self.layout.pack(position, not error, not warning)

    def decode(self, word: object) -> BissReading:
        """Check and decode a frame word (Start..CRC).

        Raises :class:`FrameError` (width, Start or CDS wrong) or :class:`CrcError`.
        """
        pos, ne, nw = self.layout.unpack(word)
        return BissReading(pos, ne == 0, nw == 0)

    # -- line level -----------------------------------------------------------------------
    def encode_line(self, position: int, error: bool = False, warning: bool = False,
                    ready_bits: int = 1, ack_bits: int = 1, timeout_bits: int = 1
                    ) -> tuple[int, ...]:
        """SLO samples on successive MA rising edges for one read cycle.

        ``ready_bits`` ones (SLO idle high), ``ack_bits`` zeros (Ack: the encoder needs
        time to latch), the frame, then ``timeout_bits`` zeros (SLO held low until ready).
        """
        ready_bits = as_int(ready_bits, "ready_bits", 0, MAX_LINE_BITS)
        ack_bits = as_int(ack_bits, "ack_bits", 1, MAX_LINE_BITS)
        timeout_bits = as_int(timeout_bits, "timeout_bits", 0, MAX_LINE_BITS)
        word = self.encode(position, error, warning)
        n = self.frame_bits
        frame = tuple((word >> i) & 1 for i in range(n - 1, -1, -1))
        return (1,) * ready_bits + (0,) * ack_bits + frame + (0,) * timeout_bits

    def decode_line(self, samples: Sequence[object]) -> BissReading:
        """Find the frame in sampled SLO levels (ready ones, Ack zeros, Start...) and decode.

        Raises :class:`FrameError` if there is no Ack, no Start or too few bits, or
        ``samples`` is not a sequence.
        """
        n_samples = len(as_sequence(samples, "BiSS SLO samples"))
        i = 0
        # Skip the ready (high) level, then at least one Ack zero, then expect Start.
        while i < n_samples and _bit(samples[i]) == 1:
            i += 1
        ack_start = i
        while i < n_samples and _bit(samples[i]) == 0:
            i += 1
        if i == ack_start:
            raise FrameError("no Ack (SLO never went low)")
        if i >= n_samples:
            raise FrameError("no Start bit after the Ack")
        n = self.frame_bits
        if i + n > n_samples:
            raise FrameError(f"frame truncated: need {n} bits from Start, have {n_samples - i}")
        word = 0
        for k in range(i, i + n):
            word = (word << 1) | _bit(samples[k])
        return self.decode(word)

    # -- batch ----------------------------------------------------------------------------
    def encode_array(self, position: np.ndarray, error: np.ndarray | bool = False,
                     warning: np.ndarray | bool = False) -> np.ndarray:
        """Vectorised :meth:`encode`: uint64 frame words."""
        pos = as_int_array(position, "BiSS positions", 0, (1 << self.position_bits) - 1)
        flags = [as_int_array(f, f"BiSS {what} flags", 0, 1)
                 for f, what in ((error, "error"), (warning, "warning"))]
        try:
            ne, nw = (np.logical_not(np.broadcast_to(f, pos.shape)).astype(np.uint64)
                      for f in flags)
        except ValueError:
            raise RangeError(f"BiSS flags of shape {flags[0].shape}/{flags[1].shape} do not "
                             f"match positions of shape {pos.shape}") from None
        return self.layout.pack_array(pos, ne, nw)

    def decode_array(self, words: np.ndarray) -> BissBatch:
        """Vectorised :meth:`decode` of a uint64 array of logged frame words.

        Never raises for bad frames: ``valid`` marks frames whose framing and CRC are right;
        ``position``, ``error`` and ``warning`` are only meaningful where it is true.
        """
        vals, frame_ok, crc_ok = self.layout.unpack_array(words)
        return BissBatch(vals["position"], vals["n_error"] == 0, vals["n_warning"] == 0,
                         frame_ok & crc_ok, frame_ok & ~crc_ok)


class BissBatch(NamedTuple):
    """Decoded arrays of a batch of BiSS frames."""

    position: np.ndarray  # uint64 counts
    error: np.ndarray  # bool, True = error reported (nE = 0)
    warning: np.ndarray  # bool, True = warning reported (nW = 0)
    valid: np.ndarray  # bool, framing and CRC right
    crc_failed: np.ndarray  # bool, framing right but CRC wrong


def _bit(sample: object) -> int:
    b = as_index(sample, "SLO sample")
    if b not in (0, 1):
        raise FrameError(f"SLO sample {b} is neither 0 nor 1")
    return b


def linear_position_m(counts: int) -> float:
    """Linear RESOLUTE position in metres from counts (5 nm per count)."""
    return as_int(counts, "counts") * LINEAR_COUNT_M


def counts_from_linear_m(x_m: float, position_bits: int) -> int:
    """Counts for a linear position in metres, rounded to nearest; RangeError off scale."""
    position_bits = as_int(position_bits, "position_bits", 1, 64)
    c = round(finite_number(x_m, "x_m") / LINEAR_COUNT_M)
    if not 0 <= c < (1 << position_bits):
        raise RangeError(f"{x_m} m outside the {position_bits}-bit scale")
    return c
