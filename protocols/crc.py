"""Cyclic redundancy checks over bit strings of any length, MSB first.

The serial links of the actuator (BiSS-C, the LVDS driver-board link, SSI parity) compute
their check codes over a run of *bits* that is rarely a whole number of bytes, so this
module works on a message given as a non-negative ``int`` plus its bit count ``nbits``: the
first bit on the wire is bit ``nbits - 1`` of the int (see :mod:`protocols.bits`).

Only non-reflected CRCs (``refin = refout = False`` in the Rocksoft/Williams model) are
supported: every CRC of these links is MSB first. A CRC is described by its width, its
polynomial without the top term, ``init`` and ``xorout``, as in the CRC catalogue.

Three paths compute the same function:

* :meth:`Crc.compute` (scalar): table-driven, one lookup per 8 message bits, a smaller
  table for the leading ``nbits % 8`` bits, so no padding assumption on ``init``.
* :meth:`Crc.compute_array` (numpy): the same steps on a whole array of messages at once.
* :func:`crc_bitwise`: the textbook shift-register loop, one bit at a time; a reference.
"""

from __future__ import annotations

from functools import cache
from itertools import combinations
from math import comb

import numpy as np

from protocols.errors import RangeError, as_bytes, as_int, as_int_array

#: Largest message a numpy batch path accepts: the message must fit a uint64.
MAX_ARRAY_BITS = 64
#: Largest message the scalar paths accept, in bits (16 KiB: above a 9000-byte jumbo
#: frame). The limit is there so that a wrong length fails at once instead of building a
#: chunk plan of that many steps.
MAX_MESSAGE_BITS = 1 << 17


def _message(value: object, nbits: object) -> tuple[int, int]:
    """``(value, nbits)`` checked: 0 <= nbits <= MAX_MESSAGE_BITS, value fits nbits bits."""
    n = as_int(nbits, "CRC message length nbits", 0, MAX_MESSAGE_BITS)
    v = as_int(value, "CRC message", 0)
    if v >> n:
        raise RangeError(f"CRC message: {v:#x} does not fit in {n} bits")
    return v, n


def crc_bitwise(value: int, nbits: int, width: int, poly: int, init: int = 0,
                xorout: int = 0) -> int:
    """Return the non-reflected CRC of ``nbits`` message bits, one bit per loop step.

    ``value`` holds the message, first bit in bit ``nbits - 1``. Shift-register form:
    each message bit is XORed into the register's top bit, which selects whether the
    polynomial is subtracted (XORed) after the shift.
    """
    value, nbits = _message(value, nbits)
    width = as_int(width, "CRC width", 1, 64)
    poly = as_int(poly, "CRC polynomial", 0, (1 << width) - 1)
    init, xorout = as_int(init, "CRC init"), as_int(xorout, "CRC xorout")
    top = 1 << (width - 1)
    mask = (1 << width) - 1
    reg = init & mask
    for i in range(nbits - 1, -1, -1):
        feedback = ((reg & top) != 0) ^ ((value >> i) & 1)
        reg = (reg << 1) & mask
        if feedback:
            reg ^= poly
    return reg ^ xorout


def _remainder_table(width: int, poly: int, k: int) -> tuple[int, ...]:
    """Table T[v] = (v(x) * x^width) mod P(x) for every k-bit chunk v.

    Computed with the bitwise register (init 0, xorout 0) over the k bits of v, which is
    exactly that remainder.
    """
    return tuple(crc_bitwise(v, k, width, poly) for v in range(1 << k))


