"""SSI of the RLS RMB30SI motor encoder: value-level codec and a bit-level transfer model.

Value level
    A frame is ``lead zeros | position | status | parity`` (MSB first, see
    :mod:`protocols.bits`); every part but the position is optional. Defaults, because the
    RMB30 data sheet does not confirm them for the 2048-count option: 11 position bits
    (2048 counts/rev), natural binary, no lead zeros, no status bits, no parity. All are
    set by :class:`SsiFormat`.

Bit level
    :class:`SsiSlave` is the encoder's output stage as a pure state machine over clock
    events ``(t_ns, level)``: the clock idles high; the first falling edge latches the
    position and starts the monoflop; each rising edge shifts out the next bit, MSB on the
    first; after the LSB the data line goes low, and it returns high (ready) when the
    monoflop time ``tm`` has passed without a clock edge. :class:`SsiMaster` produces the
    clock train and samples the data line on the falling edges from the second on. Times
    are integer nanoseconds given by the caller; nothing here reads a clock.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from protocols.bits import Layout, check, const, gray_decode, gray_encode, value
from protocols.crc import PARITY_EVEN, PARITY_ODD
from protocols.errors import FrameError, RangeError, as_bit, as_int, as_int_array

#: RMB30SI resolution used on the Hydra motor (counts per revolution).
COUNTS_PER_REV = 2048


@dataclass(frozen=True)
class SsiFormat:
    """Frame format of an SSI encoder. Defaults: RMB30SI, 2048 counts/rev (assumed).

    ``lead_zeros``: zero bits sent before the position (frames padded to a fixed length);
    ``status_bits``: raw status bits after the position (meaning is device specific);
    ``gray``: position in Gray code instead of natural binary;
    ``parity``: "none", "even" or "odd" parity bit over position + status, sent last.
    """

    position_bits: int = 11
    lead_zeros: int = 0
    status_bits: int = 0
    gray: bool = False
    parity: str = "none"

    def __post_init__(self) -> None:
        as_int(self.position_bits, "position_bits", 1, 32)
        as_int(self.lead_zeros, "lead_zeros", 0, 64)
        as_int(self.status_bits, "status_bits", 0, 64)
        as_bit(self.gray, "gray", RangeError)
        if self.parity not in ("none", "even", "odd"):
            raise RangeError("parity must be 'none', 'even' or 'odd'")
        if self.frame_bits > 64:
            raise RangeError("SSI frame longer than 64 bits")

    @property
    def frame_bits(self) -> int:
        """Bits clocked out per frame (excluding the trailing low level)."""
        return (self.lead_zeros + self.position_bits + self.status_bits
                + (self.parity != "none"))


def frame_layout(fmt: SsiFormat) -> Layout:
    """The declared SSI frame for a format."""
    fields = []
    if fmt.lead_zeros:
        fields.append(const("lead", fmt.lead_zeros, 0, "leading zeros (padding)"))
    coding = "Gray code" if fmt.gray else "natural binary"
    fields.append(value("position", fmt.position_bits, f"position, {coding}, MSB first"))
    covered = ["position"]
    if fmt.status_bits:
        fields.append(value("status", fmt.status_bits, "status bits (device specific)"))
        covered.append("status")
    if fmt.parity != "none":
        crc = PARITY_EVEN if fmt.parity == "even" else PARITY_ODD
        fields.append(check("parity", crc, covered, f"{fmt.parity} parity over position+status"))
    return Layout(f"SSI/{fmt.frame_bits}", fields)


class SsiReading(NamedTuple):
    """One decoded SSI frame: position in counts (binary) and the raw status bits."""

    position: int
    status: int


class SsiBatch(NamedTuple):
    """Decoded arrays of a batch of SSI frames (meaningful where ``valid``)."""

    position: np.ndarray  # uint64 counts, natural binary
    status: np.ndarray  # uint64 raw status bits (zeros if the format has none)
    valid: np.ndarray  # bool: padding and parity right


class SsiCodec:
    """Value-level SSI codec for one :class:`SsiFormat`."""

    __slots__ = ("fmt", "layout", "_gray", "_has_status", "_pbits")

    def __init__(self, fmt: SsiFormat | None = None) -> None:
        self.fmt = fmt or SsiFormat()
        self.layout = frame_layout(self.fmt)
        self._gray = self.fmt.gray
        self._has_status = self.fmt.status_bits > 0
        self._pbits = self.fmt.position_bits

    def __repr__(self) -> str:
        return f"SsiCodec({self.fmt!r})"

    @property
    def frame_bits(self) -> int:
        """Bits per frame."""
        return self.layout.width

    def encode(self, position: int, status: int = 0) -> int:
        """Frame word for a position in counts (0 .. 2^position_bits - 1) and status."""
        if self._gray:
            # Range-check before Gray coding, which would otherwise hide a negative value.
            if position.__class__ is not int:
                try:
                    position = operator.index(position)
                except TypeError:
                    raise RangeError(f"position {position!r} is not an integer") from None
            if position < 0 or position >> self._pbits:
                raise RangeError(f"position {position} does not fit in {self._pbits} bits")
            position ^= position >> 1
        if status.__class__ is not int:
            status = as_int(status, "SSI status")
        if self._has_status:
            return self.layout.pack(position, status)
        if status:
            raise RangeError("this SSI format has no status bits")
        return self.layout.pack(position)

    def decode(self, word: object) -> SsiReading:
        """Decode a frame word; FrameError on bad width/padding, CrcError on bad parity."""
        vals = self.layout.unpack(word)
        pos = gray_decode(vals[0], self._pbits) if self._gray else vals[0]
        return SsiReading(pos, vals[1] if self._has_status else 0)

    def encode_array(self, position: np.ndarray, status: np.ndarray | int = 0) -> np.ndarray:
        """Vectorised :meth:`encode` -> uint64 frame words."""
        pos = as_int_array(position, "SSI positions", 0, (1 << self._pbits) - 1)
        pos = pos.astype(np.uint64)
        if self._gray:
            pos = gray_encode(pos)
        if self._has_status:
            return self.layout.pack_array(pos, np.broadcast_to(status, pos.shape))
        return self.layout.pack_array(pos)

    def decode_array(self, words: np.ndarray) -> SsiBatch:
        """Vectorised :meth:`decode` of a uint64 array; never raises for bad frames."""
        vals, frame_ok, crc_ok = self.layout.unpack_array(words)
        pos = vals["position"]
        if self._gray:
            pos = gray_decode(pos, self._pbits)
        status = vals["status"] if self._has_status else np.zeros_like(pos)
        return SsiBatch(pos, status, frame_ok & crc_ok)


# -- bit-level model of the clocked transfer ------------------------------------------------
@dataclass(frozen=True)
class SsiTiming:
    """Clock and monoflop of the link, integer nanoseconds. Defaults are assumptions.

    ``clock_hz`` 1 MHz (typical SSI masters run 80 kHz - 1.5 MHz; RMB30 maximum not
    confirmed, hence ``max_clock_hz`` = 1.5 MHz); ``monoflop_ns`` tm = 20 us (typical),
    which must exceed one clock period.
    """

    clock_hz: int = 1_000_000
    monoflop_ns: int = 20_000
    max_clock_hz: int = 1_500_000

    def __post_init__(self) -> None:
        as_int(self.max_clock_hz, "max_clock_hz", 1)
        as_int(self.clock_hz, "clock_hz", 1, self.max_clock_hz)
        as_int(self.monoflop_ns, "monoflop_ns", 1)
        if not 0 < self.clock_hz <= self.max_clock_hz:
            raise RangeError(f"clock {self.clock_hz} Hz outside 0..{self.max_clock_hz} Hz")
        if self.monoflop_ns <= 2 * self.half_period_ns:
            # The monoflop is retriggered by every clock edge; if tm were shorter than a
            # clock period it would expire mid-frame and the encoder would drop out.
            raise RangeError("monoflop time must exceed one clock period")

    @property
    def half_period_ns(self) -> int:
        """Half clock period, ns (rounded up so the clock never exceeds ``clock_hz``)."""
        return -(-1_000_000_000 // (2 * self.clock_hz))


class SsiSlave:
    """Encoder-side SSI shift register driven by clock events; pure and deterministic.

    Call :meth:`present` with the frame word the encoder would latch now, then feed clock
    levels with :meth:`step` in non-decreasing time order. :meth:`data_at` gives the data
    line level at any time (the monoflop may expire between events).
    """

    def __init__(self, frame_bits: int, monoflop_ns: int = 20_000) -> None:
        frame_bits = as_int(frame_bits, "frame_bits", 1, 64)
        monoflop_ns = as_int(monoflop_ns, "monoflop_ns", 1)
        self.frame_bits = frame_bits
        self.monoflop_ns = monoflop_ns
        self.clock = 1  # idles high
        self.data = 1  # idles high = ready
        self.busy = False  # monoflop running
        self.latches = 0  # frames latched so far
        self._present = 0
        self._frame = 0
        self._sent = 0
        self._last_edge_ns: int | None = None
        self._t_ns = 0

    def present(self, word: int) -> None:
        """Set the frame the encoder would latch on its next first falling edge."""
        if word.__class__ is not int:
            word = as_int(word, "SSI frame word")
        if word < 0 or word >> self.frame_bits:
            raise RangeError("word does not fit the frame")
        self._present = word

    def _expire(self, t_ns: int) -> None:
        # The monoflop times out tm after the last clock edge: line back high, ready.
        if self.busy and self._last_edge_ns is not None and t_ns - self._last_edge_ns >= (
                self.monoflop_ns):
            self.busy = False
            self.data = 1

    def data_at(self, t_ns: int) -> int:
        """Data line level at time ``t_ns`` (no clock edge at that instant)."""
        if t_ns.__class__ is not int:
            t_ns = as_int(t_ns, "time t_ns")
        if t_ns < self._t_ns:
            raise RangeError("time went backwards")
        self._expire(t_ns)
        self._t_ns = t_ns
        return self.data

    def step(self, t_ns: int, clock: int) -> int:
        """Apply clock level ``clock`` at ``t_ns``; return the data level just after."""
        if clock.__class__ is not int or not (clock == 0 or clock == 1):
            clock = as_bit(clock, "SSI clock level")
        self.data_at(t_ns)
        if clock == self.clock:
            return self.data
        self.clock = clock
        self._last_edge_ns = t_ns
        if clock == 0:
            if not self.busy:
                # First falling edge: latch the position, start the monoflop.
                self.busy = True
                self.latches += 1
                self._frame = self._present
                self._sent = 0
        elif self.busy:
            if self._sent < self.frame_bits:
                self.data = (self._frame >> (self.frame_bits - 1 - self._sent)) & 1
                self._sent += 1
            else:
                self.data = 0  # after the LSB the line goes low until tm expires
        return self.data


class SsiMaster:
    """Master side: generates the clock train for one frame and samples the data line."""

    def __init__(self, frame_bits: int, timing: SsiTiming | None = None) -> None:
        self.frame_bits = as_int(frame_bits, "frame_bits", 1, 64)
        self.timing = timing or SsiTiming()

    def clock_train(self, t0_ns: int) -> list[tuple[int, int]]:
        """Clock events (t_ns, level) for one frame starting at ``t0_ns``.

        ``frame_bits + 1`` periods: falling edge 1 latches, rising edge k puts out bit k,
        falling edge k + 1 samples it, the last rising edge makes the line go low.
        """
        t0_ns = as_int(t0_ns, "start time t0_ns")
        h = self.timing.half_period_ns
        events = []
        for k in range(self.frame_bits + 1):
            events.append((t0_ns + 2 * k * h, 0))
            events.append((t0_ns + (2 * k + 1) * h, 1))
        return events

    def read(self, slave: SsiSlave, t0_ns: int) -> tuple[int, int]:
        """Clock one frame out of ``slave``; return (frame word, earliest next start, ns).

        Raises :class:`FrameError` if the line is not high before the first edge (encoder
        busy: the monoflop of the previous read has not expired, or line stuck low) or not
        low after the LSB (missing end of frame: line stuck high or frame length wrong).
        """
        if slave.data_at(t0_ns) != 1:
            raise FrameError("SSI data line low before the clock: encoder not ready")
        word = 0
        events = self.clock_train(t0_ns)
        for i, (t, level) in enumerate(events):
            if level == 0 and i >= 2:
                # Sample just before the falling edge: the bit set by the previous rising edge.
                word = (word << 1) | slave.data_at(t)
            slave.step(t, level)
        t_last = events[-1][0]
        if slave.data_at(t_last + self.timing.half_period_ns) != 0:
            raise FrameError("SSI data line not low after the LSB")
        return word, t_last + self.timing.monoflop_ns
