"""The motor encoder: RLS RMB30SI, absolute angle over SSI plus an incremental ABI output.

Value level (compiled): ``ssi_count`` = floor((theta_m + mount) N / 2 pi) mod N with
N = 2^ssi_bits; ``abi_count`` = floor(theta_m N_abi / 2 pi), kept by the board as a 16-bit
counter value. Line level: :class:`MotorEncoderLines` presents the SSI frame to an
:class:`~protocols.ssi.SsiSlave` and walks the A/B quadrature states. Fault knobs:
``ssi_stuck`` (data line held at 0/1), ``ssi_flip_mask`` (XOR into the next frame,
one-shot), and at value level the ``K_MOTOR_DEAD`` flag (no valid frame).

A small epsilon (1e-7 count) before each floor keeps an angle that the plant's own
quantisation (``effects.quantisation``, :mod:`plant.sensors.readings`) has already put on a
whole count on that count despite float rounding.
"""

from __future__ import annotations

import math

from numba import njit

from plant.sensors.chips import K_ABI_N, K_SSI_MOUNT, K_SSI_N, TWO_PI
from protocols.abi import ab_from_count
from protocols.ssi import SsiCodec, SsiSlave

EPS_COUNT = 1e-7


@njit(cache=True)
def ssi_count(theta_m, k):
    n = k[K_SSI_N]
    return int(math.floor(theta_m * n / TWO_PI + k[K_SSI_MOUNT] + EPS_COUNT)) % int(n)


@njit(cache=True)
def abi_count(theta_m, k):
    return int(math.floor(theta_m * k[K_ABI_N] / TWO_PI + EPS_COUNT))


class FaultySsiSlave(SsiSlave):
    """An :class:`SsiSlave` whose data line can be held low or high (``stuck``)."""

    def __init__(self, frame_bits: int, monoflop_ns: int = 20_000) -> None:
        super().__init__(frame_bits, monoflop_ns)
        #: None: healthy; 0 or 1: the data line reads this level whatever the encoder does.
        self.stuck: int | None = None

    def data_at(self, t_ns: int) -> int:
        """Data line level at ``t_ns`` (the stuck level if a fault is set)."""
        level = super().data_at(t_ns)
        return level if self.stuck is None else self.stuck

    def step(self, t_ns: int, clock: int) -> int:
        """Apply a clock level; the encoder shifts on as usual, the line may be stuck."""
        level = super().step(t_ns, clock)
        return level if self.stuck is None else self.stuck


class MotorEncoderLines:
    """The encoder's SSI slave and A/B lines. The FPGA's quadrature counter was zeroed with
    the encoder at count 0 (theta_m = 0), as the value level counts from there."""

    def __init__(self, codec: SsiCodec, monoflop_ns: int) -> None:
        self.codec = codec
        self.ssi = FaultySsiSlave(codec.frame_bits, monoflop_ns)
        self.abi_levels: list[tuple[int, int]] = []
        self._abi = 0
        self.ssi_flip_mask = 0

    def update(self, theta_m: float, k) -> None:  # noqa: ANN001
        # SSI: the frame the encoder latches on the master's first falling edge.
        word = self.codec.encode(ssi_count(theta_m, k))
        if self.ssi_flip_mask:
            word ^= self.ssi_flip_mask
            self.ssi_flip_mask = 0
        self.ssi.present(word)
        # ABI: walk the quadrature states one count at a time so no edge is skipped.
        c = abi_count(theta_m, k)
        prev = self._abi
        if c > prev:
            self.abi_levels = [ab_from_count(n) for n in range(prev + 1, c + 1)]
        elif c < prev:
            self.abi_levels = [ab_from_count(n) for n in range(prev - 1, c - 1, -1)]
        else:
            self.abi_levels = []
        self._abi = c
