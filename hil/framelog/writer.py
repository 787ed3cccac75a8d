"""Write frame logs: every frame that crosses a link, with its simulated time, to MCAP.

A log is an MCAP file (https://mcap.dev) written with the official ``mcap`` library:

* the header's profile is ``"eha-hil"``; a Metadata record named ``"eha-hil"`` written
  first holds the level of detail, the package version and whatever the run adds (the
  configuration as TOML text, the seed, ...);
* one channel per link and direction (``/lvds/<board>/up``, ``/fieldbus/frames``, ...);
  a channel's *encoding* says what one frame's bytes mean (``eha-hil/lvds-up``, ...);
* a *single* channel carries one frame per MCAP message; a *block* channel packs many
  fixed-width frames into one message (:func:`hil.framelog.formats.pack_block`), so a 5 kHz
  link costs one message per block instead of one per frame;
* JSON signal channels (``message_encoding="json"`` with a JSON schema) plot in Foxglove.

Crash safety: records go straight to the operating system (no Python-side buffer), so a
run that is killed leaves every chunk completed before the kill on disk; the reader returns
those and reports the file as truncated. ``chunk_size`` (bytes) and ``flush_every_ns``
(simulated ns) bound how much a kill loses. An OS crash or power loss is not covered (no
fsync).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from types import TracebackType
from typing import Literal

import numpy as np
from mcap.exceptions import UnsupportedCompressionError
from mcap.writer import CompressionType, Writer

from hil.framelog import batch, chunk, heads, rawpb
from hil.framelog.formats import (
    BLOCK_MESSAGE_ENCODING,
    DTYPE_CODES,
    ENC_JSON,
    LEVELS,
    META_CONTAINER,
    META_DTYPE,
    META_FRAME_ENCODING,
    META_FRAMING,
    META_LAYOUT,
    META_UNITS,
    META_WIDTH,
    METADATA_NAME,
    PROFILE,
    dtype_code,
    level_includes,
    pack_block,
)
from hil.framelog.layout import SCHEMA_ENCODING as LAYOUT_SCHEMA_ENCODING
from hil.framelog.protobuf import MESSAGE_ENCODING as PB_MESSAGE_ENCODING
from hil.framelog.protobuf import SCHEMA_ENCODING as PB_SCHEMA_ENCODING
from hil.framelog.protobuf import MessageType

Compression = Literal["zstd", "lz4", "none"]
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}
#: Compression levels the codecs take (zstd's negative levels trade ratio for speed).
_LEVELS = {"zstd": (min(chunk.TUNED_LEVELS), 22), "lz4": (0, 16)}
_JSON_TYPES = ("number", "integer")
#: The writer's default ``chunk_compression`` (with zstd at its default level): the decoded
#: signals (``/signals/...``: doubles and floats of noisy sensor words, ~40 % of a
#: whole-robot log's bytes and half of zstd's time) in chunks of zstd's fastest level
#: here (:data:`chunk.SIGNAL_LEVEL`), ~25 % less compression time for a log ~20 % larger
#: (docs/framelog.md, "Chunks of their own compression"); the register words and frames
#: keep :data:`chunk.ZSTD_LEVEL`.
#: The actuators' signals (two thirds of the signals' bytes) at a faster level of their own
#: (:data:`chunk.ACTUATOR_SIGNAL_LEVEL`), with the bus's rows (~1 % of the signals' bytes,
#: written just before them: in their chunk, not in a small one of their own per block).
SIGNAL_CHUNKS: dict[str, tuple[Compression, int]] = {
    "/signals/": ("zstd", chunk.SIGNAL_LEVEL),
    "/signals/actuator/": ("zstd", chunk.ACTUATOR_SIGNAL_LEVEL),
    "/signals/bus": ("zstd", chunk.ACTUATOR_SIGNAL_LEVEL)}
#: The writer's default ``chunk_compression`` (with zstd at its default level): the decoded
#: signals' kinds (:data:`SIGNAL_CHUNKS`) and the register words' blocks (``/lvds/...``, the
#: largest raw channels, most of their bytes the sensors' noise) at a faster level of their
#: own (:data:`chunk.REGISTER_BLOCK_LEVEL`); the fieldbus frames and the boxes' records,
#: which compress ~5:1 at :data:`chunk.ZSTD_LEVEL`, keep it. The register words first: a
#: flush closes the kinds' chunks in this order after the first kind's, so that the raw
#: channels a replay reads come before the decoded signals in the file (a log cut short
#: keeps them as it did when they shared the first kind's chunk).
CHUNK_KINDS: dict[str, tuple[Compression, int]] = {
    "/lvds/": ("zstd", chunk.REGISTER_BLOCK_LEVEL), **SIGNAL_CHUNKS}
#: Keys of the "eha-hil" metadata record that the writer sets itself.
RESERVED_METADATA = ("level", "version", "time")


def package_version() -> str:
    """Installed version of eha-hil ("unknown" when run from a source tree)."""
    try:
        return version("eha-hil")
    except PackageNotFoundError:
        return "unknown"


class _DirectFile:
    """A write-only file without a Python buffer: every ``write`` is an ``os.write``.

    The mcap Writer hands over whole records (a chunk and its indexes, a metadata record),
    so unbuffered writes are few and large; what matters is that a record the Writer has
    written is in the kernel's page cache, where it survives the process being killed.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pos = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
            self._pos += n
        return len(data)

    def writev(self, parts: list) -> int:
        """``parts`` (bytes-likes) one after the other, in one system call (more only if
        the kernel takes less than all of them)."""
        total = sum(memoryview(p).nbytes for p in parts)
        n = os.writev(self._fd, parts)
        self._pos += n
        if n < total:  # rare (a signal, a full disk): the rest by write
            rest = memoryview(b"".join(parts))[n:]
            self.write(rest)
        return total

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass  # nothing is buffered here

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


