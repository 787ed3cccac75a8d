"""Many MCAP Message records at once, into the mcap library's open chunk.

``mcap.writer.Writer.add_message`` costs ~9 us of Python per message (a ``Message``
dataclass, five ``struct.pack`` calls and a seek-back per record, statistics and index
updates one at a time, and two more ``struct.pack`` per message for its index entry when the
chunk closes; measured by ``eha-hil bench log``). A ``bus run`` log has
thousands of small messages per simulated second (one decoded-signal sample per
actuator and MCU step, two fieldbus frames per cycle), and that alone would cost about
half of the run's own time. :func:`add_messages` builds the record heads of a whole batch
as one numpy structured array (with the payloads in it when they all have one length) and
makes exactly the updates ``add_message`` would: statistics (count, start and end time,
per-channel counts), the chunk builder's message index, count and time range, then the
chunk-size check; a channel's index entries are numpy arrays, written with one call
(:func:`hil.framelog.chunk.write_indexes`). :func:`records` and :func:`add_records`:
the records of many channels built in place in the chunk's buffer.

These are the Writer's private attributes (mcap 1.x). :func:`supported` checks that they
are there and have the expected types; if not, :func:`add_messages` falls back to
``add_message`` per message, so a future mcap release can make logging slower but never
wrong. A batch goes into the open chunk whole (the chunk closes after it if it is then over
size), so with small chunks the chunk boundaries differ from ``add_message``'s; otherwise
the file is the same: ``tests/framelog/test_batch.py`` compares the two byte for byte, and
the messages read back by the mcap library's reader.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np
from mcap.records import MessageIndex, Opcode
from mcap.writer import Writer

from hil.framelog import heads
from hil.framelog.chunk import ChunkBuffer, many_index, write_indexes

_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish


class _MessageIndex(MessageIndex):
    """A MessageIndex whose ``records`` may also hold (n, 2) arrays of (time, offset)
    pairs (from :func:`add_messages` and :func:`add_records`); written in one go, the
    bytes of the library's record (:func:`hil.framelog.chunk.write_indexes`, which also
    writes a chunk's indexes when our chunk closing is installed)."""

    def write(self, stream) -> None:  # noqa: ANN001 - mcap's RecordBuilder
        write_indexes({self.channel_id: self}, stream, 0, {})


def supported(w: Writer) -> bool:
    """True if ``w`` has the private state :func:`add_messages` updates."""
    stats = getattr(w, "_Writer__statistics", None)
    cb = getattr(w, "_Writer__chunk_builder", None)
    rw = getattr(cb, "record_writer", None)
    return (stats is not None and cb is not None
            and hasattr(stats, "channel_message_counts") and hasattr(stats, "message_count")
            and isinstance(getattr(cb, "message_indices", None), dict)
            and hasattr(cb, "num_messages") and hasattr(getattr(rw, "_buffer", None), "write")
            and isinstance(getattr(w, "_Writer__chunk_size", None), int)
            and callable(getattr(w, "_Writer__maybe_finalize_chunk", None)))


