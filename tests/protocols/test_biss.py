"""BiSS-C (Renishaw RESOLUTE) codec.

Known answers: no public data sheet gives a complete frame with its CRC as numbers (we
searched the Renishaw BiSS notes and master manuals; they give the polynomial, the bit
order and the inversion, not a worked example). The worked frame below is computed by
hand from those rules: position 0 with no error and no warning makes the CRC message
26 zeros followed by nE = 1, nW = 1, i.e. M(x) = x + 1; M(x) x^6 = x^7 + x^6 = (x^2 + x)
+ (x + 1) = x^2 + 1 = 0b000101 (mod x^6 + x + 1), sent inverted as 0b111010.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.biss import POSITION_BITS, BissCodec, BissReading, counts_from_linear_m
from protocols.crc import hamming_distance
from protocols.errors import CodecError, CrcError, FrameError, RangeError

CODECS = {n: BissCodec(n) for n in POSITION_BITS}


def frames(n: int) -> st.SearchStrategy[tuple[int, bool, bool]]:
    return st.tuples(st.integers(0, 2**n - 1), st.booleans(), st.booleans())


widths = st.sampled_from(POSITION_BITS)


def test_worked_frame_by_hand() -> None:
    word = CODECS[26].encode(0, error=False, warning=False)
    assert format(word, "036b") == "1" + "0" + "0" * 26 + "1" + "1" + "111010"
    assert CODECS[26].decode(word) == BissReading(0, False, False)


def test_error_and_warning_are_active_low() -> None:
    c = CODECS[26]
    word = c.encode(5, error=True, warning=False)
    assert (word >> 7) & 1 == 0  # nE
    assert (word >> 6) & 1 == 1  # nW
    assert c.decode(word) == BissReading(5, True, False)
    assert c.decode(c.encode(5, error=False, warning=True)) == BissReading(5, False, True)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(widths.flatmap(lambda n: st.tuples(st.just(n), frames(n))))
def test_round_trip_whole_range(case: tuple[int, tuple[int, bool, bool]]) -> None:
    n, (pos, err, warn) = case
    c = CODECS[n]
    word = c.encode(pos, err, warn)
    assert word.bit_length() == c.frame_bits  # the Start bit leads
    assert c.decode(word) == BissReading(pos, err, warn)


@pytest.mark.parametrize("n", POSITION_BITS)
def test_range_extremes(n: int) -> None:
    c = CODECS[n]
    for pos in (0, 1, 2**n - 1):
        assert c.decode(c.encode(pos, True, True)).position == pos
    for bad in (-1, 2**n):
        with pytest.raises(RangeError):
            c.encode(bad)


@settings(max_examples=200, deadline=None)
@given(widths.flatmap(lambda n: st.tuples(st.just(n), frames(n))),
       st.integers(0, 4), st.integers(1, 6), st.integers(0, 4))
def test_line_round_trip(case, ready: int, ack: int, timeout: int) -> None:
    n, (pos, err, warn) = case
    c = CODECS[n]
    line = c.encode_line(pos, err, warn, ready_bits=ready, ack_bits=ack, timeout_bits=timeout)
    assert c.decode_line(line) == BissReading(pos, err, warn)


@pytest.mark.parametrize("n", POSITION_BITS)
def test_hamming_distance_of_crc6_at_frame_length(n: int) -> None:
    # x^6 + x + 1 is primitive (period 63): HD 3 for codewords up to 63 bits, and the
    # longest RESOLUTE message is 36 + 2 bits + 6 CRC bits = 44 bits.
    assert hamming_distance(6, 0x03, n + 2) == 3


@settings(max_examples=30, deadline=None)
@given(widths.flatmap(lambda n: st.tuples(st.just(n), frames(n))))
def test_every_error_below_hd_is_detected(case) -> None:
    """All 1- and 2-bit error patterns anywhere in Start..CRC, exhaustively (HD = 3)."""
    n, (pos, err, warn) = case
    c = CODECS[n]
    word = c.encode(pos, err, warn)
    nb = c.frame_bits
    for k in (1, 2):
        for idx in combinations(range(nb), k):
            bad = word
            for i in idx:
                bad ^= 1 << i
            with pytest.raises((CrcError, FrameError)):
                c.decode(bad)


def test_bad_crc_is_rejected_with_crc_error() -> None:
    c = CODECS[36]
    word = c.encode(123456789, False, False)
    with pytest.raises(CrcError):
        c.decode(word ^ 1)  # last CRC bit
    with pytest.raises(CrcError):
        c.decode(word ^ (1 << 20))  # a position bit
    with pytest.raises(FrameError):
        c.decode(word ^ (1 << (c.frame_bits - 1)))  # Start bit


@settings(max_examples=500, deadline=None)
@given(widths, st.integers(-2**70, 2**70))
def test_arbitrary_words_never_yield_corrupt_values(n: int, word: int) -> None:
    c = CODECS[n]
    try:
        r = c.decode(word)
    except CodecError:
        return
    # Whatever decodes must be exactly a frame the encoder could have sent.
    assert c.encode(*r) == word


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(widths, st.lists(st.one_of(st.integers(-3, 3), st.booleans(), st.none(),
                                  st.text(max_size=1), st.floats()), max_size=60))
def test_arbitrary_samples_raise_only_codec_errors(n: int, samples: list) -> None:
    c = CODECS[n]
    try:
        r = c.decode_line(samples)
    except CodecError:
        return
    assert c.decode(c.encode(*r)) == r


def test_arbitrary_objects_raise_codec_error() -> None:
    c = CODECS[26]
    for junk in (None, "abc", 1.5, [1, 0], b"\x01"):
        with pytest.raises(CodecError):
            c.decode(junk)
    for junk in (None, 5, [2, 0, 1]):
        with pytest.raises(CodecError):
            c.decode_line(junk)


def test_line_framing_errors() -> None:
    c = CODECS[26]
    with pytest.raises(FrameError):
        c.decode_line([1] * 50)  # no Ack
    with pytest.raises(FrameError):
        c.decode_line([1, 0, 0, 0])  # no Start
    with pytest.raises(FrameError):
        c.decode_line(c.encode_line(7)[:-5])  # truncated


@settings(max_examples=50, deadline=None)
@given(widths, st.lists(st.integers(0, 2**64 - 1), min_size=1, max_size=200),
       st.data())
def test_batch_path_equals_scalar(n: int, raw: list[int], data) -> None:
    c = CODECS[n]
    # Mix genuine frames and raw junk so both outcomes are exercised.
    words = [c.encode(r & (2**n - 1), bool(r & 1), bool(r & 2)) if i % 2 else r
             for i, r in enumerate(raw)]
    words = [w ^ (1 << data.draw(st.integers(0, 45))) if i % 3 == 0 else w
             for i, w in enumerate(words)]
    batch = c.decode_array(np.asarray(words, dtype=np.uint64))
    for i, w in enumerate(words):
        try:
            r = c.decode(w)
        except CrcError:
            assert not batch.valid[i] and batch.crc_failed[i]
            continue
        except FrameError:
            assert not batch.valid[i] and not batch.crc_failed[i]
            continue
        assert batch.valid[i]
        assert (int(batch.position[i]), bool(batch.error[i]), bool(batch.warning[i])) == r


def test_encode_array_matches_scalar() -> None:
    c = CODECS[32]
    pos = np.array([0, 1, 2**32 - 1, 123456], dtype=np.uint64)
    err = np.array([True, False, True, False])
    words = c.encode_array(pos, err, ~err)
    assert [int(w) for w in words] == [c.encode(int(p), bool(e), not e)
                                       for p, e in zip(pos, err, strict=True)]


def test_linear_scale_counts() -> None:
    assert counts_from_linear_m(1e-3, 32) == 200_000
    with pytest.raises(RangeError):
        counts_from_linear_m(0.5, 26)  # 26 bit x 5 nm covers only 0.34 m
    with pytest.raises(RangeError):
        BissCodec(30)
