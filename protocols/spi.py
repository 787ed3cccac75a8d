"""SPI at the bit and line level: bytes <-> bit sequences <-> sampled waveforms.

Three layers, all pure:

* :func:`bytes_to_bits` / :func:`bits_to_bytes` — a byte string as the sequence of bits that
  travels on one data line (MSB first by default, as the AD7195 and most SPI parts).
* :func:`encode_waveform` / :func:`decode_waveform` — the four lines ``(cs_n, sclk, mosi,
  miso)`` as a list of samples, one sample after every line change, for any of the four SPI
  modes. Decoding samples each data line on the mode's sampling edge, so the pair is a codec
  for "what a logic analyser would see".
* :func:`exchange_bits` / :func:`transfer_waveform` — clock a :class:`SpiSlave` state machine
  bit by bit, the way a master's shift register does.

Mode semantics (Motorola SPI): CPOL is the SCLK idle level; with CPHA = 0 data is sampled on
the leading (first) edge of each clock pulse and shifted on the trailing edge, with CPHA = 1
data is shifted on the leading edge and sampled on the trailing edge. Mode 3 (CPOL = 1,
CPHA = 1, used by the AD7195): SCLK idles high, both sides shift on the falling edge and
sample on the rising edge.
"""

from __future__ import annotations

import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

from protocols.errors import FrameError, RangeError, as_bytes, as_iterable, as_sequence

__all__ = [
    "SpiMode",
    "MODE0",
    "MODE1",
    "MODE2",
    "MODE3",
    "Sample",
    "SpiSlave",
    "bytes_to_bits",
    "bits_to_bytes",
    "encode_waveform",
    "decode_waveform",
    "exchange_bits",
    "exchange_bytes",
    "transfer_waveform",
]


@dataclass(frozen=True)
class SpiMode:
    """Clock polarity/phase and bit order of an SPI link.

    ``cpol``: SCLK level when idle (0 or 1). ``cpha``: 0 = sample on the leading edge,
    1 = sample on the trailing edge. ``msb_first``: bit order within each byte.
    """

    cpol: int
    cpha: int
    msb_first: bool = True

    def __post_init__(self) -> None:
        if self.cpol not in (0, 1) or self.cpha not in (0, 1):
            raise RangeError(f"cpol/cpha must be 0 or 1, got {self.cpol}/{self.cpha}")

    @property
    def number(self) -> int:
        """Conventional mode number 0..3 (``2 * cpol + cpha``)."""
        return 2 * self.cpol + self.cpha


MODE0 = SpiMode(0, 0)
MODE1 = SpiMode(0, 1)
MODE2 = SpiMode(1, 0)
MODE3 = SpiMode(1, 1)


class Sample(NamedTuple):
    """Logic levels of the four SPI lines after one event (0 = low, 1 = high)."""

    cs_n: int
    sclk: int
    mosi: int
    miso: int


class SpiSlave(Protocol):
    """A device clocked bit by bit.

    ``clock(din)`` is one SCLK period: the device first decides the bit it drives on DOUT
    for this period (it is shifted out on the shift edge, before the sampling edge, so it
    cannot depend on ``din``), then samples ``din`` on the sampling edge. Returns the DOUT bit.
    """

    def clock(self, din: int) -> int: ...


def _level(value: object, what: str) -> int:
    """Return ``value`` as a plain int 0/1 or raise :class:`FrameError`."""
    try:
        level = operator.index(value)  # type: ignore[arg-type]
    except TypeError as exc:
        raise FrameError(f"{what}: {value!r} is not a logic level") from exc
    if level not in (0, 1):
        raise FrameError(f"{what}: level {level!r} is not 0 or 1")
    return level


def _check_bits(bits: Sequence[int], what: str) -> list[int]:
    return [_level(b, what) for b in as_iterable(bits, what)]


def bytes_to_bits(data: bytes, msb_first: bool = True) -> list[int]:
    """Return the bits of ``data`` in transmission order (8 per byte)."""
    order = range(7, -1, -1) if msb_first else range(8)
    return [(byte >> i) & 1 for byte in as_bytes(data, "SPI data") for i in order]


def bits_to_bytes(bits: Sequence[int], msb_first: bool = True) -> bytes:
    """Pack bits in transmission order back into bytes.

    Raises :class:`FrameError` if the count is not a multiple of 8 or a bit is not 0/1.
    """
    if len(as_sequence(bits, "bits_to_bytes")) % 8:
        raise FrameError(f"{len(bits)} bits is not a whole number of bytes")
    bits = _check_bits(bits, "bits_to_bytes")
    out = bytearray()
    for k in range(0, len(bits), 8):
        chunk = bits[k : k + 8]
        if not msb_first:
            chunk = chunk[::-1]
        value = 0
        for b in chunk:
            value = (value << 1) | b
        out.append(value)
    return bytes(out)