class Interleaved:
    """Messages whose lengths repeat with a period ``p``: message ``i`` is row ``i // p`` of
    ``parts[i % p]`` (each an (m, size_r) uint8 array), e.g. a bus cycle's request and
    reply. :func:`add_messages` builds their records as one array, with no bytes object
    per message (:func:`hil.framelog.rawpb.wrap_periodic` makes them)."""

    def __init__(self, parts: list[np.ndarray]) -> None:
        self.parts = parts

    def __len__(self) -> int:
        return len(self.parts) * len(self.parts[0])

    def __getitem__(self, i: int) -> bytes:
        p = len(self.parts)
        return self.parts[i % p][i // p].tobytes()


def add_messages(w: Writer, channel_id: int, times: Sequence[int] | np.ndarray,
                 data: Sequence[bytes] | np.ndarray | Interleaved, seq0: int,
                 fast: bool = True) -> None:
    """Messages ``data[i]`` at log and publish time ``times[i]``, sequence ``seq0 + i``
    (mod 2^32), on ``channel_id``; as ``add_message`` for each, in one go. ``data`` may be
    a (n, size) uint8 array (messages of one length) or :class:`Interleaved`."""
    n = len(data)
    if not n:
        return
    if isinstance(data, Interleaved) and not fast:
        data = [data[i] for i in range(n)]
    if isinstance(data, np.ndarray):
        if not fast:
            data = [bytes(d) for d in data]
        times = np.asarray(times, dtype=np.int64)
    if not fast:
        times = [int(x) for x in times]
        for i in range(n):
            w.add_message(channel_id, times[i], data[i], times[i], (seq0 + i) & 0xFFFFFFFF)
        return
    stats = w._Writer__statistics  # noqa: SLF001 - see the module docstring
    cb = w._Writer__chunk_builder  # noqa: SLF001
    times = np.asarray(times, dtype=np.int64)
    t_first, t_last = int(times.min()), int(times.max())
    if stats.message_count == 0:
        stats.message_start_time = t_first
    else:
        stats.message_start_time = min(t_first, stats.message_start_time)
    stats.message_end_time = max(t_last, stats.message_end_time)
    stats.channel_message_counts[channel_id] += n
    stats.message_count += n

    if cb.num_messages == 0:
        cb.message_start_time = t_first
    else:
        cb.message_start_time = min(cb.message_start_time, t_first)
    cb.message_end_time = max(cb.message_end_time, t_last)
    base = cb.record_writer.count
    if isinstance(data, Interleaved):
        blob, offsets = _interleaved(data, channel_id, times, seq0, base)
        _index(cb, channel_id, offsets)
        cb.num_messages += n
        cb.record_writer._buffer.write(blob)  # noqa: SLF001
        w._Writer__maybe_finalize_chunk()  # noqa: SLF001
        return
    size = len(data[0])
    if isinstance(data, np.ndarray) or all(len(d) == size for d in data):
        rec = np.zeros(n, np.dtype([("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"),
                                    ("log", "<u8"), ("pub", "<u8"), ("data", "u1", (size,))]))
        rec["op"] = Opcode.MESSAGE
        rec["len"] = _HEAD.size - 9 + size
        rec["ch"] = channel_id
        rec["seq"] = (np.arange(n, dtype=np.int64) + seq0) & 0xFFFFFFFF
        t = np.asarray(times, dtype=np.uint64)
        rec["log"] = t
        rec["pub"] = t
        rec["data"] = (data if isinstance(data, np.ndarray) else
                       np.frombuffer(b"".join(data), np.uint8).reshape(n, size))
        blob = rec.tobytes()
        step = rec.itemsize
        offsets = np.stack([t, base + step * np.arange(n, dtype=np.uint64)], axis=1)
    else:  # the record heads as one array, each message's bytes between them
        lens = np.fromiter(map(len, data), np.int64, n)
        heads = np.zeros(n, np.dtype(HEAD_FIELDS))
        heads["op"] = Opcode.MESSAGE
        heads["len"] = _HEAD.size - 9 + lens
        heads["ch"] = channel_id
        heads["seq"] = (np.arange(n, dtype=np.int64) + seq0) & 0xFFFFFFFF
        heads["log"] = times
        heads["pub"] = times
        hb = heads.tobytes()
        h = _HEAD.size
        parts: list = [None] * (2 * n)
        parts[0::2] = [hb[i:i + h] for i in range(0, n * h, h)]
        parts[1::2] = data
        blob = b"".join(parts)
        ends = np.cumsum(lens + h)
        offsets = np.stack([times.astype(np.uint64),
                            (base + ends - (lens + h)).astype(np.uint64)], axis=1)
    _index(cb, channel_id, offsets)
    cb.num_messages += n
    cb.record_writer._buffer.write(blob)  # noqa: SLF001
    w._Writer__maybe_finalize_chunk()  # noqa: SLF001


def _index(cb: object, channel_id: int, entries: np.ndarray) -> None:
    """``channel_id``'s index entries ``entries`` ((n, 2) log times and offsets) of a batch
    of its messages: a MessageIndex record of them kept with the chunk builder's batches
    (:func:`keep`) where it keeps them, else added to the builder's message indexes."""
    if getattr(cb, "eha_batches", None) is None:
        index = cb.message_indices.get(channel_id)
        if not isinstance(index, _MessageIndex):  # none yet, or the library's own
            index = cb.message_indices[channel_id] = _MessageIndex(
                channel_id=channel_id, records=list(index.records) if index else [])
        index.records.append(entries)
        return
    rec = np.empty(1, many_index(len(entries)))
    rec["op"] = Opcode.MESSAGE_INDEX
    rec["len"] = rec.dtype.itemsize - 9
    rec["ch"] = channel_id
    rec["n"] = 16 * len(entries)
    rec["e"][0] = entries
    keep(cb, rec.view(np.uint8).reshape(1, -1), [channel_id])


# --- a chunk's message indexes, kept per batch --------------------------------------------
# A chunk builder that keeps its batches (:func:`lazy`, from
# :func:`hil.framelog.chunk.install`) gets no per-channel index entries from a batch: the
# batch's MessageIndex records, built as one array, are kept in order, and the chunk's
# closing writes them as they are (:func:`hil.framelog.chunk.write_indexes`) when they are
# the chunk's only indexes, each channel once. Only when the library's own ``add_message``
# adds to the chunk, or a channel has two batches in it, are the kept entries put into the
# builder's ``message_indices`` (:func:`settle`), in the order they came, and the indexes
# written from those: the same bytes either way. A batch of 47 channels saves ~30 us of
# Python per call (an index object, a lookup and an append per channel, and their
# clearing when the chunk closes).


def lazy(cb: object) -> None:
    """Make chunk builder ``cb`` keep its batches' indexes (see above)."""
    cb.eha_batches = []
    cb.eha_settled = 0  # batches whose entries are in message_indices
    cb.eha_seen = set()  # channels of the kept batches
    cb.eha_twice = False  # a channel in two batches
    add = cb.add_message

    def add_message(message: object) -> None:  # the library's: entries in message_indices
        settle(cb)
        add(message)

    cb.add_message = add_message


def keep(cb: object, rec: np.ndarray, channel_ids: list[int]) -> None:
    """A batch's MessageIndex records ``rec`` ((channels, bytes) uint8: each row a record
    of :func:`many_index` entries) of ``channel_ids``, one each, kept with chunk builder
    ``cb``'s batches."""
    seen = cb.eha_seen
    if not cb.eha_twice and not seen.isdisjoint(channel_ids):
        cb.eha_twice = True
    seen.update(channel_ids)
    cb.eha_batches.append((rec, channel_ids))


def clean(cb: object) -> bool:
    """True if ``cb``'s chunk has the kept batches' indexes alone, each channel once (its
    indexes are then the kept records, in order)."""
    return getattr(cb, "eha_batches", None) is not None and not cb.message_indices \
        and not cb.eha_twice


def settle(cb: object) -> None:
    """Put the entries of ``cb``'s kept batches not yet there into its message indexes,
    in order."""
    batches = getattr(cb, "eha_batches", None)
    if not batches or cb.eha_settled == len(batches):
        return
    indices = cb.message_indices
    for rec, cids in batches[cb.eha_settled:]:
        entries = rec[:, heads.INDEX_HEAD:].view("<u8").reshape(len(cids), -1, 2)
        for j, cid in enumerate(cids):
            index = indices.get(cid)
            if type(index) is not _MessageIndex:  # none yet, or the library's own
                index = indices[cid] = _MessageIndex(
                    channel_id=cid, records=list(index.records) if index else [])
            index.records.append(entries[j])
    cb.eha_settled = len(batches)


def forget(cb: object) -> None:
    """The chunk is written: no batches kept, no indexes."""
    cb.message_indices.clear()
    if getattr(cb, "eha_batches", None) is not None:
        cb.eha_batches.clear()
        cb.eha_settled = 0
        cb.eha_seen.clear()
        cb.eha_twice = False


def _interleaved(data: Interleaved, channel_id: int, times: np.ndarray, seq0: int,
                 base: int) -> tuple[memoryview, np.ndarray]:
    """The records of :class:`Interleaved` messages as one array (a row: one period of
    records, each head then its message) and their index entries (time, offset from
    ``base``), in message order."""
    p, m = len(data.parts), len(data.parts[0])
    fields: list[tuple] = []
    for r, part in enumerate(data.parts):
        fields += [(f"{name}{r}", *spec) for name, *spec in HEAD_FIELDS]
        fields.append((f"data{r}", "u1", (part.shape[1],)))
    dt = np.dtype(fields)
    rec = np.empty(m, dt)
    t = times.reshape(m, p)
    seq = (np.arange(m, dtype=np.int64) * p + seq0) & 0xFFFFFFFF
    within = np.empty(p, np.uint64)
    for r, part in enumerate(data.parts):
        rec[f"op{r}"] = Opcode.MESSAGE
        rec[f"len{r}"] = _HEAD.size - 9 + part.shape[1]
        rec[f"ch{r}"] = channel_id
        rec[f"seq{r}"] = (seq + r) & 0xFFFFFFFF
        rec[f"log{r}"] = t[:, r]
        rec[f"pub{r}"] = t[:, r]
        rec[f"data{r}"] = part
        within[r] = dt.fields[f"op{r}"][1]
    offsets = np.empty((m, p, 2), np.uint64)
    offsets[:, :, 0] = t
    offsets[:, :, 1] = (np.uint64(base) + np.arange(m, dtype=np.uint64)[:, None]
                        * np.uint64(dt.itemsize) + within)
    return memoryview(rec.view(np.uint8)), offsets.reshape(m * p, 2)


#: The MCAP Message record's head as numpy fields: what :func:`add_records` fills in
#: front of the payload fields of a record array.
HEAD_FIELDS = [("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"), ("log", "<u8"),
               ("pub", "<u8")]
_HEAD_NAMES = tuple(name for name, _ in HEAD_FIELDS)


def records(w: Writer, dtype: np.dtype, n: int) -> tuple[np.ndarray, int | None]:
    """``n`` uninitialised records of ``dtype`` (fields starting with :data:`HEAD_FIELDS`)
    to fill and pass to :func:`add_records`, and where they lie: in the open chunk's
    :class:`~hil.framelog.chunk.ChunkBuffer` at that offset, so that they go into the chunk
    without a copy (the chunk closes after them if it is then over its size, as after
    ``add_message``); or (None) a new array, when the Writer has no such buffer."""
    cb = w._Writer__chunk_builder  # noqa: SLF001 - see the module docstring
    buf = cb.record_writer._buffer  # noqa: SLF001
    if not isinstance(buf, ChunkBuffer):
        return np.empty(n, dtype), None
    at = buf.tell()
    return buf.reserve(n * dtype.itemsize).view(dtype), at


def rows(w: Writer, n: int, size: int) -> tuple[np.ndarray, int | None]:
    """:func:`records` as ``n`` rows of ``size`` bytes ((n, size) uint8: a record's head,
    :data:`heads.HEAD <hil.framelog.heads.HEAD>` bytes, then its message) for
    :func:`add_records`."""
    cb = w._Writer__chunk_builder  # noqa: SLF001 - see the module docstring
    buf = cb.record_writer._buffer  # noqa: SLF001
    if not isinstance(buf, ChunkBuffer):
        return np.empty((n, size), np.uint8), None
    at = buf.tell()
    return buf.reserve(n * size).reshape(n, size), at


def drop(w: Writer, at: int | None) -> None:
    """Take records reserved by :func:`records` at ``at`` out of the chunk again (their
    filling failed); nothing for None."""
    if at is not None:
        w._Writer__chunk_builder.record_writer._buffer.drop(at)  # noqa: SLF001


def add_records(w: Writer, channel_ids: Sequence[int] | np.ndarray, log_ns: np.ndarray,
                publish_ns: np.ndarray, seqs: Sequence[int], rec: np.ndarray,
                at: int | None = None, ordered: bool = False) -> None:
    """``k`` messages on each channel of ``channel_ids`` (``c`` of them), channel-major:
    ``rec`` ((c * k,) structured, fields starting with :data:`HEAD_FIELDS`, filled here;
    the payload after them filled by the caller, e.g.
    :func:`hil.framelog.rawpb.pack_blocks`; or the same records as a (c * k, record
    bytes) uint8 array) holds channel ``j``'s records at
    ``[j * k, (j + 1) * k)``, at log times ``log_ns`` and publish times ``publish_ns``
    ((k,) each, the same for every channel), sequences from ``seqs[j]`` on. As
    ``add_message`` per message, with no bytes object each: ``rec`` made by
    :func:`records` lies in the chunk at ``at`` already; any other array goes into the
    chunk buffer straight from the array, a slice of channels at a time that keeps a chunk
    near its size. ``ordered``: the caller has checked that ``log_ns`` does not decrease
    (its first and last are then its least and greatest)."""
    c = len(channel_ids)
    if not c:
        return
    if rec.ndim == 2 and rec.dtype == np.uint8:  # records as rows of bytes
        size = rec.shape[1]
        if size < heads.HEAD or not rec.flags.c_contiguous:
            raise ValueError("need contiguous records of at least the head's bytes")
        rows = rec
    else:
        if not rec.flags.c_contiguous or rec.dtype.names[:len(HEAD_FIELDS)] != _HEAD_NAMES:
            raise ValueError("need contiguous records whose fields start with HEAD_FIELDS")
        size = rec.dtype.itemsize
        rows = rec.view(np.uint8).reshape(len(rec), size)
    k = len(rows) // c
    log = np.asarray(log_ns, dtype=np.int64)
    pub = np.asarray(publish_ns, dtype=np.int64)
    if ordered or len(log) == 1:
        t_first, t_last = int(log[0]), int(log[-1])
    else:
        t_first, t_last = int(log.min()), int(log.max())
    stats = w._Writer__statistics  # noqa: SLF001 - see the module docstring
    cb = w._Writer__chunk_builder  # noqa: SLF001
    if stats.message_count == 0:
        stats.message_start_time = t_first
    else:
        stats.message_start_time = min(t_first, stats.message_start_time)
    stats.message_end_time = max(t_last, stats.message_end_time)
    stats.message_count += c * k
    per = c if at is not None else max(1, w._Writer__chunk_size // (size * k))  # noqa: SLF001
    # the records' heads and every channel's MessageIndex record (entries: log time,
    # offset in the chunk) in one compiled pass (hil.framelog.heads), the index records
    # (rows of bytes) kept with the chunk builder's batches for its closing
    # (chunk.write_indexes)
    ix = np.empty((c, heads.INDEX_HEAD + 16 * k), np.uint8)
    heads.fill(rows, channel_ids, seqs, log, pub, ix, 0 if at is None else at)
    counts = stats.channel_message_counts
    ids = channel_ids.tolist() if isinstance(channel_ids, np.ndarray) else list(channel_ids)
    if at is not None:  # (the usual case: one slice, the records in the chunk already)
        _batch_in_chunk(w, cb, ids, ix, counts, k, t_first, t_last, c * k)
        return
    pairs = ix[:, heads.INDEX_HEAD:].view("<u8").reshape(c, k, 2)
    for lo in range(0, c, per):
        n = min(per, c - lo)
        base = cb.record_writer.count
        # entries of this slice: from where it starts in the chunk
        pairs[lo:lo + n, :, 1] -= np.uint64(lo * k * size)
        pairs[lo:lo + n, :, 1] += np.uint64(base)
        cb.record_writer._buffer.write(rows[lo * k:(lo + n) * k])  # noqa: SLF001
        _batch_in_chunk(w, cb, ids[lo:lo + n], ix[lo:lo + n], counts, k, t_first, t_last,
                        n * k)


def _batch_in_chunk(w: Writer, cb: object, ids: list[int], ix: np.ndarray, counts: dict,
                    k: int, t_first: int, t_last: int, n: int) -> None:
    """The chunk builder's and the statistics' share of ``n`` records of channels ``ids``
    (``k`` each) already in the chunk, their MessageIndex records ``ix`` (rows of bytes);
    then the chunk-size check (the chunk may close)."""
    if cb.num_messages == 0:
        cb.message_start_time = t_first
    else:
        cb.message_start_time = min(cb.message_start_time, t_first)
    cb.message_end_time = max(cb.message_end_time, t_last)
    for cid in ids:
        counts[cid] += k
    if getattr(cb, "eha_batches", None) is not None:
        keep(cb, ix, ids)
    else:
        indices = cb.message_indices
        entries = ix[:, heads.INDEX_HEAD:].view("<u8").reshape(len(ids), k, 2)
        for j, cid in enumerate(ids):
            index = indices.get(cid)
            if type(index) is not _MessageIndex:  # none yet, or the library's own
                index = indices[cid] = _MessageIndex(
                    channel_id=cid, records=list(index.records) if index else [])
            index.records.append((int(entries[j, 0, 0]), int(entries[j, 0, 1])) if k == 1
                                 else entries[j])
    cb.num_messages += n
    w._Writer__maybe_finalize_chunk()  # noqa: SLF001
