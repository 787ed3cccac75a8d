"""Bit conventions and the declarative frame layout shared by the serial-link codecs.

Convention (used by every module of this family: ssi, biss, lvds, hall, abi)
-----------------------------------------------------------------------------
A frame is a non-negative Python ``int`` *word* plus its bit count ``n``, **MSB first**:
wire bit ``i`` (``i = 0`` is the first bit on the line) is ``(word >> (n - 1 - i)) & 1``.
The same bits as a sequence are a tuple of 0/1 ints in wire order; :func:`to_bits` and
:func:`from_bits` convert. Batch (numpy) paths hold one frame per ``uint64`` element in the
same layout, so frames are limited to 64 bits there.

A frame is declared once as a :class:`Layout`, an ordered list of :class:`Field` s (first
field = first on the wire). Three kinds of field exist:

* value fields, which the caller supplies and gets back;
* constant fields (start bits, spacers), checked on decode -> :class:`FrameError`;
* check fields (CRC, parity) computed over named fields on encode and verified on decode
  -> :class:`CrcError`.

``pack``/``unpack`` (scalar) and ``pack_array``/``unpack_array`` (numpy) are all derived
from the declaration, so encoder and decoder cannot disagree about a bit position.
"""

from __future__ import annotations

import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from protocols.crc import MAX_ARRAY_BITS, MAX_MESSAGE_BITS, Crc
from protocols.errors import CodecError, CrcError, FrameError, RangeError, as_int, as_int_array


def as_index(value: object, what: str = "value") -> int:
    """``value`` as a Python int (accepts ints, bools, numpy integers), else FrameError."""
    if value.__class__ is int:
        return value  # type: ignore[return-value]
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise FrameError(f"{what} must be an integer, not {type(value).__name__}") from None


def as_word(word: object, nbits: int) -> int:
    """Validate a received frame word of ``nbits`` bits and return it as an int.

    Raises :class:`FrameError` if it is not an integer or does not fit in ``nbits``
    (0..MAX_MESSAGE_BITS).
    """
    nbits = as_int(nbits, "frame length nbits", 0, MAX_MESSAGE_BITS, FrameError)
    w = as_index(word, "frame word")
    if w < 0 or w >> nbits:
        raise FrameError(f"frame word {w:#x} does not fit in {nbits} bits")
    return w


def to_bits(word: int, nbits: int) -> tuple[int, ...]:
    """The ``nbits`` bits of ``word`` in wire order (MSB first) as a tuple of 0/1."""
    w = as_word(word, nbits)
    return tuple((w >> i) & 1 for i in range(nbits - 1, -1, -1))


def from_bits(bits: Iterable[object]) -> int:
    """Inverse of :func:`to_bits`: a sequence of 0/1 in wire order -> int (first bit = MSB).

    Raises :class:`FrameError` for an element that is not 0 or 1.
    """
    word = 0
    try:
        for b in bits:
            if b == 1:
                word = (word << 1) | 1
            elif b == 0:
                word <<= 1
            else:
                raise FrameError(f"bit value {b!r} is neither 0 nor 1")
    except TypeError:
        raise FrameError("bits must be an iterable of 0/1") from None
    return word


def bits_from_words(words: np.ndarray, nbits: int) -> np.ndarray:
    """Serialise an array of ``nbits``-bit words into one uint8 bit array, wire order."""
    nbits = as_int(nbits, "word length nbits", 0, MAX_ARRAY_BITS)
    w = as_int_array(words, "words", 0, None if nbits == 64 else (1 << nbits) - 1)
    w = w.astype(np.uint64).reshape(-1, 1)
    shifts = np.arange(nbits - 1, -1, -1, dtype=np.uint64)
    return ((w >> shifts) & np.uint64(1)).astype(np.uint8).ravel()


def gray_encode(value):  # int -> int, or uint64 array -> array
    """Binary-reflected Gray code of ``value`` (an int or a numpy unsigned array).

    :class:`RangeError` for anything else, or a negative value.
    """
    if isinstance(value, np.ndarray):
        if value.dtype.kind != "u":
            raise RangeError(f"gray_encode: array of dtype {value.dtype} is not unsigned")
    elif value.__class__ is not int or value < 0:
        value = as_int(value, "gray_encode value", 0)
    return value ^ (value >> 1)


def gray_decode(gray, nbits: int):
    """Inverse of :func:`gray_encode` for codes of up to ``nbits`` bits (int or array).

    Prefix XOR by doubling shifts: ceil(log2(nbits)) steps instead of one per bit.
    :class:`RangeError` for a code that is not a non-negative int or an unsigned array,
    or ``nbits`` not in 0..MAX_MESSAGE_BITS.
    """
    if nbits.__class__ is not int or not 0 <= nbits <= MAX_MESSAGE_BITS:
        nbits = as_int(nbits, "gray_decode nbits", 0, MAX_MESSAGE_BITS)
    is_array = isinstance(gray, np.ndarray)
    if is_array:
        if gray.dtype.kind != "u":
            raise RangeError(f"gray_decode: array of dtype {gray.dtype} is not unsigned")
    elif gray.__class__ is not int or gray < 0:
        gray = as_int(gray, "gray_decode code", 0)
    shift = 1
    while shift < nbits:
        gray = gray ^ (gray >> (np.uint64(shift) if is_array else shift))
        shift <<= 1
    return gray