def encode_waveform(
    mosi_bits: Sequence[int], miso_bits: Sequence[int], mode: SpiMode = MODE3
) -> list[Sample]:
    """Return the sampled line levels of one chip-select frame carrying the given bits.

    The frame starts and ends with CS high and SCLK idle; data lines are shifted on the
    mode's shift edge and stable across its sampling edge. Lines not yet driven sit at 1
    (pulled up). Both sequences must have the same length.
    """
    mosi_bits = as_sequence(mosi_bits, "mosi", RangeError)
    miso_bits = as_sequence(miso_bits, "miso", RangeError)
    if len(mosi_bits) != len(miso_bits):
        raise RangeError("mosi and miso must carry the same number of bits")
    mosi_bits = _check_bits(mosi_bits, "mosi")
    miso_bits = _check_bits(miso_bits, "miso")
    idle, active = mode.cpol, 1 - mode.cpol
    n = len(mosi_bits)
    out = [Sample(1, idle, 1, 1)]
    if n == 0:
        out.append(Sample(0, idle, 1, 1))
        out.append(Sample(1, idle, 1, 1))
        return out
    if mode.cpha == 0:
        # First bit must be on the lines before the first (sampling) edge: set at CS fall.
        out.append(Sample(0, idle, mosi_bits[0], miso_bits[0]))
        for i in range(n):
            out.append(Sample(0, active, mosi_bits[i], miso_bits[i]))  # sample
            j = i + 1 if i + 1 < n else i
            out.append(Sample(0, idle, mosi_bits[j], miso_bits[j]))  # shift next
        last = n - 1
        out.append(Sample(1, idle, mosi_bits[last], miso_bits[last]))
    else:
        out.append(Sample(0, idle, 1, 1))
        for i in range(n):
            out.append(Sample(0, active, mosi_bits[i], miso_bits[i]))  # shift
            out.append(Sample(0, idle, mosi_bits[i], miso_bits[i]))  # sample
        out.append(Sample(1, idle, mosi_bits[-1], miso_bits[-1]))
    return out


def decode_waveform(
    samples: Iterable[Sequence[int]], mode: SpiMode = MODE3
) -> tuple[list[int], list[int]]:
    """Recover ``(mosi_bits, miso_bits)`` from sampled line levels.

    Each sample is ``(cs_n, sclk, mosi, miso)``. Bits are taken on every sampling edge while
    CS is low. Raises :class:`FrameError` if a level is not 0/1, a sample has the wrong
    shape, or SCLK is not at its idle level when CS changes (a master glitch that would
    shift the slave by a bit).
    """
    idle = mode.cpol
    sample_on_leading = mode.cpha == 0
    mosi: list[int] = []
    miso: list[int] = []
    prev_cs: int | None = None
    prev_clk: int | None = None
    for s in as_iterable(samples, "SPI samples"):
        try:
            cs_n, sclk, d_mosi, d_miso = s
        except (TypeError, ValueError) as exc:
            raise FrameError(f"sample {s!r} is not (cs_n, sclk, mosi, miso)") from exc
        cs_n, sclk = _level(cs_n, "cs_n"), _level(sclk, "sclk")
        d_mosi, d_miso = _level(d_mosi, "mosi"), _level(d_miso, "miso")
        if prev_cs is not None and cs_n != prev_cs and (sclk != idle or prev_clk != idle):
            raise FrameError("SCLK not idle while chip select changes")
        if cs_n == 0 and prev_cs == 0 and prev_clk is not None and sclk != prev_clk:
            leading = prev_clk == idle
            if leading == sample_on_leading:
                mosi.append(d_mosi)
                miso.append(d_miso)
        if prev_cs is None and cs_n == 0 and sclk != idle:
            raise FrameError("capture starts inside a frame with SCLK active")
        prev_cs, prev_clk = cs_n, sclk
    return mosi, miso


def exchange_bits(slave: SpiSlave, mosi_bits: Iterable[int]) -> list[int]:
    """Clock ``slave`` once per MOSI bit; return the bits it drove on MISO."""
    return [slave.clock(b) for b in _check_bits(mosi_bits, "mosi")]


def exchange_bytes(slave: SpiSlave, data: bytes, msb_first: bool = True) -> bytes:
    """Full-duplex transfer of ``data`` through a bit-clocked ``slave`` (bit-level path)."""
    return bits_to_bytes(exchange_bits(slave, bytes_to_bits(data, msb_first)), msb_first)


def transfer_waveform(
    slave: SpiSlave, mosi_bits: Sequence[int], mode: SpiMode = MODE3
) -> list[Sample]:
    """Drive ``slave`` with ``mosi_bits`` and return the resulting four-line waveform."""
    miso_bits = exchange_bits(slave, mosi_bits)
    return encode_waveform(list(mosi_bits), miso_bits, mode)
