"""The LVDS link word between the FPGA driver board and the MCU board (thesis 6.3.1).

The thesis gives only "a custom protocol with a start word, address, data, and CRC" over a
full-duplex LVDS pair, with two shared memory spaces (up: FPGA -> MCU, down: MCU -> FPGA)
swept word by word. Each direction is its own line, so a word needs no direction bit.
The widths and coding below are our choice (docs/protocols-links.md says why).

One word is 45 bits, MSB first (see :mod:`protocols.bits`)::

    111111111 | 0 addr[7:0] | 0 data[15:8] | 0 data[7:0] | 0 crc[7:0]
    start(9)    spacer+byte   spacer+byte    spacer+byte   spacer+byte

* start word: nine ones; every payload byte is preceded by a spacer 0, so the payload
  never holds more than eight ones in a row and "nine ones then a zero" occurs in an
  error-free stream only at the start of a word. Alignment is therefore unambiguous.
* address: 8 bits (256 words of 16 bits per shared-memory space).
* data: 16 bits (the FPGA's native fixed-point word: currents, angles, PWM duties).
* crc: CRC-8/AUTOSAR (x^8+x^5+x^3+x^2+x+1, init 0xFF, xorout 0xFF) over the three payload
  bytes addr, data_hi, data_lo. Hamming distance 4 at this length (24 data bits): every
  1-, 2- and 3-bit error in the word is detected, and so is every odd number of errors
  (the generator has the factor x + 1) and every burst of up to 8 bits. The non-zero
  init/xorout make an all-zero payload an invalid word.

:class:`LvdsStreamDecoder` finds words in a raw bit stream, drops words that fail and
counts them, and recovers alignment after a slip or burst within one word.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from protocols.bits import Layout, as_index, bits_from_words, check, const, value
from protocols.crc import CRC8_AUTOSAR
from protocols.errors import CodecError, CrcError, FrameError, RangeError, as_int_array, as_iterable

ADDR_BITS = 8
DATA_BITS = 16
START_BITS = 9

LAYOUT = Layout("LVDS word", [
    const("start", START_BITS, (1 << START_BITS) - 1, "start word: nine ones"),
    const("sp0", 1, 0, "spacer"),
    value("addr", ADDR_BITS, "address in the shared-memory space, MSB first"),
    const("sp1", 1, 0, "spacer"),
    value("data_hi", 8, "data bits 15..8"),
    const("sp2", 1, 0, "spacer"),
    value("data_lo", 8, "data bits 7..0"),
    const("sp3", 1, 0, "spacer"),
    check("crc", CRC8_AUTOSAR, ("addr", "data_hi", "data_lo"),
          "CRC-8/AUTOSAR over the bytes addr, data_hi, data_lo"),
])

#: Bits per word on the line.
WORD_BITS = LAYOUT.width
#: What marks a word start in the bit stream: the start word and the first spacer.
SYNC_TEXT = "1" * START_BITS + "0"

_pack = LAYOUT.pack
_unpack = LAYOUT.unpack


class LinkWord(NamedTuple):
    """One decoded word: ``addr`` 0..255, ``data`` 0..65535 (raw 16-bit word)."""

    addr: int
    data: int


def encode_word(addr: int, data: int) -> int:
    """The 45-bit line word for one (address, data) pair; RangeError if out of range."""
    if data.__class__ is not int:
        try:
            data = as_index(data)
        except FrameError:
            raise RangeError(f"data {data!r} is not an integer") from None
    if data < 0 or data >> DATA_BITS:
        raise RangeError(f"data {data} outside 0..65535")
    return _pack(addr, data >> 8, data & 0xFF)


def decode_word(word: object) -> LinkWord:
    """Decode one aligned 45-bit word; FrameError (start/spacers) or CrcError."""
    addr, hi, lo = _unpack(word)
    return LinkWord(addr, (hi << 8) | lo)


def word_bits(addr: int, data: int) -> tuple[int, ...]:
    """The line bits of one word in wire order."""
    w = encode_word(addr, data)
    return tuple((w >> i) & 1 for i in range(WORD_BITS - 1, -1, -1))


def encode_stream(words: Iterable[tuple[int, int]]) -> np.ndarray:
    """The uint8 bit stream (wire order) of a sequence of (addr, data) words."""
    return bits_from_words(np.array([encode_word(*_pair(w)) for w in as_iterable(
        words, "LVDS words", RangeError)], dtype=np.uint64), WORD_BITS)


def _pair(word: object) -> tuple[int, int]:
    """An ``(addr, data)`` pair from one element of :func:`encode_stream`'s input."""
    try:
        addr, data = word  # type: ignore[misc]
    except (TypeError, ValueError):
        raise RangeError(f"LVDS word {word!r} is not an (addr, data) pair") from None
    return addr, data


# -- batch ----------------------------------------------------------------------------------
class LvdsBatch(NamedTuple):
    """Decoded arrays of aligned words (meaningful where ``valid``)."""

    addr: np.ndarray  # uint64
    data: np.ndarray  # uint64
    valid: np.ndarray  # bool: start, spacers and CRC right
    crc_failed: np.ndarray  # bool: framing right, CRC wrong


def encode_words_array(addr: np.ndarray, data: np.ndarray) -> np.ndarray:
    """Vectorised :func:`encode_word` -> uint64 line words."""
    d = as_int_array(data, "LVDS data", 0, (1 << DATA_BITS) - 1).astype(np.uint64)
    return LAYOUT.pack_array(addr, d >> np.uint64(8), d & np.uint64(0xFF))