class Crc:
    """A non-reflected CRC: ``width`` bits, polynomial ``poly`` (top term implicit).

    Example: CRC-8/SMBUS is ``Crc(8, 0x07)``; BiSS-C's CRC-6 is
    ``Crc(6, 0x03, xorout=0x3F)`` (x^6 + x + 1, sent inverted).
    """

    __slots__ = ("width", "poly", "init", "xorout", "name", "mask", "_tables", "_np_tables",
                 "_plans")

    def __init__(self, width: int, poly: int, init: int = 0, xorout: int = 0,
                 name: str = "") -> None:
        width = as_int(width, "CRC width", 1, 64)
        self.width = width
        self.mask = (1 << width) - 1
        poly = as_int(poly, "CRC polynomial")
        init, xorout = as_int(init, "CRC init"), as_int(xorout, "CRC xorout")
        if not 0 <= poly <= self.mask or poly & 1 == 0:
            # A generator without the x^0 term is x * Q(x): it wastes a check bit.
            raise RangeError(f"polynomial {poly:#x} is not a valid {width}-bit generator")
        self.poly = poly
        self.init = init & self.mask
        self.xorout = xorout & self.mask
        self.name = name or f"CRC-{width}/{poly:#x}"
        # One table per chunk size 1..8: chunk size 8 for the body, the rest for the head.
        self._tables: tuple[tuple[int, ...], ...] = tuple(
            _remainder_table(width, poly, k) if k else () for k in range(9))
        self._np_tables = tuple(np.asarray(t, dtype=np.uint64) for t in self._tables)
        self._plans: dict[int, tuple[tuple[int, int, int, tuple[int, ...]], ...]] = {}

    def __repr__(self) -> str:
        return (f"Crc({self.name}: width={self.width}, poly={self.poly:#x}, "
                f"init={self.init:#x}, xorout={self.xorout:#x})")

    # -- scalar ---------------------------------------------------------------------------
    def _plan(self, nbits: int) -> tuple[tuple[int, int, int, tuple[int, ...]], ...]:
        """Chunking of an ``nbits`` message: (shift of chunk, chunk mask, k, table)."""
        plan = self._plans.get(nbits)
        if plan is None:
            steps = []
            head = nbits % 8
            pos = nbits
            if head:
                pos -= head
                steps.append((pos, (1 << head) - 1, head, self._tables[head]))
            while pos:
                pos -= 8
                steps.append((pos, 0xFF, 8, self._tables[8]))
            plan = tuple(steps)
            self._plans[nbits] = plan
        return plan

    def compute(self, value: int, nbits: int) -> int:
        """CRC of the ``nbits``-bit message ``value`` (first bit = bit ``nbits - 1``).

        :class:`RangeError` if ``nbits`` is not an int in 0..MAX_MESSAGE_BITS or ``value``
        is not a non-negative int that fits in ``nbits`` bits.
        """
        # Per-frame path of every link codec: plain ints in range pass one cheap test.
        if (value.__class__ is not int or nbits.__class__ is not int or value < 0
                or not 0 <= nbits <= MAX_MESSAGE_BITS or value >> nbits):
            value, nbits = _message(value, nbits)
        w = self.width
        mask = self.mask
        reg = self.init
        for shift, cmask, k, table in self._plan(nbits):
            chunk = (value >> shift) & cmask
            if k >= w:
                # The whole register is shifted out: (R x^(k-w) + c) x^w mod P.
                reg = table[(reg << (k - w)) ^ chunk]
            else:
                # Only the top k register bits leave; the rest shift up unchanged.
                reg = ((reg << k) & mask) ^ table[(reg >> (w - k)) ^ chunk]
        return reg ^ self.xorout

    def compute_bytes(self, data: bytes) -> int:
        """CRC of a byte string, first byte first, each byte MSB first."""
        data = as_bytes(data, "CRC message", RangeError)
        return self.compute(int.from_bytes(data, "big"), 8 * len(data))

    # -- numpy ----------------------------------------------------------------------------
    def compute_array(self, values: np.ndarray, nbits: int) -> np.ndarray:
        """CRC of every ``nbits``-bit message in a uint64 array (vectorised, table lookups).

        Returns a uint64 array of the same shape. ``nbits`` must be at most 64.
        """
        nbits = as_int(nbits, "CRC message length nbits (array messages)", 0, MAX_ARRAY_BITS)
        v = as_int_array(values, "CRC messages", 0, None if nbits == 64 else (1 << nbits) - 1)
        if v.dtype != np.uint64:
            v = v.astype(np.uint64)
        w = self.width
        mask = np.uint64(self.mask)
        reg = np.full(v.shape, self.init, dtype=np.uint64)
        for shift, cmask, k, _table in self._plan(nbits):
            table = self._np_tables[k]
            chunk = (v >> np.uint64(shift)) & np.uint64(cmask)
            if k >= w:
                reg = table[(reg << np.uint64(k - w)) ^ chunk]
            else:
                reg = ((reg << np.uint64(k)) & mask) ^ table[(reg >> np.uint64(w - k)) ^ chunk]
        return reg ^ np.uint64(self.xorout)


