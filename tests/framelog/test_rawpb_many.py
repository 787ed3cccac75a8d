"""EtherCAT frames wrapped a batch at a time (rawpb.wrap_many) give the messages of the
per-frame wrapper, whatever the frames hold."""

from __future__ import annotations

import struct
import zlib

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.framelog import rawpb

ENC = "eha-hil/ethercat-fcs"


def _frame(dgs: list[tuple[int, int, int, bytes]], last_more: bool, fcs_ok: bool,
           pad: bytes) -> bytes:
    body = b""
    for k, (cmd, idx, addr, data) in enumerate(dgs):
        more = k < len(dgs) - 1 or last_more
        body += struct.pack("<BBIH", cmd, idx, addr, len(data) | (0x8000 if more else 0))
        body += b"\0\0" + data + struct.pack("<H", (cmd * 7 + idx) & 0xFFFF)
    pdu = struct.pack("<H", len(body) | 0x1000) + body + pad
    fcs = zlib.crc32(pdu) ^ (0 if fcs_ok else 1)
    return pdu + struct.pack("<I", fcs)


_dg = st.tuples(st.integers(0, 14), st.integers(0, 255), st.integers(0, 2**32 - 1),
                st.integers(0, 40))


@settings(max_examples=60, deadline=None)
@given(layouts=st.lists(st.tuples(st.lists(_dg, max_size=4), st.booleans(),
                                  st.binary(max_size=3)), min_size=1, max_size=3),
       picks=st.lists(st.tuples(st.integers(0, 2), st.booleans(), st.integers(0, 2**16)),
                      min_size=2, max_size=24),
       junk=st.lists(st.binary(max_size=30), max_size=3))
def test_batch_wrap_equals_per_frame(layouts, picks, junk) -> None:  # noqa: ANN001
    rng = np.random.default_rng(0)
    frames = []
    for which, ok, seed in picks:
        dgs, last_more, pad = layouts[which % len(layouts)]
        r = np.random.default_rng(seed)
        frames.append(_frame([(c, i, a, bytes(r.integers(0, 256, n, dtype=np.uint8)))
                              for c, i, a, n in dgs], last_more, ok, pad))
    frames += junk  # not EtherCAT at all, or too short
    frames = [frames[i] for i in rng.permutation(len(frames))]
    wrap = rawpb.wrapper(ENC)
    got = rawpb.wrap_many(ENC, frames)
    assert [bytes(m) for m in got] == [wrap(f) for f in frames]


def test_one_layout_gives_one_array() -> None:
    frames = [_frame([(12, k, 0x10000, bytes(8))], False, k % 3 != 0, b"") for k in range(9)]
    got = rawpb.wrap_many(ENC, frames)
    assert isinstance(got, np.ndarray) and got.shape[0] == 9
    assert [bytes(m) for m in got] == [rawpb.wrapper(ENC)(f) for f in frames]
    # a frame whose datagram length differs (same frame length) is wrapped on its own
    odd = bytearray(frames[4])
    odd[2 + 6] ^= 1
    frames[4] = bytes(odd)
    got = rawpb.wrap_many(ENC, frames)
    assert [bytes(m) for m in got] == [rawpb.wrapper(ENC)(f) for f in frames]


def test_periodic_lengths_give_one_array_per_place() -> None:
    """A cycle's request and reply (two lengths, repeating) wrap into one array each, whose
    rows interleaved are the per-frame messages; a period broken or an unknown layout: None."""
    frames = []
    for k in range(6):
        frames.append(_frame([(12, k, 0x10000, bytes(8))], False, True, b""))
        frames.append(_frame([(4, k, 0x20000, bytes(30)), (12, k, 3, bytes(2))], False,
                             k != 2, b"\1"))
    parts = rawpb.wrap_periodic(ENC, frames)
    assert parts is not None and len(parts) == 2 and [len(p) for p in parts] == [6, 6]
    wrap = rawpb.wrapper(ENC)
    assert [parts[i % 2][i // 2].tobytes() for i in range(12)] == [wrap(f) for f in frames]
    assert rawpb.wrap_periodic(ENC, frames[:-1]) is None  # 11 frames: no period up to 8
    assert rawpb.wrap_periodic(ENC, [frames[0]] * 3 + [frames[1]] * 6) is None
    assert rawpb.wrap_periodic("eha-hil/other", frames) is None
