"""The compiled record heads and index entries (hil.framelog.heads) against numpy's field
by field assignment of the same records (the lines they replace in batch.add_records)."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.records import Opcode

from hil.framelog import batch, heads
from hil.framelog.chunk import many_index


def _reference(rec: np.ndarray, ids: np.ndarray, seqs: np.ndarray, log: np.ndarray,
               pub: np.ndarray, base: int) -> np.ndarray:
    """The heads set one numpy field at a time, and the MessageIndex records (entries at
    ``base`` + each record's offset)."""
    c, k = len(ids), len(log)
    rec["op"] = Opcode.MESSAGE
    rec["len"] = rec.dtype.itemsize - 9
    recs = rec.reshape(c, k)
    recs["ch"] = ids[:, None]
    recs["seq"] = (seqs[:, None] + np.arange(k)) & 0xFFFFFFFF
    recs["log"] = log
    recs["pub"] = pub
    ix = np.empty(c, many_index(k))
    ix["op"] = Opcode.MESSAGE_INDEX
    ix["len"] = ix.dtype.itemsize - 9
    ix["ch"] = ids
    ix["n"] = 16 * k
    ix["e"][:, :, 0] = log.astype(np.uint64)
    ix["e"][:, :, 1] = (np.arange(c * k, dtype=np.uint64).reshape(c, k)
                        * np.uint64(rec.dtype.itemsize) + np.uint64(base))
    return ix


@pytest.mark.parametrize(("c", "k", "size"), [(1, 1, 0), (3, 7, 13), (47, 200, 212),
                                              (5, 1, 4000)])
def test_heads_and_index_are_numpys(c: int, k: int, size: int) -> None:
    rng = np.random.default_rng(c * k + size)
    dt = np.dtype([*batch.HEAD_FIELDS, ("data", "u1", (size,))])
    payload = rng.integers(0, 256, (c * k, size), np.uint8)
    ids = rng.integers(0, 2**16, c)
    seqs = rng.integers(2**32 - 3, 2**32 + 5, c)  # wrapping past 2^32
    log = np.sort(rng.integers(0, 2**62, k))
    pub = log + rng.integers(0, 1000, k)
    base = int(rng.integers(0, 2**40))
    want, got = np.zeros(c * k, dt), np.full(c * k, 0xAB, np.uint8).repeat(dt.itemsize)
    want["data"] = payload
    got = got.view(dt)
    got["data"] = payload
    ix_want = _reference(want, ids, seqs, log, pub, base)
    ix_got = np.full(c, 0xCD, np.uint8).repeat(ix_want.dtype.itemsize).reshape(c, -1)
    heads.fill(got.view(np.uint8).reshape(c * k, -1), ids, seqs, log, pub, ix_got, base)
    assert got.tobytes() == want.tobytes()  # every head byte set, the messages untouched
    assert ix_got.tobytes() == ix_want.tobytes()


def test_bad_arrays_are_refused() -> None:
    one = np.zeros(1, np.int64)
    with pytest.raises(ValueError, match="need records"):
        heads.fill(np.zeros((1, 30), np.uint8), one, one, one, one)
    with pytest.raises(ValueError, match="need records"):
        heads.fill(np.zeros((2, 80), np.uint8)[:, ::2], one, one, np.zeros(2, np.int64),
                   np.zeros(2, np.int64))
    with pytest.raises(ValueError, match="need index"):
        heads.fill(np.zeros((1, 40), np.uint8), one, one, one, one, np.zeros((1, 30), np.uint8))
