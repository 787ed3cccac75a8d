"""The piston encoder: Renishaw RESOLUTE linear, 5 nm, over BiSS-C.

Value level (compiled): count = floor(x / 5 nm) + zero count, modulo 2^bits. Line level:
:class:`PistonEncoderLine` gives the SLO samples of one read cycle (ready, Ack, frame,
timeout). Fault knobs: ``biss_flip_mask`` (XOR into the next frame Start..CRC, bit 0 = the
last CRC bit, one-shot; :meth:`~PistonEncoderLine.corrupt_crc`), ``biss_error_frames``
(the next n frames carry the error bit, nE low), and at value level ``K_PISTON_DEAD``.
"""

from __future__ import annotations

import math

from numba import njit

from plant.sensors.chips import K_BISS_MOD, K_BISS_ZERO
from plant.sensors.motor_encoder import EPS_COUNT
from protocols.biss import LINEAR_COUNT_M, BissCodec
from protocols.errors import RangeError

#: BiSS read cycle shape: SLO high before the cycle, Ack zeros, timeout zeros (MA periods).
BISS_READY_BITS = 1
BISS_ACK_BITS = 1
BISS_TIMEOUT_BITS = 1


@njit(cache=True)
def biss_count(x_m, k):
    c = int(math.floor(x_m / LINEAR_COUNT_M + EPS_COUNT)) + int(k[K_BISS_ZERO])
    return c % int(k[K_BISS_MOD])


class PistonEncoderLine:
    """The encoder's SLO line for the board's BiSS master."""

    def __init__(self, bits: int) -> None:
        self.codec = BissCodec(bits)
        self.samples: tuple[int, ...] = ()
        self.flip_mask = 0
        self.error_frames = 0

    def corrupt_crc(self) -> None:
        """Flip the last CRC bit of the next frame."""
        self.flip_mask ^= 1

    def update(self, x_m: float, k) -> None:  # noqa: ANN001
        error = self.error_frames > 0
        if error:
            self.error_frames -= 1
        line = self.codec.encode_line(
            biss_count(x_m, k), error=error, ready_bits=BISS_READY_BITS,
            ack_bits=BISS_ACK_BITS, timeout_bits=BISS_TIMEOUT_BITS)
        if self.flip_mask:
            line = self._flip(line, self.flip_mask)
            self.flip_mask = 0
        self.samples = line

    def _flip(self, line: tuple[int, ...], mask: int) -> tuple[int, ...]:
        n = self.codec.frame_bits
        if mask >> n:
            raise RangeError(f"BiSS flip mask {mask:#x} wider than the {n}-bit frame")
        start = BISS_READY_BITS + BISS_ACK_BITS  # index of the Start bit
        out = list(line)
        for i in range(n):
            if (mask >> i) & 1:
                out[start + n - 1 - i] ^= 1
        return tuple(out)
