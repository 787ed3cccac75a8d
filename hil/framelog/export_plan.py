"""What ``eha-hil log export`` writes, and the decoded frames in time order a window at a time.

An export is one table: a row per frame in simulated-time order, a column per decoded field
of any selected channel (:mod:`hil.framelog.export`). Its header must be known before the
first row, and its rows come from channels stored block by block, so an export reads the
log twice, a batch of frames at a time (:meth:`FrameLogReader.raw_batches`):

1. :class:`Plan`: the columns (names, int or float, units), whether a ``decode_error``
   column is needed, and which fields occur. A channel decoded by a whole-array path (a
   block decoder, a byte layout, fixed-width protobuf: ``Columns.fixed``) has the same
   columns in every batch, so only its first batch is decoded here; the others (EtherCAT
   frames, JSON, foreign protobuf) are decoded whole. Every channel's frame times are
   checked to be non-decreasing.
2. :meth:`Plan.windows`: the frames decoded batch by batch and handed on in time order.
   Each channel's times do not decrease, so no frame still to come is earlier than the
   lowest of the channels' latest times (their first time for one not yet seen): the
   frames up to that time go out as a :class:`Window`, the rest wait. What is held is
   the frames between the slowest channel's latest block and the reading position (for
   ``bus run`` logs: about one block, 100 ms of simulated time at level ``mcu``, 10 ms at
   ``full``), whatever the log's length.

A log that breaks these assumptions (a foreign file whose channel times go back, a fixed
channel that decodes otherwise further on) is still exported right: the windows then take
the whole log at once, or the plan decodes every channel whole (:class:`Replan`).
Ties in time keep file order (message number, then row in a block message), as
:meth:`FrameLogReader.frames` does.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence

import numpy as np

from hil.framelog.columnar import ChannelDecoding, Columns
from hil.framelog.decoders import DecodeError
from hil.framelog.reader import ChannelInfo, FrameLogError, FrameLogReader, LogInfo, RawChannel

#: Frame bytes read per batch: bounds what one batch holds (raw and decoded).
BATCH_BYTES = 16 << 20
#: Rows that wait before a window is handed on (fewer, larger windows cost fewer calls).
WINDOW_ROWS = 1 << 18
_INT64_MAX = (1 << 63) - 1
_NONE = (1 << 64, 0)


class Replan(Exception):
    """A fixed channel decoded into other columns than planned: plan again, decoding every
    channel whole (raised before a row is written only if the caller could not rewind)."""


class Plan:
    """The columns of an export of ``log_path`` (``topics``/``fields`` as in
    :func:`hil.framelog.export.export_csv`); ``thorough``: decode every channel whole in
    the planning pass (no :class:`Replan` later)."""

    def __init__(self, log_path: str | os.PathLike[str], topics: Sequence[str] | None,
                 fields: Sequence[str] | None, info: LogInfo | None,
                 thorough: bool = False) -> None:
        self.log_path = log_path
        self.reader = FrameLogReader(log_path)
        if info is not None and topics:
            for t in topics:
                info.channel(t)  # FrameLogError naming the topics present
        self.fields = list(fields) if fields else None
        self.selected = list(dict.fromkeys(topics)) if topics else None
        self.stream = True
        self.big = False  # known after the planning pass: times as uint64 then
        self._decoding: dict[str, ChannelDecoding] = {}
        self._keys: dict[str, tuple] = {}
        first: dict[str, tuple[int, int]] = {}
        cols: dict[str, dict[str, str]] = {}
        units: dict[str, dict[str, str]] = {}
        present: set[str] = set()
        errors = False
        fixed: set[str] = set()
        last: dict[str, int] = {}
        # the planning pass; it also gives the log's summary when the caller has none
        batches = self.reader.raw_batches(self.selected, BATCH_BYTES)
        self.infos: dict[str, ChannelInfo] = {}
        for batch in batches:
            for topic, raw in batch.items():
                if topic not in self.infos:
                    self.infos[topic] = batches.channel(topic)
                self._check_order(topic, raw, last)
                if topic in fixed:
                    continue
                c = self.decode(topic, raw)
                if c.fixed and not thorough:
                    fixed.add(topic)
                units[topic] = c.units
                kinds = cols.setdefault(topic, {})
                for k, v in c.columns.items():
                    kinds[k] = _merge(kinds.get(k), column_kind(v))
                    ok = c.valid[k]
                    if c.n and (ok is None or ok.any()):
                        present.add(k)
                errors |= c.errors is not None
                if c.n and topic not in first:
                    first[topic] = (int(c.t_ns[0]), int(c.seq[0]))
        if info is None:
            info = batches.info()
            for t in topics or ():
                info.channel(t)
        self.info = info
        self.selected = self.selected or [c.topic for c in info.channels]
        want = set(self.selected)
        self.infos = {c.topic: c for c in info.channels if c.topic in want}
        self.big = any(c.last_ns is not None and c.last_ns > _INT64_MAX
                       for c in self.infos.values())
        for topic, ch in self.infos.items():
            if not ch.frame_count:  # its columns all the same (a block channel's decoder)
                c = self.decode(topic, _empty(ch))
                units[topic] = c.units
                cols[topic] = {k: column_kind(v) for k, v in c.columns.items()}
        if self.fields:
            missing = [f for f in self.fields if f not in present]
            if missing:
                raise FrameLogError(f"{log_path}: field {missing[0]!r} occurs in no frame "
                                    f"of {', '.join(self.selected)}")
        # columns in order of first appearance: channels by their first frame
        order = sorted(self.infos, key=lambda t: first.get(t, _NONE))
        names: dict[str, None] = {}
        self.units: dict[str, str] = {}
        kind_of: dict[str, str] = {}
        for t in order:
            for k, kind in cols[t].items():
                names.setdefault(k, None)
                if k in units[t]:
                    self.units.setdefault(k, units[t][k])
                kind_of[k] = _merge(kind_of.get(k), kind)
        #: the float columns; of those, the ones every channel gives as float32
        self.floats = {k for k, kind in kind_of.items() if kind != "i"}
        self.singles = {k for k, kind in kind_of.items() if kind == "f4"}
        self.columns = list(self.fields) if self.fields else list(names)
        self.where = {k: j for j, k in enumerate(self.columns)}
        self.errors = errors
        self.topics = order
        self.index = {t: i for i, t in enumerate(order)}

    def key_of(self, c: Columns) -> tuple:
        """A channel's columns as ((position, dtype kind), ...): channels with the same
        key are written as one group (a fixed channel's is made once)."""
        key = self._keys.get(c.topic) if c.fixed else None
        if key is None:
            key = tuple(sorted((self.where[k], column_kind(v)) for k, v in c.columns.items()))
            if c.fixed:
                self._keys[c.topic] = key
        return key

    def names(self) -> list[str]:
        return [*self.columns] + (["decode_error"] if self.errors else [])

    def decode(self, topic: str, raw: RawChannel) -> Columns:
        """One batch of one channel's frames as columns (only frames with one of the
        selected fields, and those columns, if fields were given)."""
        try:
            how = self._decoding.get(topic)
            if how is None or how.ch is not self.infos[topic]:
                how = self._decoding[topic] = ChannelDecoding(self.infos[topic])
            c = how(raw)
        except DecodeError as exc:
            raise FrameLogError(f"{self.log_path}: {exc}") from None
        if self.big and c.t_ns.dtype != np.uint64:
            if c.n and int(c.t_ns.min()) < 0:
                raise FrameLogError(f"{self.log_path}: log times beyond 2^63 ns next to "
                                    "negative block times cannot be ordered")
            c.t_ns = c.t_ns.astype(np.uint64)
        return _keep_fields(c, self.fields) if self.fields else c

    def _check_order(self, topic: str, raw: RawChannel, last: dict[str, int]) -> None:
        """Streaming needs each channel's times non-decreasing and none before the
        channel's first message time: else the windows take the whole log at once."""
        t = raw.t_ns
        if not len(t) or not self.stream:
            return
        lo = last.get(topic, self.infos[topic].first_ns)  # first message's log time
        if (lo is not None and int(t[0]) < lo) or (len(t) > 1 and bool(np.any(t[1:] < t[:-1]))):
            self.stream = False
        last[topic] = int(t[-1])

    def windows(self) -> Iterator[Window]:
        """The decoded frames in time order (ties in file order), a window at a time.
        Frames wait as read (raw: smaller than decoded) and are decoded as they go out."""
        n = len(self.topics)
        pending: list[list[RawChannel]] = [[] for _ in range(n)]
        got = [0] * n
        total = [self.infos[t].frame_count for t in self.topics]
        bound = [self.infos[t].first_ns for t in self.topics]
        waiting = 0
        for batch in self.reader.raw_batches(self.selected, BATCH_BYTES):
            for topic, raw in batch.items():
                i = self.index[topic]
                got[i] += len(raw.t_ns)
                if len(raw.t_ns):
                    bound[i] = int(raw.t_ns[-1])
                    pending[i].append(raw)
                    waiting += len(raw.t_ns)
            if not self.stream or waiting < WINDOW_ROWS:
                continue
            open_ = [b for b, g, m in zip(bound, got, total, strict=True)
                     if g < m and b is not None]
            for cut in self._cuts(pending, min(open_) if open_ else None):
                w = self._release(pending, cut)
                if w is not None:
                    waiting -= w.frames
                    yield w
        for cut in self._cuts(pending, None) if self.stream else [None]:
            w = self._release(pending, cut)
            if w is not None:
                yield w

    @staticmethod
    def _cuts(pending: list[list[RawChannel]], upto: int | None) -> list[int | None]:
        """Times that split the pending frames up to ``upto`` (None: all) into windows of
        about :data:`WINDOW_ROWS` frames (a slow channel may hold back many), from every
        16th frame's time; the last is ``upto``."""
        every = 16
        ts = []
        for parts in pending:
            for r in parts:
                k = len(r.t_ns) if upto is None else int(np.searchsorted(r.t_ns, upto, "right"))
                ts.append(r.t_ns[:k:every])
        if not ts:
            return [upto]
        sample = np.sort(np.concatenate(ts))
        step = max(WINDOW_ROWS // every, 1)
        cuts = np.unique(sample[step::step]).tolist()
        return [c for c in cuts if upto is None or c < upto] + [upto]

    def _check_planned(self, c: Columns) -> None:
        for k, v in c.columns.items():
            kind = column_kind(v)
            if k not in self.where or (kind != "i" and k not in self.floats) or (
                    kind == "f" and k in self.singles):
                raise Replan(f"{c.topic}: column {k!r} not planned")
        if c.errors is not None and not self.errors:
            raise Replan(f"{c.topic}: decode errors not planned")

    def _release(self, pending: list[list[RawChannel]], upto: int | None) -> Window | None:
        """The pending frames at or before ``upto`` (None: all), decoded, as a window."""
        out: list[tuple[int, Columns]] = []
        frames = 0
        for i, parts in enumerate(pending):
            take: list[RawChannel] = []
            while parts:  # whole parts, then the one the time falls in (views, no copy)
                r = parts[0]
                n = len(r.t_ns)
                k = n if upto is None else int(np.searchsorted(r.t_ns, upto, side="right"))
                if k == n:
                    take.append(parts.pop(0))
                    continue
                if k:
                    take.append(_raw_slice(r, slice(0, k)))
                    parts[0] = _raw_slice(r, slice(k, None))
                break
            if not take:
                continue
            raw = _raw_concat(take)
            frames += len(raw.t_ns)
            c = self.decode(self.topics[i], raw)
            self._check_planned(c)
            if c.n:
                out.append((i, c))
        if not frames:
            return None
        return Window(self, out, frames)


def column_kind(v: np.ndarray) -> str:
    """A decoded column's kind: ``f4`` float32, ``f`` float64, ``i`` int64."""
    return ("f4" if v.dtype == np.float32 else "f") if v.dtype.kind == "f" else "i"


def _merge(a: str | None, b: str) -> str:
    """The kind of a column two channels give as kinds ``a`` (None: not yet) and ``b``:
    float32 only if both are (int64 and float32 together: float64, which holds both)."""
    if a is None or a == b:
        return b
    return "f"


def _raw_concat(parts: list[RawChannel]) -> RawChannel:
    if len(parts) == 1:
        return parts[0]
    frames = None if parts[0].frames is None else np.concatenate([p.frames for p in parts])
    payloads = None if parts[0].payloads is None else [x for p in parts for x in p.payloads]
    return RawChannel(np.concatenate([p.t_ns for p in parts]),
                      np.concatenate([p.seq for p in parts]),
                      np.concatenate([p.row for p in parts]), frames, payloads)


def _raw_slice(raw: RawChannel, sel: slice) -> RawChannel:
    return RawChannel(raw.t_ns[sel], raw.seq[sel], raw.row[sel],
                      None if raw.frames is None else raw.frames[sel],
                      None if raw.payloads is None else raw.payloads[sel])


class Window:
    """Decoded frames of several channels, ``order`` indexing their concatenation in time
    order. Channels with the same columns (every board's register channel, ...) form a
    :class:`Group`, stored one after the other: a group's columns are single arrays, so a
    slice of rows is filled a group at a time, not a channel at a time."""

    def __init__(self, plan: Plan, parts: list[tuple[int, Columns]], frames: int) -> None:
        self.frames = frames  # frames read, with those left out by a field selection
        keys: dict[tuple, list[tuple[int, Columns]]] = {}
        for i, c in parts:
            key = plan.key_of(c)
            keys.setdefault(key, []).append((i, c))
        self.groups: list[Group] = []
        start = 0
        for key, members in keys.items():
            self.groups.append(Group(key, members, start, plan.columns))
            start += self.groups[-1].n
        self.rows = start
        chans = [c for members in keys.values() for _, c in members]
        if not chans:  # a field selection left none of the frames
            chans = [Columns("", np.zeros(0, np.uint64 if plan.big else np.int64),
                             np.zeros(0, np.int64), np.zeros(0, np.int64), {}, {})]
        self.t_ns = np.concatenate([c.t_ns for c in chans])
        self.src = np.concatenate([g.which for g in self.groups] or [np.zeros(0, np.int32)])
        self.group_of = np.repeat(np.arange(len(self.groups), dtype=np.int32),
                                  [g.n for g in self.groups])
        seq = np.concatenate([c.seq for c in chans])
        row = np.concatenate([c.row for c in chans])
        self.order = np.lexsort((row, seq, self.t_ns))

    def parts(self, size: int) -> Iterator[tuple[np.ndarray, list[np.ndarray],
                                                  list[np.ndarray]]]:
        """Per ``size`` rows in time order: their indexes into the concatenated frames,
        and per group where its rows go in the slice and which of its rows they are."""
        for start in range(0, self.rows, size):
            idx = self.order[start:start + size]
            grp = self.group_of[idx]
            sort = np.argsort(grp, kind="stable")
            bounds = np.searchsorted(grp[sort], np.arange(len(self.groups) + 1))
            pos = [sort[bounds[i]:bounds[i + 1]] for i in range(len(self.groups))]
            yield idx, pos, [idx[p] - g.start for p, g in zip(pos, self.groups, strict=True)]


class Group:
    """Channels with the same columns, their values concatenated (channel after channel):
    ``key`` ((column position, dtype kind) pairs), ``start`` (first row in the window's
    concatenation), ``which`` (channel number per row), columns, masks, errors."""

    def __init__(self, key: tuple, members: list[tuple[int, Columns]], start: int,
                 names: list[str]) -> None:
        self.key = key
        self.start = start
        self.n = sum(c.n for _, c in members)
        self.which = np.repeat(np.asarray([i for i, _ in members], np.int32),
                               [c.n for _, c in members])
        cs = [c for _, c in members]
        self.columns = {names[j]: cs[0].columns[names[j]] if len(cs) == 1 else
                        np.concatenate([c.columns[names[j]] for c in cs]) for j, _ in key}
        self.valid: dict[str, np.ndarray | None] = {}
        for j, _ in key:
            masks = [c.valid[names[j]] for c in cs]
            self.valid[names[j]] = None if all(m is None for m in masks) else np.concatenate(
                [np.ones(c.n, bool) if m is None else m for c, m in zip(cs, masks, strict=True)])
        self.errors = None if all(c.errors is None for c in cs) else \
            [e for c in cs for e in (c.errors or [None] * c.n)]


def _empty(ch: ChannelInfo) -> RawChannel:
    """A channel's frames when it has none (its decoder may still name its columns)."""
    z = np.zeros(0, np.int64)
    if ch.framing == "block" and ch.dtype is not None and ch.width is not None:
        return RawChannel(z, z, z, np.zeros((0, ch.width), np.dtype(ch.dtype)), None)
    return RawChannel(z, z, z, None, [])


def _keep_fields(c: Columns, fields: Sequence[str]) -> Columns:
    """Only the frames of ``c`` that have one of ``fields``, and only those columns."""
    keep = np.zeros(c.n, bool)
    for f in fields:
        if f in c.columns:
            v = c.valid[f]
            keep |= True if v is None else v
    cols = {f: c.columns[f][keep] for f in fields if f in c.columns}
    valid = {f: (None if c.valid[f] is None else c.valid[f][keep]) for f in cols}
    return Columns(c.topic, c.t_ns[keep], c.seq[keep], c.row[keep], cols, valid, c.units,
                   None, c.fixed)