@dataclass(frozen=True)
class Field:
    """One field of a frame: ``width`` bits, MSB first.

    ``const`` makes it a fixed pattern checked on decode; ``check`` (with ``covers``,
    the names of the fields it is computed over, concatenated in frame order) makes it
    a CRC/parity field. ``doc`` is the meaning shown in the documentation tables.
    """

    name: str
    width: int
    const: int | None = None
    check: Crc | None = None
    covers: tuple[str, ...] = ()
    doc: str = ""


def value(name: str, width: int, doc: str = "") -> Field:
    """A field the caller supplies on encode and gets back on decode."""
    return Field(name, width, doc=doc)


def const(name: str, width: int, pattern: int, doc: str = "") -> Field:
    """A fixed field (start bit, spacer); a mismatch on decode is a FrameError."""
    return Field(name, width, const=pattern, doc=doc)


def check(name: str, crc: Crc, covers: Sequence[str], doc: str = "") -> Field:
    """A CRC/parity field of ``crc.width`` bits over the named fields."""
    return Field(name, crc.width, check=crc, covers=tuple(covers), doc=doc)


@dataclass(frozen=True)
class _Check:
    crc: Crc
    shift: int
    nbits: int
    segments: tuple[tuple[int, int, int], ...]  # (shift, mask, width) in wire order