@dataclass
class _Channel:
    topic: str
    encoding: str
    block: bool
    dtype: np.dtype | None = None
    width: int = 0
    json_fields: frozenset[str] | None = None
    wrap: object = None  # raw single frames: frame bytes -> protobuf message (rawpb)
    container: str = ""  # block channels: "protobuf" (rawpb) or "" (eha-hil/block)
    kind: tuple = ()  # the kind of chunk its messages go to (compression, level)
    last_ns: int = 0
    count: int = 0


class FrameLogWriter:
    """Context manager writing one frame log (an MCAP file).

    ``level`` is the level of detail the run logs at (``bus``, ``mcu``, ``full``; see
    :data:`hil.framelog.formats.LEVELS` and :meth:`logs`); it is recorded in the file, the
    writer does not filter. ``metadata`` goes into the ``"eha-hil"`` Metadata record with
    ``level`` and ``version`` (values are converted with ``str``). ``chunk_size`` is the
    uncompressed chunk size in bytes at which a chunk is closed and written;
    ``flush_every_ns`` also closes the chunk when that much simulated time has passed since
    the last one (None: by size only). ``compression``: ``zstd`` (default), ``lz4`` or
    ``none``; the mcap library depends on ``zstandard`` and ``lz4``, so all three work out
    of the box. ``compression_level``: the codec's level (None: zstd
    :data:`hil.framelog.chunk.ZSTD_LEVEL`, lz4 its default); chunks are built in one
    buffer kept for the file and closed by :mod:`hil.framelog.chunk` (one compressor per
    file, no copy of the chunk; zstd chunks carry zstd's checksum instead of a CRC).
    ``chunk_compression`` maps topic prefixes to a compression of their own, or a
    (compression, level) pair (the longest prefix of a channel's topic wins): those
    channels' messages go to chunks of that kind, open beside the others (MCAP compresses
    per chunk, and every reader reads a file of mixed chunks), e.g. ``{"/signals/":
    "none"}`` keeps the decoded signals, on which zstd spends much time for little
    (docs/framelog.md, "The whole robot"), out of zstd, and ``("zstd", -9)`` gives them
    the writer's fastest zstd level; the messages are the same either way. None (the default):
    :data:`CHUNK_KINDS` when ``compression`` is zstd at its default level, else none.

    Times must be integers >= 0 (ns of simulated time) and non-decreasing per channel, so
    that each channel reads back in time order.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        level: str = "mcu",
        profile: str = PROFILE,
        metadata: dict[str, str] | None = None,
        chunk_size: int = 1 << 20,
        compression: Compression = "zstd",
        flush_every_ns: int | None = None,
        compression_level: int | None = None,
        chunk_compression: Mapping[str, Compression | tuple[Compression, int | None]]
        | None = None,
    ) -> None:
        if level not in LEVELS:
            raise ValueError(f"unknown log level {level!r} (use {', '.join(LEVELS)})")
        if compression not in _COMPRESSION:
            raise ValueError(f"compression {compression!r} is not one of zstd, lz4, none")
        _check_level(compression, compression_level)
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be >= 1 byte, got {chunk_size}")
        if chunk_compression is None:
            chunk_compression = CHUNK_KINDS \
                if compression == "zstd" and compression_level is None else {}
        kinds: dict[str, chunk.Kind] = {}
        for prefix, kind in chunk_compression.items():
            c, lvl = (kind, compression_level if kind == compression else None) \
                if isinstance(kind, str) else kind
            if c not in _COMPRESSION:
                raise ValueError(f"chunk compression {c!r} of {prefix!r} is not one of "
                                 "zstd, lz4, none")
            _check_level(c, lvl)
            kinds[str(prefix)] = (c, lvl)
        if flush_every_ns is not None and flush_every_ns <= 0:
            raise ValueError(f"flush_every_ns must be > 0, got {flush_every_ns}")
        meta = {str(k): str(v) for k, v in (metadata or {}).items()}
        clash = [k for k in RESERVED_METADATA if k in meta]
        if clash:
            raise ValueError(f"metadata key {clash[0]!r} is set by the writer")
        self.path = Path(path)
        self.level = level
        self._file = _DirectFile(path)
        try:
            self._writer = Writer(
                self._file,  # type: ignore[arg-type]  # duck-typed stream
                chunk_size=chunk_size,
                compression=_COMPRESSION[compression],
                enable_crcs=True,
                enable_data_crcs=True,
            )
        except UnsupportedCompressionError as exc:
            self._file.close()
            raise ValueError(f"compression {compression!r} unavailable ({exc}); "
                             "use compression='none'") from None
        #: records built in place in the chunk (hil.framelog.chunk's buffer installed)
        self._in_place = chunk.install(self._writer, compression, compression_level,
                                       chunk_size, tuple(kinds.values()))
        self._kind: chunk.Kind = (compression,
                                  None if compression == "none" else compression_level)
        #: topic prefix -> kind of chunk, longest first (none when not installed)
        self._kinds = sorted(kinds.items(), key=lambda kv: -len(kv[0])) \
            if self._in_place and any(k != self._kind for k in kinds.values()) else []
        try:
            self._writer.start(profile=profile, library=f"eha-hil/{package_version()}")
            self._fast = batch.supported(self._writer)
            self._writer.add_metadata(METADATA_NAME, {
                "level": level, "version": package_version(), "time": "ns of simulated time",
                **meta})
        except BaseException:
            self._file.close()  # e.g. a full disk: no descriptor left open
            raise
        self._channels: dict[int, _Channel] = {}
        self._topics: set[str] = set()
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._groups: dict[tuple[int, ...], tuple[list[_Channel], bool, bool]] = {}
        self._id_arrays: dict[tuple[int, ...], np.ndarray] = {}
        self._flush_every = flush_every_ns
        self._last_flush_ns = 0
        self._closed = False

    # -- context manager -----------------------------------------------------------------
    def __enter__(self) -> FrameLogWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        # Also on an exception: a log that ends where the run failed is what one wants to see.
        self.close()

    def logs(self, kind: str) -> bool:
        """True if this log's level includes links of ``kind`` (fieldbus, lvds, sensors, ...)."""
        return level_includes(self.level, kind)

    # -- channels ------------------------------------------------------------------------
    def _schema(self, name: str, encoding: str, data: bytes) -> int:
        if not name:
            return 0  # MCAP: schema id 0 = no schema
        key = (name, encoding, bytes(data))
        if key not in self._schemas:
            with chunk.definitions(self._writer):
                self._schemas[key] = self._writer.register_schema(name, encoding, bytes(data))
        return self._schemas[key]

    def _register(self, topic: str, message_encoding: str, schema_id: int,
                  metadata: dict[str, str], ch: _Channel) -> int:
        self._check_open()
        if topic in self._topics:
            raise ValueError(f"topic {topic!r} already has a channel")
        ch.kind = next((k for p, k in self._kinds if topic.startswith(p)), self._kind)
        with chunk.definitions(self._writer) as made:
            cid = self._writer.register_channel(topic, message_encoding, schema_id,
                                                {str(k): str(v) for k, v in metadata.items()})
        chunk.keep_channel(self._writer, cid, made)
        self._topics.add(topic)
        self._channels[cid] = ch
        return cid

    def add_channel(self, topic: str, encoding: str, *, schema_name: str = "",
                    schema_data: bytes = b"", schema_encoding: str = "",
                    metadata: dict[str, str] | None = None) -> int:
        """A channel with one frame per message; returns its id for :meth:`write`.

        ``encoding`` names the frame layout (the key of :mod:`hil.framelog.decoders`). An
        encoding that stock MCAP readers know (``json``, ``protobuf``, ...; see
        :data:`hil.framelog.rawpb.STOCK_MESSAGE_ENCODINGS`) is the MCAP message encoding,
        with the schema given (``schema_name`` "" means none). Any other (a raw frame) is
        wrapped in a protobuf message ``eha_hil.raw.<Encoding>`` (:mod:`hil.framelog.rawpb`)
        that Foxglove and the MCAP libraries decode; an ``eha-hil/layout`` schema given for
        it goes to the channel metadata ``eha-hil.layout``. Readers get the frame back.
        """
        meta = {**(metadata or {}), META_FRAMING: "single", META_FRAME_ENCODING: encoding}
        if encoding in rawpb.STOCK_MESSAGE_ENCODINGS:
            sid = self._schema(schema_name, schema_encoding, schema_data)
            return self._register(topic, encoding, sid, meta,
                                  _Channel(topic, encoding, False))
        meta.update(self._layout_meta(topic, schema_encoding, schema_data))
        meta[META_CONTAINER] = rawpb.CONTAINER
        name, data = rawpb.frame_schema(encoding)
        sid = self._schema(name, PB_SCHEMA_ENCODING, data)
        return self._register(topic, PB_MESSAGE_ENCODING, sid, meta,
                              _Channel(topic, encoding, False, wrap=rawpb.wrapper(encoding)))

    @staticmethod
    def _layout_meta(topic: str, schema_encoding: str, schema_data: bytes) -> dict[str, str]:
        # A raw channel's own schema is the protobuf wrapper; its byte layout rides along
        # in the channel metadata.
        if not schema_data:
            return {}
        if schema_encoding != LAYOUT_SCHEMA_ENCODING:
            raise ValueError(f"{topic}: a raw channel takes an {LAYOUT_SCHEMA_ENCODING} "
                             f"schema, not {schema_encoding!r}")
        return {META_LAYOUT: bytes(schema_data).decode()}

    def add_block_channel(self, topic: str, encoding: str, *, dtype: np.dtype | str | type,
                          width: int, schema_name: str = "", schema_data: bytes = b"",
                          schema_encoding: str = "",
                          metadata: dict[str, str] | None = None,
                          container: str = rawpb.CONTAINER) -> int:
        """A channel of fixed-width frames logged in blocks (:meth:`write_block`).

        One frame is ``width`` elements of ``dtype`` (little endian), e.g. an upstream LVDS
        snapshot is 32 x uint16. The frame encoding goes into the channel metadata. Each
        block is a protobuf message ``eha_hil.raw.<Encoding>Block`` (times, frames as
        bytes, count, width, dtype; :mod:`hil.framelog.rawpb`) that stock MCAP readers
        decode; an ``eha-hil/layout`` schema (``schema_*``) goes to the channel metadata
        ``eha-hil.layout``. ``container="eha-hil/block"`` writes the format of logs before
        that (message encoding ``eha-hil/block``, the layout as the schema), for tests of
        old logs; ``schema_name`` is only used then.
        """
        code = dtype_code(dtype)
        if width < 1:
            raise ValueError(f"block frame width must be >= 1, got {width}")
        dt = DTYPE_CODES[code]
        meta = {**(metadata or {}), META_FRAMING: "block", META_FRAME_ENCODING: encoding,
                META_DTYPE: dt.name, META_WIDTH: str(width)}
        if container == BLOCK_MESSAGE_ENCODING:
            sid = self._schema(schema_name, schema_encoding, schema_data)
            return self._register(topic, BLOCK_MESSAGE_ENCODING, sid, meta,
                                  _Channel(topic, encoding, True, dt, width))
        if container != rawpb.CONTAINER:
            raise ValueError(f"container {container!r} is not {rawpb.CONTAINER!r} or "
                             f"{BLOCK_MESSAGE_ENCODING!r}")
        meta.update(self._layout_meta(topic, schema_encoding, schema_data))
        meta[META_CONTAINER] = rawpb.CONTAINER
        name, data = rawpb.block_schema(encoding)
        sid = self._schema(name, PB_SCHEMA_ENCODING, data)
        return self._register(topic, PB_MESSAGE_ENCODING, sid, meta,
                              _Channel(topic, encoding, True, dt, width,
                                       container=rawpb.CONTAINER))

    def add_json_channel(self, topic: str, fields: dict[str, str],
                         metadata: dict[str, str] | None = None) -> int:
        """A JSON signals channel (``json`` messages, ``jsonschema`` schema) for Foxglove.

        ``fields`` maps a signal name to ``"number"`` or ``"integer"``. A value that is not
        finite is written as ``null`` (JSON has no NaN; a plot shows a gap). The schema
        keeps plain ``"type": "number"`` all the same: Foxglove's JSON-schema parser
        rejects a type list such as ``["number", "null"]`` for the whole channel.
        """
        bad = {k: v for k, v in fields.items() if v not in _JSON_TYPES}
        if bad:
            k, v = next(iter(bad.items()))
            raise ValueError(f"field {k!r}: type {v!r} is not 'number' or 'integer'")
        schema = {"type": "object", "title": topic,
                  "properties": {k: {"type": v} for k, v in fields.items()}}
        sid = self._schema(topic.strip("/").replace("/", ".") or "signals", "jsonschema",
                           json.dumps(schema, sort_keys=True).encode())
        meta = {**(metadata or {}), META_FRAMING: "single", META_FRAME_ENCODING: ENC_JSON}
        return self._register(topic, ENC_JSON, sid, meta,
                              _Channel(topic, ENC_JSON, False, json_fields=frozenset(fields)))

    def add_protobuf_channel(self, topic: str, message: MessageType,
                             metadata: dict[str, str] | None = None) -> int:
        """A channel of ``message`` (:class:`~hil.framelog.protobuf.MessageType`) samples,
        one per MCAP message: encoding ``protobuf``, schema the message's
        ``FileDescriptorSet``; channel metadata ``eha-hil.units`` maps fields to SI units.
        Write with :meth:`write_messages`."""
        sid = self._schema(message.full_name, PB_SCHEMA_ENCODING, message.schema)
        meta = {**(metadata or {}), META_FRAMING: "single", META_FRAME_ENCODING:
                PB_MESSAGE_ENCODING, META_UNITS: json.dumps(message.units(), sort_keys=True)}
        return self._register(topic, PB_MESSAGE_ENCODING, sid, meta,
                              _Channel(topic, PB_MESSAGE_ENCODING, False))

    # -- messages ------------------------------------------------------------------------
    def _channel(self, channel_id: int) -> _Channel:
        self._check_open()
        try:
            return self._channels[channel_id]
        except KeyError:
            raise ValueError(f"no channel with id {channel_id}") from None

    def _to(self, ch: _Channel) -> None:
        """The next messages (of ``ch``) go to the open chunk of its compression."""
        if self._kinds:
            chunk.use(self._writer, ch.kind)

    def _mixed(self, chs: list[_Channel]) -> bool:
        """True if ``chs`` go to chunks of different compressions (then one at a time)."""
        return bool(self._kinds) and any(c.kind != chs[0].kind for c in chs)

    def _advance_all(self, chs: list[_Channel], first_ns: int, last_ns: int) -> None:
        """:meth:`_advance` of every channel of ``chs`` (one batch): the one with the
        latest frame raises if any does, before any has moved."""
        latest = max(chs, key=_last_ns)
        self._advance(latest, first_ns, last_ns)  # raises, or flushes when it is time
        for c in chs:
            c.last_ns = last_ns

    def _group(self, channel_ids: list[int]) -> tuple[list[_Channel], bool, bool]:
        """The channels of ``channel_ids`` (each checked once per log), whether they are
        block channels of one protobuf layout (:meth:`write_blocks` in one array) and
        whether single-message channels without a wrapper (:meth:`write_messages_filled`),
        both only if they go to chunks of one compression."""
        self._check_open()
        key = tuple(channel_ids)
        got = self._groups.get(key)
        if got is None:
            chs = [self._channel(c) for c in channel_ids]
            one = bool(chs) and not self._mixed(chs)
            blocks = one and all(c.block and c.container == rawpb.CONTAINER
                                 and c.dtype == chs[0].dtype and c.width == chs[0].width
                                 for c in chs)
            singles = one and not any(c.block or c.wrap is not None for c in chs)
            got = self._groups[key] = (chs, blocks, singles)
        return got

    def _advance(self, ch: _Channel, first_ns: int, last_ns: int) -> None:
        if first_ns < ch.last_ns:
            raise ValueError(f"{ch.topic}: time {first_ns} ns is before the previous frame's "
                             f"{ch.last_ns} ns (times must not decrease per channel)")
        ch.last_ns = last_ns
        if self._flush_every is not None and last_ns - self._last_flush_ns >= self._flush_every:
            self._writer.flush()
            self._last_flush_ns = last_ns

    def write(self, channel_id: int, t_ns: int, data: bytes, *,
              publish_ns: int | None = None) -> None:
        """Log one frame ``data`` at simulated time ``t_ns`` (int ns, >= 0).

        ``publish_ns`` (default ``t_ns``) goes to the MCAP publish time, e.g. when the frame
        was sent as opposed to received.
        """
        ch = self._channel(channel_id)
        if ch.block:
            raise ValueError(f"{ch.topic} is a block channel: use write_block")
        t = int(t_ns)
        if t < 0:
            raise ValueError(f"{ch.topic}: time {t} ns is negative")
        self._advance(ch, t, t)
        payload = bytes(data) if ch.wrap is None else ch.wrap(bytes(data))  # type: ignore[operator]
        self._to(ch)
        self._writer.add_message(channel_id, t, payload,
                                 t if publish_ns is None else int(publish_ns),
                                 ch.count & 0xFFFFFFFF)
        ch.count += 1

    def write_block(self, channel_id: int, t_ns: np.ndarray, frames: np.ndarray) -> None:
        """Log ``len(t_ns)`` frames as one message: ``frames[i]`` at ``t_ns[i]`` (int ns).

        ``frames`` has shape (n, width) (or (n,) for width 1) and the channel's dtype, or
        any integer dtype whose values fit it (ValueError otherwise, never a silent wrap),
        or a dtype that casts to it safely; ``t_ns`` must be non-decreasing. An empty block is
        not written. The message's log time is the first frame's, its publish time the
        last frame's.
        """
        ch = self._channel(channel_id)
        if not ch.block:
            raise ValueError(f"{ch.topic} was added with add_channel: use write, or "
                             "add_block_channel for blocks")
        assert ch.dtype is not None
        t = np.asarray(t_ns)
        f = np.asarray(frames)
        if f.ndim == 1 and ch.width == 1:
            f = f.reshape(-1, 1)
        if t.ndim != 1 or f.ndim != 2 or f.shape != (t.shape[0], ch.width):
            raise ValueError(f"{ch.topic}: need t_ns (n,) and frames (n, {ch.width}), got "
                             f"{t.shape} and {f.shape}")
        f = self._typed(ch, t, f)
        n = t.shape[0]
        if n == 0:
            return
        t, step = _block_times(ch.topic, t)
        if ch.container and self._fast and self._in_place:  # in the chunk, as write_blocks
            self._write_block_records([channel_id], [ch], t, f[None], step)
            return
        first, last = int(t[0]), int(t[-1])
        self._advance(ch, first, last)
        msg = rawpb.pack_block(t, f, ch.dtype) if ch.container else pack_block(t, f)
        self._to(ch)
        self._writer.add_message(channel_id, first, msg, last,
                                 ch.count & 0xFFFFFFFF)
        ch.count += 1

    def write_blocks(self, channel_ids: list[int], t_ns: np.ndarray,
                     frames: np.ndarray) -> None:
        """:meth:`write_block` of ``frames[i]`` on ``channel_ids[i]`` for every ``i``, all
        at the times ``t_ns``: frames ``(k, n, width)``, the channels' one dtype and width
        (e.g. every actuator's upstream words of a block of MCU steps). The same frames
        as one :meth:`write_block` each, built as one array (:func:`rawpb.pack_blocks`)
        and put into the chunk from it (:func:`batch.add_records`); the noisy low bits'
        widths are chosen once for the batch (from all its channels), so the messages'
        bytes may differ from one-channel writes' while decoding to the same frames."""
        chs, blocks, _ = self._group(channel_ids)
        f = np.asarray(frames)
        if not blocks or f.ndim != 3 or len(f) != len(chs) or not self._fast:
            if f.ndim != 3 or len(f) != len(chs):
                raise ValueError(f"need frames (channels, n, width) for {len(chs)} "
                                 f"channels, got {f.shape}")
            for c, fr in zip(channel_ids, f, strict=True):
                self.write_block(c, t_ns, fr)
            return
        ch0 = chs[0]
        t = np.asarray(t_ns)
        if t.ndim != 1 or f.shape[1:] != (t.shape[0], ch0.width):
            raise ValueError(f"{ch0.topic}...: need t_ns (n,) and frames (k, n, "
                             f"{ch0.width}), got {t.shape} and {f.shape}")
        f = self._typed(ch0, t, f)
        if t.shape[0] == 0:
            return
        t, step = _block_times(ch0.topic, t)
        self._write_block_records(channel_ids, chs, t, f, step)

    def _typed(self, ch: _Channel, t: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Frames ``f`` of a block on ``ch`` in the channel's dtype (:meth:`_cast`), after
        refusing times ``t`` that are not integer ns (one check for write_block(s))."""
        if t.dtype.kind not in "iu":
            raise ValueError(f"{ch.topic}: t_ns must be integer ns, got dtype {t.dtype}")
        return f if f.dtype == ch.dtype else self._cast(ch, f)

    def _write_block_records(self, channel_ids: list[int], chs: list[_Channel],
                             t: np.ndarray, f: np.ndarray, step: int | None) -> None:
        """The block messages of ``f[i]`` on ``channel_ids[i]`` (protobuf containers of
        one dtype and width, checked) at the times ``t`` (checked; evenly spaced by
        ``step``, or None), built in place in the chunk (:func:`batch.records`,
        :func:`rawpb.pack_blocks`)."""
        first, last = int(t[0]), int(t[-1])
        before = [c.last_ns for c in chs]
        self._advance_all(chs, first, last)
        self._to(chs[0])
        at: list[int | None] = [None]

        def alloc(dtype: np.dtype, k: int) -> np.ndarray:
            rec, at[0] = batch.records(self._writer, dtype, k)
            return rec

        try:
            rec = rawpb.pack_blocks(t, f, chs[0].dtype, batch.HEAD_FIELDS, alloc=alloc,
                                    spacing=step)
        except BaseException:
            batch.drop(self._writer, at[0])  # no half-filled records left in the chunk
            for c, t_last in zip(chs, before, strict=True):
                c.last_ns = t_last
            raise
        batch.add_records(self._writer, channel_ids, t[:1], t[-1:], [c.count for c in chs],
                          rec, at[0])
        for c in chs:
            c.count += 1

    def write_messages_many(self, channel_ids: list[int], t_ns: np.ndarray,
                            messages: np.ndarray) -> None:
        """:meth:`write_messages` of ``messages[j]`` ((k, size) uint8: messages of one
        length) on ``channel_ids[j]`` for every ``j``, all at the times ``t_ns`` (k,): e.g.
        every actuator's decoded signals of a block. The same messages, built as one
        record array in the chunk (:meth:`write_messages_filled`)."""
        m = np.asarray(messages)
        if m.ndim != 3 or m.dtype != np.uint8 or len(m) != len(channel_ids):
            raise ValueError(f"need messages (channels, n, size) uint8 for "
                             f"{len(channel_ids)} channels, got {m.shape} {m.dtype}")
        if np.ndim(t_ns) != 1 or len(t_ns) != m.shape[1]:
            raise ValueError(f"need (n,) times for {m.shape[1]} messages per channel, got "
                             f"{np.shape(t_ns)}")

        def fill(out: np.ndarray) -> None:
            out[...] = m

        self.write_messages_filled(channel_ids, t_ns, m.shape[2], fill)

    def write_messages_filled(self, channel_ids: list[int], t_ns: np.ndarray, size: int,
                              fill: Callable[[np.ndarray], None]) -> None:
        """``k`` messages of ``size`` bytes on each channel of ``channel_ids``, at the times
        ``t_ns`` (k,), written by ``fill(out)`` straight into their records in the chunk:
        ``out`` is a (channels, k, size) uint8 view (rows ``size`` bytes apart inside the
        records, not contiguous) whose every byte ``fill`` must set; ``out[j, i]`` is
        message ``i`` of ``channel_ids[j]``. The messages :meth:`write_messages_many` of
        that array would write, without a copy of them (a producer that encodes messages
        can encode them there). ``fill`` must not write to this log; if it raises,
        nothing is written."""
        chs, _, singles = self._group(channel_ids)
        t = np.asarray(t_ns)
        if (chs and not singles) or not self._fast:
            m = np.zeros((len(chs), len(t), size), np.uint8)
            fill(m)
            for c, part in zip(channel_ids, m, strict=True):
                self.write_messages(c, t_ns, part)
            return
        if t.ndim != 1 or t.dtype.kind not in "iu":
            raise ValueError(f"{chs[0].topic if chs else '?'}...: need (n,) integer times, "
                             f"got {t.shape} {t.dtype}")
        if not len(t) or not chs:
            return
        times = t if t.dtype == np.int64 else t.astype(np.int64)
        if times[0] < 0 or (len(times) > 1 and (times[1:] < times[:-1]).any()):
            raise ValueError(f"{chs[0].topic}: message times must be >= 0 and "
                             "non-decreasing")
        first, last = int(times[0]), int(times[-1])
        before = [c.last_ns for c in chs]
        self._advance_all(chs, first, last)
        self._to(chs[0])
        c_n, k = len(chs), len(times)
        # the records as rows of bytes (head, then the message): no structured dtype
        # to make and view per call
        rows, at = batch.rows(self._writer, c_n * k, heads.HEAD + size)
        try:
            fill(rows[:, heads.HEAD:].reshape(c_n, k, size))
        except BaseException:
            batch.drop(self._writer, at)  # no half-filled records left in the chunk
            for c, t_last in zip(chs, before, strict=True):
                c.last_ns = t_last
            raise
        batch.add_records(self._writer, self._ids(channel_ids), times, times,
                          [c.count for c in chs], rows, at, ordered=True)
        for c in chs:
            c.count += k

    def _ids(self, channel_ids: list[int]) -> np.ndarray:
        """``channel_ids`` as an int64 array, made once per group of channels."""
        key = tuple(channel_ids)
        ids = self._id_arrays.get(key)
        if ids is None:
            ids = self._id_arrays[key] = np.array(channel_ids, np.int64)
        return ids

    def write_messages(self, channel_id: int, t_ns: np.ndarray,
                       messages: list[bytes] | np.ndarray) -> None:
        """Log ``messages[i]`` at ``t_ns[i]`` (int ns, non-decreasing), one MCAP message each,
        on a single-frame channel (e.g. :meth:`add_protobuf_channel`): the same records as
        :meth:`write` per message, built in one go (:mod:`hil.framelog.batch`).
        ``messages`` may be a (n, size) uint8 array of messages of one length (e.g.
        :meth:`~hil.framelog.protobuf.MessageType.encode_array`): no bytes object each."""
        ch = self._channel(channel_id)
        if ch.block:
            raise ValueError(f"{ch.topic} is a block channel: use write_block")
        t = np.asarray(t_ns)
        if isinstance(messages, np.ndarray) and (messages.ndim != 2
                                                 or messages.dtype != np.uint8):
            raise ValueError(f"{ch.topic}: messages as an array must be (n, size) uint8, "
                             f"got {messages.shape} {messages.dtype}")
        if t.ndim != 1 or t.shape[0] != len(messages) or t.dtype.kind not in "iu":
            raise ValueError(f"{ch.topic}: need (n,) integer times for {len(messages)} "
                             f"messages, got {t.shape} {t.dtype}")
        if not len(messages):
            return
        times = t.astype(np.int64)
        if times[0] < 0 or (len(times) > 1 and bool(np.any(times[1:] < times[:-1]))):
            raise ValueError(f"{ch.topic}: message times must be >= 0 and non-decreasing")
        self._advance(ch, int(times[0]), int(times[-1]))
        if ch.wrap is not None:
            frames = list(map(bytes, messages))
            parts = rawpb.wrap_periodic(ch.encoding, frames)
            messages = (batch.Interleaved(parts) if parts is not None
                        else rawpb.wrap_many(ch.encoding, frames))
        self._to(ch)
        batch.add_messages(self._writer, channel_id, times, messages, ch.count, self._fast)
        ch.count += len(messages)

    @staticmethod
    def _cast(ch: _Channel, f: np.ndarray) -> np.ndarray:
        # Integer state arrays are int64 in the models: accept any integer array whose
        # values fit, rather than make every caller cast (and risk a silent wrap-around).
        assert ch.dtype is not None
        if f.dtype == ch.dtype:
            return f  # (pack_block makes the one copy it needs)
        if f.dtype.kind in "iub" and ch.dtype.kind in "iu":
            info = np.iinfo(ch.dtype)
            if f.size and (int(f.min()) < info.min or int(f.max()) > info.max):
                raise ValueError(f"{ch.topic}: frame values {int(f.min())}..{int(f.max())} "
                                 f"do not fit the channel's {ch.dtype}")
        elif not np.can_cast(f.dtype, ch.dtype, "safe"):
            raise ValueError(f"{ch.topic}: frames of dtype {f.dtype} do not fit the "
                             f"channel's {ch.dtype}")
        return f.astype(ch.dtype)

    def write_json(self, channel_id: int, t_ns: int, values: dict[str, float | int]) -> None:
        """Log one sample of signals on a JSON channel; keys must be declared fields."""
        ch = self._channel(channel_id)
        if ch.json_fields is None:
            raise ValueError(f"{ch.topic} is not a JSON channel (add_json_channel)")
        out: dict[str, float | int | None] = {}
        for k, v in values.items():
            if k not in ch.json_fields:
                raise ValueError(f"{ch.topic}: field {k!r} was not declared")
            if isinstance(v, np.generic):
                v = v.item()
            out[k] = None if isinstance(v, float) and not math.isfinite(v) else v
        self.write(channel_id, t_ns, json.dumps(out, separators=(",", ":")).encode())

    # -- end -----------------------------------------------------------------------------
    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """A further MCAP Metadata record (e.g. what a replay needs), written at once."""
        self._check_open()
        if name == METADATA_NAME:
            raise ValueError(f"metadata record {name!r} is written by the writer")
        self._writer.add_metadata(name, {str(k): str(v) for k, v in values.items()})

    def flush(self) -> None:
        """Close the chunk in progress and write it: everything so far survives a kill."""
        self._check_open()
        self._writer.flush()

    def close(self) -> None:
        """Write the last chunk, the summary and the footer; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"frame log {self.path} is closed")


def _check_level(compression: str, level: int | None) -> None:
    """ValueError in one line if ``compression`` does not take ``level``."""
    if level is not None and not (
            compression in _LEVELS and _LEVELS[compression][0] <= level <= _LEVELS[compression][1]):
        if compression not in _LEVELS:
            raise ValueError(f"compression {compression!r} takes no level")
        lo, hi = _LEVELS[compression]
        raise ValueError(f"{compression} level {level} is outside {lo}..{hi}")


def _last_ns(ch: _Channel) -> int:
    return ch.last_ns


def _block_times(topic: str, t: np.ndarray) -> tuple[np.ndarray, int | None]:
    """A block's frame times ``t`` (integer ns, at least one) as int64 and their spacing
    (:func:`rawpb.even_spacing`, from the same differences), refused in one line (naming
    ``topic``) if negative or decreasing."""
    t = t.astype(np.int64, copy=False)
    if t[0] < 0:
        raise ValueError(f"{topic}: time {int(t[0])} ns is negative")
    if len(t) < 2:
        return t, 0
    d = np.diff(t)
    lo, hi = int(d.min()), int(d.max())
    if lo < 0:
        raise ValueError(f"{topic}: block times decrease")
    return t, (lo if lo == hi else None)
