"""The MCAP Message record heads of a batch and their MessageIndex entries, in one compiled
pass (:func:`fill`).

:func:`hil.framelog.batch.add_records` puts ``c`` channels' ``k`` messages each into the
chunk as one record array. Their heads (opcode, record length, channel, sequence, log and
publish time: 31 bytes in front of each message) and the ``c`` MessageIndex records of
their (log time, offset) entries took ~14 numpy operations per batch: a strided pass over
the records per head field, with numpy's per-call cost on each, for every batch of a
whole-robot log (~80 per simulated second: the decoded signals' blocks, the raw words'
blocks, the box records). Here each head is written with six unaligned stores and each
index entry with two. The numpy lines stay the readable reference in
``tests/framelog/test_heads.py``, which compares the two byte for byte; the files are the
library's (``tests/framelog/test_batch.py``).

:func:`store` (one value stored unaligned in a row of bytes) is also what the compiled
signal encoders (:mod:`hil.replay.signal_kernel`, :mod:`hil.replay.signal_records`) write
their fields with.
"""

from __future__ import annotations

import sys

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

#: Opcodes of the records written here (MCAP: Message, MessageIndex).
MESSAGE, MESSAGE_INDEX = 0x05, 0x07
#: Bytes of a Message record's head and of a MessageIndex record's head.
HEAD, INDEX_HEAD = 31, 15

if sys.byteorder != "little":  # the stores below write the machine's own byte order
    raise ImportError("hil.framelog.heads needs a little-endian machine")


@intrinsic
def store(typingctx, buf, row, at, value):
    """``value`` (a float or integer scalar) stored in its own byte width at
    ``buf[row, at]`` (``buf`` a 2-D uint8 array, rows of any stride), unaligned: one store
    where a byte loop would take eight (a protobuf value follows its one-byte key, an MCAP
    field the opcode: neither is aligned)."""
    if not (isinstance(buf, types.Array) and buf.dtype == types.uint8 and buf.ndim == 2
            and isinstance(value, (types.Float, types.Integer))):
        return None

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1], args[2]])
        vty = context.get_value_type(signature.args[3])
        builder.store(args[3], builder.bitcast(ptr, vty.as_pointer()), align=1)
        return context.get_dummy_value()

    return types.void(buf, row, at, value), codegen


@njit(cache=True, nogil=True)
def _fill(rec, length, ch, seq0, log, pub, ix, base):  # pragma: no cover - compiled
    """See :func:`fill`."""
    c = ch.shape[0]
    k = log.shape[0]
    size = rec.shape[1]
    for j in range(c):
        cid = np.uint16(ch[j])
        for i in range(k):
            r = j * k + i
            rec[r, 0] = MESSAGE
            store(rec, r, 1, np.uint64(length))
            store(rec, r, 9, cid)
            store(rec, r, 11, np.uint32((seq0[j] + i) & 0xFFFFFFFF))
            store(rec, r, 15, np.uint64(log[i]))
            store(rec, r, 23, np.uint64(pub[i]))
        if ix.shape[0]:
            ix[j, 0] = MESSAGE_INDEX
            store(ix, j, 1, np.uint64(ix.shape[1] - 9))
            store(ix, j, 9, cid)
            store(ix, j, 11, np.uint32(16 * k))
            for i in range(k):
                store(ix, j, INDEX_HEAD + 16 * i, np.uint64(log[i]))
                store(ix, j, INDEX_HEAD + 16 * i + 8, np.uint64(base + (j * k + i) * size))


def fill(rec: np.ndarray, channel_ids: np.ndarray, seq0: np.ndarray, log_ns: np.ndarray,
         publish_ns: np.ndarray, index: np.ndarray | None = None, base: int = 0) -> None:
    """The heads of ``c * k`` Message records ``rec`` ((c * k, record bytes) uint8, rows
    contiguous: channel ``j``'s ``k`` records at rows ``[j * k, (j + 1) * k)``, their
    messages after the 31 head bytes, untouched): channel ``channel_ids[j]`` (c,),
    sequences from ``seq0[j]`` on (mod 2^32), log and publish times ``log_ns`` and
    ``publish_ns`` ((k,) int64 each, the same for every channel). ``index`` ((c, 15 +
    16 k) uint8, or None): channel ``j``'s MessageIndex record of those messages, each
    entry (log time, ``base`` + the record's offset in ``rec``)."""
    c, k = len(channel_ids), len(log_ns)
    if rec.ndim != 2 or rec.dtype != np.uint8 or rec.shape[0] != c * k \
            or rec.shape[1] < HEAD or rec.strides[1] != 1 or rec.strides[0] != rec.shape[1]:
        raise ValueError(f"need records ({c * k}, >= {HEAD}) contiguous uint8, got "
                         f"{rec.shape} {rec.dtype}")
    if index is None:
        index = np.empty((0, 0), np.uint8)
    elif index.shape != (c, INDEX_HEAD + 16 * k) or index.dtype != np.uint8:
        raise ValueError(f"need index ({c}, {INDEX_HEAD + 16 * k}) uint8, got "
                         f"{index.shape} {index.dtype}")
    # contiguous int64 whatever comes in: one compiled signature (warm_up's)
    _fill(rec, rec.shape[1] - 9, np.ascontiguousarray(channel_ids, np.int64),
          np.ascontiguousarray(seq0, np.int64), np.ascontiguousarray(log_ns, np.int64),
          np.ascontiguousarray(publish_ns, np.int64), index, int(base))


def warm_up() -> None:
    """Compile :func:`_fill` for the arguments :func:`hil.framelog.batch.add_records`
    passes (a batch of one channel and one message, with and without its index)."""
    rec = np.zeros((1, HEAD + 1), np.uint8)
    one = np.zeros(1, np.int64)
    fill(rec, one, one, one, one, np.zeros((1, INDEX_HEAD + 16), np.uint8))
    fill(rec, one, one, one, one)
