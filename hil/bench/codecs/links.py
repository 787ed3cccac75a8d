"""Benchmark cases for the serial-link codecs: SSI, BiSS-C, LVDS link word, Hall, ABI.

Frame cases do ``n`` scalar encode + decode round trips (target 100,000 frames/s); batch
cases decode a prepared uint64 array of ``n`` logged frames with the numpy path (target
1,000,000 frames/s). The array for a given ``n`` is built once and cached, so repeat calls
time only the decoding. Prepared frames include a share of corrupted ones, so the checks
do real work.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from hil.bench.codecs import CodecCase
from protocols import lvds
from protocols.biss import BissCodec
from protocols.ssi import SsiCodec, SsiFormat

_SSI = SsiCodec()  # RMB30SI default: 11-bit binary
_SSI_GRAY = SsiCodec(SsiFormat(position_bits=13, status_bits=2, gray=True, parity="even"))
_BISS_ROT = BissCodec(26)
_BISS_LIN = BissCodec(36)


def run_ssi_frame(n: int) -> int:
    """SSI (11-bit binary) encode + decode, ``n`` times."""
    enc, dec = _SSI.encode, _SSI.decode
    for i in range(n):
        dec(enc(i & 2047))
    return n


def run_ssi_gray_frame(n: int) -> int:
    """SSI (13-bit Gray, 2 status bits, parity) encode + decode, ``n`` times."""
    enc, dec = _SSI_GRAY.encode, _SSI_GRAY.decode
    for i in range(n):
        dec(enc(i & 8191, i & 3))
    return n


def run_biss_frame(n: int) -> int:
    """BiSS-C rotary 26-bit encode + decode (CRC-6 both ways), ``n`` times."""
    enc, dec = _BISS_ROT.encode, _BISS_ROT.decode
    for i in range(n):
        dec(enc((i * 2654435761) & 0x3FFFFFF, False, bool(i & 8)))
    return n


def run_biss36_frame(n: int) -> int:
    """BiSS-C linear 36-bit encode + decode, ``n`` times."""
    enc, dec = _BISS_LIN.encode, _BISS_LIN.decode
    for i in range(n):
        dec(enc((i * 2654435761) & 0xFFFFFFFFF, bool(i & 16), False))
    return n


def run_lvds_word_frame(n: int) -> int:
    """LVDS link word encode + decode, ``n`` times."""
    enc, dec = lvds.encode_word, lvds.decode_word
    for i in range(n):
        dec(enc(i & 0xFF, (i * 40503) & 0xFFFF))
    return n


@cache
def _lvds_stream(n: int) -> np.ndarray:
    words = [(i & 0xFF, (i * 40503) & 0xFFFF) for i in range(n)]
    return lvds.encode_stream(words)


def run_lvds_stream(n: int) -> int:
    """Streaming decoder over a prepared bit stream of ``n`` words, fed in 4096-bit chunks."""
    bits = _lvds_stream(n)
    dec = lvds.LvdsStreamDecoder()
    got = 0
    for k in range(0, len(bits), 4096):
        got += len(dec.feed(bits[k:k + 4096]))
    return got


def _corrupt(words: np.ndarray, nbits: int) -> np.ndarray:
    """Flip one random bit in every 16th frame (deterministic seed)."""
    rng = np.random.default_rng(1)
    out = words.copy()
    idx = np.arange(0, len(out), 16)
    out[idx] ^= np.uint64(1) << rng.integers(0, nbits, len(idx)).astype(np.uint64)
    return out


@cache
def _ssi_words(n: int) -> np.ndarray:
    pos = np.arange(n, dtype=np.uint64) & np.uint64(8191)
    return _corrupt(_SSI_GRAY.encode_array(pos, pos & np.uint64(3)), _SSI_GRAY.frame_bits)


@cache
def _biss_words(n: int) -> np.ndarray:
    pos = (np.arange(n, dtype=np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFFFFF)
    return _corrupt(_BISS_LIN.encode_array(pos, pos & np.uint64(1) == 1),
                    _BISS_LIN.frame_bits)


@cache
def _lvds_words(n: int) -> np.ndarray:
    i = np.arange(n, dtype=np.uint64)
    return _corrupt(lvds.encode_words_array(i & np.uint64(0xFF),
                                            (i * np.uint64(40503)) & np.uint64(0xFFFF)),
                    lvds.WORD_BITS)


def run_ssi_batch(n: int) -> int:
    """Vectorised decode of ``n`` SSI frames (13-bit Gray + status + parity)."""
    return int(_SSI_GRAY.decode_array(_ssi_words(n)).valid.size)


def run_biss_batch(n: int) -> int:
    """Vectorised decode of ``n`` BiSS-C 36-bit frames with table-driven CRC-6."""
    return int(_BISS_LIN.decode_array(_biss_words(n)).valid.size)


def run_lvds_batch(n: int) -> int:
    """Vectorised decode of ``n`` aligned LVDS words with table-driven CRC-8."""
    return int(lvds.decode_words_array(_lvds_words(n)).valid.size)


CASES: list[CodecCase] = [
    CodecCase("ssi frame (11 bit binary)", "frame", run_ssi_frame, 100_000),
    CodecCase("ssi frame (13 bit gray+status+parity)", "frame", run_ssi_gray_frame, 100_000),
    CodecCase("biss-c frame (26 bit rotary)", "frame", run_biss_frame, 100_000),
    CodecCase("biss-c frame (36 bit linear)", "frame", run_biss36_frame, 100_000),
    CodecCase("lvds word", "frame", run_lvds_word_frame, 100_000),
    CodecCase("lvds stream decoder", "frame", run_lvds_stream, 100_000),
    CodecCase("ssi batch decode", "batch", run_ssi_batch, 1_000_000),
    CodecCase("biss-c batch decode", "batch", run_biss_batch, 1_000_000),
    CodecCase("lvds word batch decode", "batch", run_lvds_batch, 1_000_000),
]
