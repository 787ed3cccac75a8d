"""CRC engine: catalogue check values, crcmod, an independent bitwise reference.

Known answers: the catalogue check values on ASCII "123456789" (Greg Cook's "Catalogue of
parametrised CRC algorithms", also in /work/shared/PROTOCOL_FACTS.md). CRC-6/BiSS has no
catalogue entry (it is not CRC-6/G-704, which is reflected), so it is checked against an
independent polynomial long division and against crcmod's 8-bit engine with the
polynomial shifted left by two, and against a table entry derived by hand.
"""

from __future__ import annotations

import crcmod
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.crc import (
    CRC6_BISS,
    CRC8_AUTOSAR,
    PARITY_EVEN,
    PARITY_ODD,
    Crc,
    crc_bitwise,
    hamming_distance,
)
from protocols.errors import RangeError

CHECK = b"123456789"


def poly_mod(dividend: int, divisor: int) -> int:
    """Remainder of GF(2) polynomial division, both given as ints (bit i = x^i)."""
    dl = divisor.bit_length()
    while dividend.bit_length() >= dl:
        dividend ^= divisor << (dividend.bit_length() - dl)
    return dividend


def reference_crc(value: int, nbits: int, width: int, poly: int, init: int, xorout: int) -> int:
    """CRC by definition: (M(x) x^w + init x^n) mod P(x), then xorout.

    An initial register value I is equivalent to XORing I into the first w message bits,
    i.e. adding I(x) x^n to M(x) x^w.
    """
    full = (1 << width) | poly
    return poly_mod((value << width) ^ (init << nbits), full) ^ xorout


@pytest.mark.parametrize(("crc", "check"), [
    (Crc(8, 0x07), 0xF4),  # CRC-8/SMBUS
    (CRC8_AUTOSAR, 0xDF),  # CRC-8/AUTOSAR: the LVDS link word
    (Crc(8, 0x1D, 0xFF, 0xFF), 0x4B),  # CRC-8/SAE-J1850
    (Crc(16, 0x1021), 0x31C3),  # CRC-16/XMODEM
    (Crc(16, 0x1021, 0xFFFF), 0x29B1),  # CRC-16/IBM-3740
    (Crc(32, 0x04C11DB7, 0xFFFFFFFF), 0x0376E6E7),  # CRC-32/MPEG-2
    (Crc(32, 0x04C11DB7, 0xFFFFFFFF, 0xFFFFFFFF), 0xFC891918),  # CRC-32/BZIP2
])
def test_catalogue_check_values(crc: Crc, check: int) -> None:
    assert crc.compute_bytes(CHECK) == check
    assert crc_bitwise(int.from_bytes(CHECK, "big"), 72, crc.width, crc.poly, crc.init,
                       crc.xorout) == check


def test_crc8_autosar_matches_crcmod_check() -> None:
    # crcmod's initCrc is the register init XORed with xorOut (its CRC of an empty string).
    fun = crcmod.mkCrcFun(0x12F, initCrc=0xFF ^ 0xFF, rev=False, xorOut=0xFF)
    assert fun(CHECK) == 0xDF


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40))
def test_crc8_autosar_equals_crcmod(data: bytes) -> None:
    fun = crcmod.mkCrcFun(0x12F, initCrc=0x00, rev=False, xorOut=0xFF)
    assert CRC8_AUTOSAR.compute_bytes(data) == fun(data)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.integers(1, 64).flatmap(lambda n: st.tuples(st.just(n), st.integers(0, 2**n - 1))))
def test_crc6_biss_table_equals_independent_references(msg: tuple[int, int]) -> None:
    n, value = msg
    want = reference_crc(value, n, 6, 0x03, 0, 0x3F)
    assert CRC6_BISS.compute(value, n) == want
    assert crc_bitwise(value, n, 6, 0x03, 0, 0x3F) == want
    # crcmod's 8-bit engine: polynomial and init shifted left by 2, result shifted right
    # by 2; the message is left-padded with zeros to whole bytes (valid because init = 0).
    fun = crcmod.mkCrcFun(0x100 | (0x03 << 2), initCrc=0, rev=False, xorOut=0)
    nbytes = (n + 7) // 8
    assert (fun(value.to_bytes(nbytes, "big")) >> 2) ^ 0x3F == want


def test_crc6_table_by_hand() -> None:
    """x^6 mod (x^6+x+1) = x+1 = 0x03; x^7 mod P = x^2+x = 0x06; x^12 mod P = x^2+1."""
    assert CRC6_BISS.compute(0b1, 1) ^ 0x3F == 0b000011
    assert CRC6_BISS.compute(0b10, 2) ^ 0x3F == 0b000110
    # x^12 = (x+1)^2 = x^2 + 1 (mod P, char 2)
    assert CRC6_BISS.compute(0b1000000, 7) ^ 0x3F == 0b000101


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 64), st.lists(st.integers(0, 2**64 - 1), min_size=1, max_size=50),
       st.sampled_from([CRC6_BISS, CRC8_AUTOSAR, PARITY_ODD, Crc(16, 0x1021, 0xFFFF)]))
def test_array_path_equals_scalar(n: int, values: list[int], crc: Crc) -> None:
    vals = [v & ((1 << n) - 1) for v in values]
    got = crc.compute_array(np.asarray(vals, dtype=np.uint64), n)
    assert [int(x) for x in got] == [crc.compute(v, n) for v in vals]


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**40 - 1))
def test_parity_crcs(value: int) -> None:
    assert PARITY_EVEN.compute(value, 40) == value.bit_count() & 1
    assert PARITY_ODD.compute(value, 40) == 1 - (value.bit_count() & 1)


def brute_force_distance(width: int, poly: int, data_bits: int) -> int:
    """Least weight of a non-zero codeword, by enumerating every message."""
    crc = Crc(width, poly)
    return min(((m << width) | crc.compute(m, data_bits)).bit_count()
               for m in range(1, 1 << data_bits))


@pytest.mark.parametrize(("width", "poly", "data_bits"), [
    (6, 0x03, 8), (6, 0x03, 12), (8, 0x2F, 12), (8, 0x07, 10), (8, 0x9B, 9), (4, 0x3, 11),
])
def test_hamming_distance_search_against_brute_force(width: int, poly: int,
                                                     data_bits: int) -> None:
    assert hamming_distance(width, poly, data_bits) == brute_force_distance(width, poly,
                                                                            data_bits)


def test_invalid_generators_rejected() -> None:
    with pytest.raises(RangeError):
        Crc(8, 0x06)  # no x^0 term
    with pytest.raises(RangeError):
        Crc(0, 0x1)
    with pytest.raises(RangeError):
        CRC8_AUTOSAR.compute_array(np.zeros(3, dtype=np.uint64), 65)