class Layout:
    """A fixed-length frame declared as fields; encoder and decoder derived from it."""

    def __init__(self, name: str, fields: Sequence[Field]) -> None:
        self.name = name
        self.fields = tuple(fields)
        names = [f.name for f in self.fields]
        if len(set(names)) != len(names):
            raise CodecError(f"{name}: duplicate field names")
        self.width = sum(f.width for f in self.fields)
        self.shifts: dict[str, int] = {}
        pos = self.width
        for f in self.fields:
            if f.width < 1:
                raise CodecError(f"{name}.{f.name}: width must be positive")
            pos -= f.width
            self.shifts[f.name] = pos
        by_name = {f.name: f for f in self.fields}
        const_mask = const_word = 0
        vals = []
        checks = []
        for f in self.fields:
            shift, mask = self.shifts[f.name], (1 << f.width) - 1
            if f.const is not None:
                if not 0 <= f.const <= mask:
                    raise CodecError(f"{name}.{f.name}: constant does not fit")
                const_mask |= mask << shift
                const_word |= f.const << shift
            elif f.check is not None:
                segs: list[tuple[int, int, int]] = []
                for cname in sorted(f.covers, key=names.index):
                    cf = by_name[cname]
                    if cf.check is not None:
                        raise CodecError(f"{name}.{f.name}: a check cannot cover a check")
                    s = self.shifts[cname]
                    if segs and segs[-1][0] == s + cf.width:
                        # Adjacent on the wire: one wider segment, one shift at run time.
                        ps, _pm, pw = segs[-1]
                        segs[-1] = (s, (1 << (pw + cf.width)) - 1, pw + cf.width)
                    else:
                        segs.append((s, (1 << cf.width) - 1, cf.width))
                nbits = sum(w for _s, _m, w in segs)
                checks.append(_Check(f.check, shift, nbits, tuple(segs)))
            else:
                vals.append((f.name, shift, mask))
        self.value_names: tuple[str, ...] = tuple(n for n, _s, _m in vals)
        self._vals = tuple((s, m) for _n, s, m in vals)
        self._named_vals = tuple(vals)
        self._const_mask = const_mask
        self._const_word = const_word
        self._checks = tuple(checks)

    # -- scalar ---------------------------------------------------------------------------
    def pack(self, *values: int) -> int:
        """Frame word from the value fields' values, in declaration order.

        Raises :class:`RangeError` if a value does not fit its field.
        """
        if len(values) != len(self._vals):
            raise RangeError(f"{self.name}: expected {len(self._vals)} values, got {len(values)}")
        word = self._const_word
        for (shift, mask), v in zip(self._vals, values, strict=True):
            if v.__class__ is not int:
                try:
                    v = operator.index(v)
                except TypeError:
                    raise RangeError(f"{self.name}: {v!r} is not an integer") from None
            if v < 0 or v > mask:
                raise RangeError(f"{self.name}: {v} does not fit in {mask.bit_length()} bits")
            word |= v << shift
        for c in self._checks:
            word |= c.crc.compute(self._covered(word, c), c.nbits) << c.shift
        return word

    @staticmethod
    def _covered(word: int, c: _Check) -> int:
        msg = 0
        for s, m, w in c.segments:
            msg = (msg << w) | ((word >> s) & m)
        return msg

    def unpack(self, word: object) -> tuple[int, ...]:
        """Value fields of a received frame word, in declaration order.

        Raises :class:`FrameError` (not an int, too wide, a constant field wrong) or
        :class:`CrcError` (a check field wrong); constants are checked first.
        """
        w = word if word.__class__ is int else as_index(word, "frame word")
        if w < 0 or w >> self.width:  # type: ignore[operator]
            raise FrameError(f"{self.name}: word does not fit in {self.width} bits")
        if w & self._const_mask != self._const_word:  # type: ignore[operator]
            raise FrameError(f"{self.name}: fixed bits wrong (start/spacer pattern)")
        for c in self._checks:
            if c.crc.compute(self._covered(w, c), c.nbits) != (w >> c.shift) & c.crc.mask:
                raise CrcError(f"{self.name}: {c.crc.name} mismatch")
        return tuple([(w >> s) & m for s, m in self._vals])  # type: ignore[operator]

    # -- numpy ----------------------------------------------------------------------------
    def _require_array_width(self) -> None:
        if self.width > MAX_ARRAY_BITS:
            raise RangeError(f"{self.name}: {self.width}-bit frames exceed a uint64")

    def pack_array(self, *values: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`pack`: arrays of field values -> uint64 array of frame words."""
        self._require_array_width()
        if len(values) != len(self._vals):
            raise RangeError(f"{self.name}: expected {len(self._vals)} arrays")
        arrays = [as_int_array(v, f"{self.name}: field {name}", 0, mask)
                  for (name, _s, mask), v in zip(self._named_vals, values, strict=True)]
        shape = np.broadcast_shapes(*(a.shape for a in arrays)) if arrays else ()
        word = np.full(shape, self._const_word, dtype=np.uint64)
        for (shift, _mask), a in zip(self._vals, arrays, strict=True):
            word |= a.astype(np.uint64) << np.uint64(shift)
        for c in self._checks:
            word |= c.crc.compute_array(self._covered_array(word, c), c.nbits) << np.uint64(
                c.shift)
        return word

    @staticmethod
    def _covered_array(words: np.ndarray, c: _Check) -> np.ndarray:
        msg = np.zeros(words.shape, dtype=np.uint64)
        for s, m, w in c.segments:
            msg = (msg << np.uint64(w)) | ((words >> np.uint64(s)) & np.uint64(m))
        return msg

    def unpack_array(self, words: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray,
                                                        np.ndarray]:
        """Vectorised :meth:`unpack` of a uint64 array of frame words.

        Returns ``(values, frame_ok, crc_ok)``: a dict of value-field arrays (uint64), and
        boolean masks "fits and constants right" and "every check matches". A frame is
        good where both masks are true; values elsewhere are meaningless.
        """
        self._require_array_width()
        if isinstance(words, np.ndarray) and words.dtype.kind in "iu":
            # A signed array is reinterpreted as uint64 (a log's uint64 column read back
            # as int64): words too wide then come out invalid, not as an exception.
            w = words.astype(np.uint64, copy=False)
        else:
            w = as_int_array(words, f"{self.name}: frame words", 0, error=FrameError
                             ).astype(np.uint64, copy=False)
        frame_ok = (w & np.uint64(self._const_mask)) == np.uint64(self._const_word)
        if self.width < 64:
            frame_ok &= (w >> np.uint64(self.width)) == 0
        crc_ok = np.ones(w.shape, dtype=bool)
        for c in self._checks:
            got = (w >> np.uint64(c.shift)) & np.uint64(c.crc.mask)
            crc_ok &= c.crc.compute_array(self._covered_array(w, c), c.nbits) == got
        values = {name: (w >> np.uint64(s)) & np.uint64(m)
                  for name, (s, m) in zip(self.value_names, self._vals, strict=True)}
        return values, frame_ok, crc_ok

    # -- documentation --------------------------------------------------------------------
    def rows(self) -> list[tuple[str, str, str]]:
        """(wire bits, field name, meaning) per field, wire bit 0 = first bit sent."""
        out = []
        for f in self.fields:
            first = self.width - self.shifts[f.name] - f.width
            last = first + f.width - 1
            span = f"{first}" if first == last else f"{first}..{last}"
            meaning = f.doc
            if f.const is not None:
                meaning = f"{meaning} (fixed {f.const:#0{f.width + 2}b})".strip()
            out.append((span, f.name, meaning))
        return out

    def markdown_table(self) -> str:
        """The field table as Markdown (used to write docs/protocols-links.md)."""
        lines = ["| wire bits | field | meaning |", "|---|---|---|"]
        lines += [f"| {a} | {b} | {c} |" for a, b, c in self.rows()]
        return "\n".join(lines)