def decode_words_array(words: np.ndarray) -> LvdsBatch:
    """Vectorised :func:`decode_word` of aligned uint64 words (e.g. from a log)."""
    vals, frame_ok, crc_ok = LAYOUT.unpack_array(words)
    data = (vals["data_hi"] << np.uint64(8)) | vals["data_lo"]
    return LvdsBatch(vals["addr"], data, frame_ok & crc_ok, frame_ok & ~crc_ok)


# -- streaming ------------------------------------------------------------------------------
_HUNT, _LOCKED, _VERIFY = 0, 1, 2


def _as_text(bits: object) -> str:
    """Bits (0/1 ints, numpy array, or a '0'/'1' string) as a '0'/'1' string."""
    if isinstance(bits, str):
        if bits.replace("0", "").replace("1", ""):
            raise FrameError("bit string may hold only '0' and '1'")
        return bits
    if isinstance(bits, np.ndarray):
        if bits.dtype.kind not in "biu":
            raise FrameError(f"bit array of dtype {bits.dtype} is not integer")
        flat = bits.ravel()
        if flat.size and (flat.min() < 0 or flat.max() > 1):
            raise FrameError("bit array holds values other than 0 and 1")
        return (flat.astype(np.uint8) + 48).tobytes().decode("ascii")
    try:
        chars = []
        for b in bits:  # type: ignore[attr-defined]
            if b == 1:
                chars.append("1")
            elif b == 0:
                chars.append("0")
            else:
                raise FrameError(f"bit value {b!r} is neither 0 nor 1")
    except TypeError:
        raise FrameError("bits must be an iterable of 0/1") from None
    return "".join(chars)


class LvdsStreamDecoder:
    """Incremental decoder: feed received bits, get the (address, data) words found.

    States: *hunt* (search for "nine ones then a zero", try the word there), *locked*
    (expect the next word right after the previous one). In lock, a word that fails is
    dropped and counted; the decoder then checks the word one length further on: if that
    one is good the failure was a corrupted word and lock is kept (so a corrupted word
    never makes the decoder look at shifted, misaligned bits), otherwise it was a slip
    and the decoder hunts again from one bit after the failed word's start.

    Guarantees: a word is emitted only if its start word, spacers and CRC are right; a
    word of the error-free stream that starts one word length or more after the end of a
    slip or burst is decoded (at most one intact word is lost after the disturbance);
    once locked, any error pattern of weight < 4 inside one word costs exactly that word.
    A phase check may wait for the next word; call :meth:`flush` at the end of a log.
    Garbage can itself form a valid word (about 2^-12 per candidate position: four spacers
    and eight CRC bits); no code can tell such a word from a real one.

    Counters: ``words`` emitted, ``crc_failures`` (framing right, CRC wrong), ``frame_errors``
    (a word expected in lock whose start word/spacers are wrong), ``resyncs`` (lock lost,
    hunt started).
    """

    def __init__(self) -> None:
        self._buf = ""
        self._state = _HUNT
        self.words = 0
        self.crc_failures = 0
        self.frame_errors = 0
        self.resyncs = 0

    @property
    def locked(self) -> bool:
        """True while the decoder trusts its word alignment."""
        return self._state != _HUNT

    def feed(self, bits: object) -> list[LinkWord]:
        """Append received bits (wire order) and return the words completed by them.

        Accepts 0/1 ints, a numpy integer array or a '0'/'1' string; anything else
        raises :class:`FrameError` (and leaves the decoder unchanged).
        """
        self._buf += _as_text(bits)
        return self._drain(final=False)

    def flush(self) -> list[LinkWord]:
        """End of input (e.g. end of a log): settle a pending phase check, return the words
        still decodable from the buffered bits, then start afresh (hunting, empty buffer).

        A failed word in lock is normally confirmed as corruption or slip by the word after
        it; at the end of the input there is none, so it counts as a slip and the decoder
        hunts through the remaining bits.
        """
        out = self._drain(final=True)
        self._buf = ""
        self._state = _HUNT
        return out

    def _drain(self, final: bool) -> list[LinkWord]:
        buf = self._buf
        n = len(buf)
        p = 0
        out: list[LinkWord] = []
        state = self._state
        while True:
            if state == _LOCKED:
                if p + WORD_BITS > n:
                    break
                try:
                    out.append(decode_word(int(buf[p:p + WORD_BITS], 2)))
                    p += WORD_BITS
                    continue
                except CrcError:
                    self.crc_failures += 1
                except FrameError:
                    self.frame_errors += 1
                state = _VERIFY
            if state == _VERIFY:
                # The word at p failed: is the next one in phase (corruption) or not (slip)?
                q = p + WORD_BITS
                word = None
                if q + len(SYNC_TEXT) <= n and not buf.startswith(SYNC_TEXT, q):
                    pass  # no start word where the next word should begin: a slip
                elif q + WORD_BITS <= n:
                    try:
                        word = decode_word(int(buf[q:q + WORD_BITS], 2))
                    except CodecError:
                        pass
                elif not final:
                    break  # wait for the rest of the next word
                if word is None:
                    state = _HUNT
                    self.resyncs += 1
                    p += 1
                    continue
                out.append(word)
                p = q + WORD_BITS
                state = _LOCKED
                continue
            # Hunt: the next "nine ones then zero" marks a candidate word start.
            s = buf.find(SYNC_TEXT, p)
            if s < 0:
                p = max(p, n - START_BITS)  # a start word may straddle the next chunk
                break
            if s + WORD_BITS > n:
                p = s
                break
            try:
                out.append(decode_word(int(buf[s:s + WORD_BITS], 2)))
            except CrcError:
                self.crc_failures += 1
                p = s + 1
                continue
            except FrameError:
                p = s + 1  # spacers wrong: a false start inside garbage, not a word
                continue
            p = s + WORD_BITS
            state = _LOCKED
        self._buf = buf[p:]
        self._state = state
        self.words += len(out)
        return out
