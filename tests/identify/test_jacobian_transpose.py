"""The Jacobian's transposing copy by blocks: the same array as one ``ascontiguousarray``."""

from __future__ import annotations

import numpy as np
import pytest

from hil.identify import fit


@pytest.mark.parametrize("block", [1, 7, 64, 4096])
def test_the_blocked_transpose_is_the_plain_one(monkeypatch, block):
    monkeypatch.setattr(fit, "TRANSPOSE_BLOCK", block)
    rng = np.random.default_rng(3)
    rows = rng.standard_normal((13, 1000))  # one row per column of the Jacobian
    rows[4, 17] = -0.0
    got = fit._transposed(rows)
    want = np.ascontiguousarray(rows.T)
    assert got.flags.c_contiguous and got.shape == (1000, 13)
    # the same bits (a copy), whatever the block and a last block cut short
    assert got.tobytes() == want.tobytes()