def hamming_distance(crc_width: int, poly: int, data_bits: int, max_weight: int = 6) -> int:
    """Minimum Hamming distance of the code (data_bits message + CRC) of a plain CRC.

    The code is linear, so the distance is the least weight of a non-zero codeword, i.e. of
    a non-zero error pattern the CRC cannot see. Searched exhaustively over all error
    patterns of weight up to ``max_weight`` (meet in the middle on the syndromes), so it
    is exact whenever the answer is at most ``max_weight``; returns ``max_weight + 1``
    when no codeword of weight <= ``max_weight`` exists. ``init``/``xorout`` do not change
    the distance.
    """
    crc_width = as_int(crc_width, "crc_width", 1, 64)
    poly = as_int(poly, "poly", 0, (1 << crc_width) - 1)
    data_bits = as_int(data_bits, "data_bits", 1, MAX_MESSAGE_BITS)
    max_weight = as_int(max_weight, "max_weight", 1)
    # The search walks every combination of half the weight: refuse one that would run
    # for hours rather than start it.
    work = comb(data_bits + crc_width, (max_weight + 1) // 2)
    if work > _MAX_SEARCH:
        raise RangeError(f"hamming_distance: {work} error patterns per side to search "
                         f"(limit {_MAX_SEARCH}); lower data_bits or max_weight")
    return _hamming_distance(crc_width, poly, data_bits, max_weight)


_MAX_SEARCH = 5_000_000


@cache
def _hamming_distance(crc_width: int, poly: int, data_bits: int, max_weight: int) -> int:
    n = data_bits + crc_width
    # Syndrome of a single error at codeword bit i (counted from the last bit sent):
    # x^i mod P. An error pattern is undetected iff its syndromes XOR to 0.
    syn = []
    reg = 1
    full = (1 << crc_width) | poly
    for _ in range(n):
        syn.append(reg)
        reg <<= 1
        if reg >> crc_width:
            reg ^= full
    if any(s == 0 for s in syn):
        return 1
    # Weight-w codewords exist iff two sub-patterns of weights a + b = w share a syndrome.
    def sums(weight: int) -> dict[int, list[tuple[int, ...]]]:
        out: dict[int, list[tuple[int, ...]]] = {}
        for combo in combinations(range(n), weight):
            s = 0
            for i in combo:
                s ^= syn[i]
            out.setdefault(s, []).append(combo)
        return out

    cache: dict[int, dict[int, list[tuple[int, ...]]]] = {}
    for w in range(2, max_weight + 1):
        a = w // 2
        b = w - a
        left = cache.setdefault(a, sums(a))
        right = cache.setdefault(b, sums(b))
        for s, combos_b in right.items():
            combos_a = left.get(s)
            if not combos_a:
                continue
            for ca in combos_a:
                for cb in combos_b:
                    if not set(ca) & set(cb):
                        return w
    return max_weight + 1


# -- the CRCs the links use -----------------------------------------------------------------
#: BiSS-C (Renishaw RESOLUTE): x^6 + x + 1, init 0, MSB first, transmitted inverted.
CRC6_BISS = Crc(6, 0x03, init=0, xorout=0x3F, name="CRC-6/BiSS")
#: CRC-8/AUTOSAR (poly 0x2F, init 0xFF, xorout 0xFF; check 0xDF): the LVDS link word.
CRC8_AUTOSAR = Crc(8, 0x2F, init=0xFF, xorout=0xFF, name="CRC-8/AUTOSAR")
#: Even parity as a CRC of width 1 (generator x + 1): the optional SSI parity bit.
PARITY_EVEN = Crc(1, 0x1, name="parity/even")
#: Odd parity: even parity inverted.
PARITY_ODD = Crc(1, 0x1, xorout=1, name="parity/odd")
