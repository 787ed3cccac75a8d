"""How one channel's frames become named numbers, and in which units.

Chosen per channel, the file's own description first:

0. A raw channel whose frames travel inside protobuf messages (``eha-hil.container`` =
   ``protobuf``, :mod:`hil.framelog.rawpb`): the reader hands over the frames, decoded as
   below from 2 on (the wrapper is not what one wants to see).
1. MCAP message encoding ``protobuf``: the stock protobuf runtime, built from the schema
   stored in the file (``mcap_protobuf``'s decoder factory); every scalar field (nested
   messages flattened as ``a.b``), booleans as 0/1. Units from the channel metadata
   ``eha-hil.units`` when the writer put them there.
2. A decoder registered for the frame encoding (:mod:`hil.framelog.decoders`): it knows
   more than a byte layout can say (an LVDS line word's address, data and CRC check; an
   EtherCAT frame's datagrams).
3. A byte layout with a fixed frame size (:mod:`hil.framelog.layout`; channel metadata
   ``eha-hil.layout``, or the schema of encoding ``eha-hil/layout`` in older logs): its
   fields at their offsets, scaled to their units.
4. Nothing known: the frame's ``length``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.framelog import layout as LY
from hil.framelog import rawpb
from hil.framelog.decoders import DecodeError, decode, has_decoder
from hil.framelog.formats import META_CONTAINER, META_LAYOUT, META_UNITS
from hil.framelog.reader import ChannelInfo

Values = dict[str, int | float]


@dataclass(frozen=True)
class ChannelDecoder:
    """``decode(frame bytes) -> {field: number}`` (DecodeError for a bad frame) and the SI
    unit of each field that has one; ``how`` names the method (for messages)."""

    decode: Callable[[bytes], Values]
    units: dict[str, str]
    how: str


def _flatten(msg, prefix: str, out: Values) -> None:  # noqa: ANN001 - a protobuf message
    for fd in msg.DESCRIPTOR.fields:
        v = getattr(msg, fd.name)
        if fd.message_type is not None and not _is_repeated(fd):
            _flatten(v, f"{prefix}{fd.name}.", out)
        elif isinstance(v, bool):
            out[prefix + fd.name] = int(v)
        elif isinstance(v, int | float):
            out[prefix + fd.name] = v
        # strings, bytes and repeated fields carry no single number: left out


def _is_repeated(fd) -> bool:  # noqa: ANN001
    rep = getattr(fd, "is_repeated", None)
    return bool(rep) if rep is not None else fd.label == fd.LABEL_REPEATED


def _protobuf(ch: ChannelInfo) -> ChannelDecoder:
    from google.protobuf.message import DecodeError as PbDecodeError
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    schema = Schema(id=1, name=ch.schema_name, encoding=ch.schema_encoding,
                    data=ch.schema_data)
    try:
        parse = DecoderFactory().decoder_for("protobuf", schema)
    except Exception as exc:  # noqa: BLE001 - a foreign schema may fail in many ways
        raise DecodeError(f"{ch.topic}: protobuf schema {ch.schema_name!r}: {exc}") from None
    if parse is None:
        raise DecodeError(f"{ch.topic}: no protobuf schema")

    def run(data: bytes) -> Values:
        try:
            msg = parse(data)
        except PbDecodeError as exc:
            raise DecodeError(f"protobuf: {exc}") from None
        out: Values = {}
        _flatten(msg, "", out)
        return out

    try:
        units = json.loads(ch.metadata.get(META_UNITS, "{}"))
    except ValueError:
        units = {}
    return ChannelDecoder(run, {str(k): str(v) for k, v in units.items()}, "protobuf")


def _layout(ch: ChannelInfo, lay: LY.Layout) -> ChannelDecoder:
    dt = lay.dtype()
    scales = [(f.name, f.scale) for f in lay.fields]

    def run(data: bytes) -> Values:
        if len(data) != lay.size:
            raise DecodeError(f"{lay.encoding}: frame of {len(data)} bytes, layout has "
                              f"{lay.size}")
        rec = np.frombuffer(data, dt, 1)[0].tolist()
        return {n: (v * s if s != 1.0 else v) for (n, s), v in zip(scales, rec, strict=True)}

    return ChannelDecoder(run, lay.units(), "layout")


def is_wrapped(ch: ChannelInfo) -> bool:
    """True if the channel's frames travel inside protobuf messages (:mod:`rawpb`)."""
    return ch.metadata.get(META_CONTAINER) == rawpb.CONTAINER


def channel_layout(ch: ChannelInfo) -> LY.Layout | None:
    """The byte layout of one frame of ``ch`` with a fixed size and fields, or None."""
    data = ch.metadata.get(META_LAYOUT, "").encode()
    if not data and ch.schema_encoding == LY.SCHEMA_ENCODING:
        data = ch.schema_data
    if not data:
        return None
    try:
        lay = LY.parse(data)
    except ValueError:
        return None
    return lay if lay.size and lay.fields else None


def channel_decoder(ch: ChannelInfo) -> ChannelDecoder:
    """The decoder of channel ``ch`` (see the module docstring)."""
    if ch.message_encoding == "protobuf" and ch.schema_encoding == "protobuf" and \
            not is_wrapped(ch):
        return _protobuf(ch)
    if has_decoder(ch.encoding):
        enc = ch.encoding
        return ChannelDecoder(lambda data: decode(enc, data), {}, "registered")
    lay = channel_layout(ch)
    if lay is not None:
        return _layout(ch, lay)
    return ChannelDecoder(lambda data: {"length": len(data)}, {}, "length")
