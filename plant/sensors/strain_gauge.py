"""The strain-gauge bridge on the connecting rod and its AD7195 (24-bit, SPI).

Value level (compiled): bipolar code = floor(F 2^23 / F_FS + 2^23 + 1/2), saturated (as
:func:`protocols.ad7195.clamp_force_to_code`), a new conversion every 1/ODR
(:func:`strain_conversions`, exact on the integer clock); a clamped conversion carries the
ERR status bit, so the board's master rejects it. Line level: :class:`StrainAdcLine`, an
:class:`~protocols.ad7195.AD7195Device` given each conversion result, read over SPI when
DOUT/RDY is low. Fault knob: ``flip_mask``, XOR into the 32-bit code+status word of the next
data read (one-shot): 0x40 ERR, 0x80 /RDY (stale), 0x100 a data bit (parity error).
Temperature drift of the bridge is physics (the rod's temperature, ``effects.strain_drift``)
and stays in the plant.
"""

from __future__ import annotations

import math

from numba import njit

from plant.sensors.chips import K_ODR, K_STRAIN_SCALE, K_TICK_NS
from protocols.ad7195 import CMD_READ_DATA, CODE_MAX, MIDSCALE, AD7195Device

#: Bytes of an AD7195 data read with DAT_STA: comms byte + 3 code bytes + status.
_STRAIN_READ_LEN = 5


@njit(cache=True)
def strain_conversions(tick, k):
    """AD7195 conversions completed by the end of ``tick`` (integer clock, exact)."""
    return (tick * int(k[K_TICK_NS]) * int(k[K_ODR])) // 1_000_000_000


@njit(cache=True)
def strain_code(force_n, k):
    x = force_n * k[K_STRAIN_SCALE] + MIDSCALE
    if x < -0.5:
        return 0
    if x >= CODE_MAX + 0.5:
        return CODE_MAX
    return int(math.floor(x + 0.5))


@njit(cache=True)
def strain_clamped(force_n, k):
    """True when the AD7195 clamps this force to 0 or CODE_MAX: the part then sets ERR in
    its status byte and the board's master rejects the read (strain_ok = 0)."""
    x = force_n * k[K_STRAIN_SCALE] + MIDSCALE
    return x < -0.5 or x >= CODE_MAX + 0.5


def zero_code_force(k) -> float:  # noqa: ANN001
    """A force the AD7195 reads as code 0 (a dead bridge, for fault injection)."""
    return -(MIDSCALE + 1.0) / k[K_STRAIN_SCALE]


class StrainAdcLine:
    """The AD7195 on the board's SPI bus."""

    def __init__(self, full_scale_n: float) -> None:
        self.device = AD7195Device(full_scale_n=full_scale_n)
        self.flip_mask = 0

    @property
    def rdy_n(self) -> int:
        """DOUT/RDY level: 0 while an unread conversion result waits."""
        return 0 if self.device.ready else 1

    def transfer(self, data: bytes) -> bytes:
        """SPI bytes (DIN in, DOUT out); applies ``flip_mask`` to a data read."""
        out = self.device.transfer(data)
        mask = self.flip_mask
        if mask and len(data) == _STRAIN_READ_LEN and data[0] == CMD_READ_DATA:
            self.flip_mask = 0
            word = int.from_bytes(out[1:], "big") ^ (mask & 0xFFFFFFFF)
            out = out[:1] + word.to_bytes(4, "big")
        return out

    def update(self, force_n: float, tick: int, k) -> None:  # noqa: ANN001
        """A conversion that completed during ``tick`` replaces the data register."""
        if strain_conversions(tick, k) != strain_conversions(tick - 1, k):
            self.device.set_code(strain_code(force_n, k), err=strain_clamped(force_n, k))
