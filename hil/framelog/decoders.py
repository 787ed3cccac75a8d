"""Frame decoders by encoding name: frame bytes -> named numbers (for export and tools).

``register_decoder(encoding, fn)`` adds one; ``decode(encoding, data)`` applies it. A decoder
returns a flat ``{field: int | float}`` dict and raises :class:`DecodeError` (a ValueError)
for bytes that are not a frame of its encoding. Block channels may also register a batch
decoder (frames array -> column arrays), which export uses when present.

Shipped encodings (byte layouts in ``docs/framelog.md``):

* ``eha-hil/lvds-word``: one 45-bit LVDS line word (:mod:`protocols.lvds`), 8 bytes LE.
* ``eha-hil/lvds-up``: upstream snapshot, 31 x u16 LE in register order (UP_REGISTERS).
* ``eha-hil/lvds-down``: downstream writes, (addr u8, data u16 LE) triplets (DOWN_REGISTERS).
* ``eha-hil/ethercat``: one Ethernet frame carrying EtherCAT (direct or over UDP).
* ``eha-hil/ethercat-fcs``: an EtherCAT PDU and its Ethernet FCS (what ``bus run`` logs).
* ``eha-hil/sensor-raw``: the sensor masters' raw inputs of one tick, 17 x u32 LE (RAW_NAMES).
* ``json``: a JSON object; numbers (nested objects flattened as ``a.b``), bools as 0/1.
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from collections.abc import Callable

import numpy as np

from firmware_model.fpga.layout import (
    DOWN_REGISTERS,
    FIRST_N_RAW,
    FIRST_N_UP,
    RAW_NAMES,
    UP_REGISTERS,
)
from hil.framelog.formats import (
    ENC_ETHERCAT,
    ENC_ETHERCAT_FCS,
    ENC_JSON,
    ENC_LVDS_DOWN,
    ENC_LVDS_UP,
    ENC_LVDS_WORD,
    ENC_SENSOR_RAW,
)
from protocols import ethercat, lvds
from protocols.errors import CodecError

Value = int | float
Decoder = Callable[[bytes], dict[str, Value]]
BatchDecoder = Callable[[np.ndarray], dict[str, np.ndarray]]


class DecodeError(ValueError):
    """Bytes that are not a frame of the encoding they were logged under."""


_DECODERS: dict[str, Decoder] = {}
_BATCH: dict[str, BatchDecoder] = {}


def register_decoder(encoding: str, fn: Decoder, batch: BatchDecoder | None = None) -> None:
    """Register (or replace) the decoder of ``encoding``; ``batch`` optionally decodes a
    (n, width) frames array of a block channel into columns of the same fields."""
    _DECODERS[encoding] = fn
    if batch is not None:
        _BATCH[encoding] = batch
    else:
        _BATCH.pop(encoding, None)


def decoders() -> tuple[str, ...]:
    """Encodings with a registered decoder."""
    return tuple(sorted(_DECODERS))


def has_decoder(encoding: str) -> bool:
    """True if ``encoding`` has a decoder."""
    return encoding in _DECODERS


def decode(encoding: str, data: bytes) -> dict[str, Value]:
    """Decode one frame; KeyError for an encoding without decoder, DecodeError for bad bytes."""
    try:
        fn = _DECODERS[encoding]
    except KeyError:
        raise KeyError(f"no decoder for encoding {encoding!r}") from None
    return fn(bytes(data))


def decode_block(encoding: str, frames: np.ndarray) -> dict[str, np.ndarray] | None:
    """Columns of a frames array with the batch decoder of ``encoding``; None if it has none."""
    fn = _BATCH.get(encoding)
    return None if fn is None else fn(frames)


# --- LVDS -----------------------------------------------------------------------------------
# A log written with an older layout holds the first registers / raw words of today's
# (layouts only append): frames of FIRST_N_UP .. len(UP_REGISTERS) words decode.
_UP_NAMES = tuple(r[1] for r in UP_REGISTERS)
_UP_SIGNED = np.array([r[2] == "s16" for r in UP_REGISTERS])
_UP_WIDTHS = range(FIRST_N_UP, len(UP_REGISTERS) + 1)
_UP_STRUCTS = {2 * n: struct.Struct("<" + "".join("h" if r[2] == "s16" else "H"
                                                  for r in UP_REGISTERS[:n]))
               for n in _UP_WIDTHS}
_DOWN = {r[0]: (r[1], r[2] == "s16") for r in DOWN_REGISTERS}
_RAW_WIDTHS = range(FIRST_N_RAW, len(RAW_NAMES) + 1)


def _lvds_word(data: bytes) -> dict[str, Value]:
    if len(data) != 8:
        raise DecodeError(f"lvds-word frame must be 8 bytes, got {len(data)}")
    cols = _lvds_word_batch(np.frombuffer(data, "<u8").reshape(1, 1))
    return {k: int(v[0]) for k, v in cols.items()}


def _lvds_word_batch(frames: np.ndarray) -> dict[str, np.ndarray]:
    # Bits above the 45 of a word make frame_ok false (unpack_array checks them).
    words = np.ascontiguousarray(frames, dtype=np.uint64).reshape(-1)
    vals, frame_ok, crc_ok = lvds.LAYOUT.unpack_array(words)
    data = (vals["data_hi"] << np.uint64(8)) | vals["data_lo"]
    return {"addr": vals["addr"].astype(np.int64), "data": data.astype(np.int64),
            "frame_ok": frame_ok.astype(np.int64), "crc_ok": (frame_ok & crc_ok).astype(np.int64)}


def _lvds_up(data: bytes) -> dict[str, Value]:
    layout = _UP_STRUCTS.get(len(data))
    if layout is None:
        raise DecodeError(f"lvds-up frame must be {_sizes(_UP_WIDTHS, 2)} bytes "
                          f"(u16 registers), got {len(data)}")
    return dict(zip(_UP_NAMES, layout.unpack(data), strict=False))


def _sizes(widths: range, per_word: int) -> str:
    """The frame sizes a log of some layout may have, for a message: ``62`` or ``62..64``."""
    lo, hi = per_word * widths[0], per_word * widths[-1]
    return str(hi) if lo == hi else f"{lo}..{hi}"


def _lvds_up_batch(frames: np.ndarray) -> dict[str, np.ndarray]:
    if frames.shape[1] not in _UP_WIDTHS:
        raise DecodeError(f"lvds-up frames must be {_sizes(_UP_WIDTHS, 1)} words wide, "
                          f"got {frames.shape[1]}")
    u = np.ascontiguousarray(frames, dtype=np.uint16)
    s = u.view(np.int16)
    return {n: (s[:, i] if _UP_SIGNED[i] else u[:, i]).astype(np.int64)
            for i, n in enumerate(_UP_NAMES[:frames.shape[1]])}


def _lvds_down(data: bytes) -> dict[str, Value]:
    if len(data) % 3:
        raise DecodeError(f"lvds-down frame must be (addr, data u16) triplets, got {len(data)} "
                          "bytes")
    out: dict[str, Value] = {}
    for i in range(0, len(data), 3):
        addr, value = data[i], data[i + 1] | data[i + 2] << 8
        name, signed = _DOWN.get(addr, (f"addr_{addr:#04x}", False))
        out[name] = value - 0x10000 if signed and value & 0x8000 else value
    return out


def down_writes(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(addr, data)`` int64 arrays of an lvds-down block channel's (n, 3) uint8 frames."""
    f = np.asarray(frames, dtype=np.uint8)
    if f.ndim != 2 or f.shape[1] != 3:
        raise DecodeError(f"lvds-down block frames must be (n, 3) bytes, got {f.shape}")
    return f[:, 0].astype(np.int64), f[:, 1].astype(np.int64) | f[:, 2].astype(np.int64) << 8


# --- EtherCAT -------------------------------------------------------------------------------
def _datagram_fields(dgs: list) -> dict[str, Value]:
    """Command, index, address, length and working counter of each datagram, ``dg<i>.``."""
    out: dict[str, Value] = {}
    for i, d in enumerate(dgs):
        p = f"dg{i}."
        out[p + "cmd"] = d.cmd
        out[p + "idx"] = d.idx
        out[p + "address"] = d.adp | d.ado << 16
        out[p + "length"] = len(d.data)
        out[p + "wkc"] = d.wkc
    return out


def _ethercat(data: bytes) -> dict[str, Value]:
    try:
        dgs = ethercat.decode_any(data)
    except CodecError as exc:
        raise DecodeError(f"EtherCAT frame: {exc}") from None
    out: dict[str, Value] = {"frame_bytes": len(data), "datagrams": len(dgs)}
    out.update(_datagram_fields(dgs))
    return out


def _ethercat_fcs(data: bytes) -> dict[str, Value]:
    # An EtherCAT PDU followed by its Ethernet FCS (hil.fieldbus.wire), as bus run logs it.
    if len(data) <= 4:
        raise DecodeError(f"ethercat-fcs frame of {len(data)} bytes has no PDU")
    pdu = data[:-4]
    fcs_ok = int((zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") == data[-4:])
    try:
        dgs = ethercat.decode_pdu(pdu, allow_trailing=False)
    except CodecError as exc:
        raise DecodeError(f"EtherCAT PDU: {exc}") from None
    out: dict[str, Value] = {"frame_bytes": len(data), "fcs_ok": fcs_ok, "datagrams": len(dgs)}
    out.update(_datagram_fields(dgs))
    return out


# --- sensors, JSON --------------------------------------------------------------------------
def _sensor_raw(data: bytes) -> dict[str, Value]:
    n, rest = divmod(len(data), 4)
    if rest or n not in _RAW_WIDTHS:
        raise DecodeError(f"sensor-raw frame must be {_sizes(_RAW_WIDTHS, 4)} bytes "
                          f"(u32 words), got {len(data)}")
    return dict(zip(RAW_NAMES, struct.unpack(f"<{n}I", data), strict=False))


def _sensor_raw_batch(frames: np.ndarray) -> dict[str, np.ndarray]:
    if frames.shape[1] not in _RAW_WIDTHS:
        raise DecodeError(f"sensor-raw frames must be {_sizes(_RAW_WIDTHS, 1)} wide, "
                          f"got {frames.shape[1]}")
    return {n: frames[:, i].astype(np.int64) for i, n in enumerate(RAW_NAMES[:frames.shape[1]])}


def _flatten(obj: object, prefix: str, out: dict[str, Value]) -> None:
    if isinstance(obj, dict):
        for k, v in obj.items():
            _flatten(v, f"{prefix}{k}.", out)
        return
    key = prefix[:-1]
    if isinstance(obj, bool):
        out[key] = int(obj)
    elif isinstance(obj, int | float):
        out[key] = obj
    elif obj is None:
        out[key] = math.nan  # what write_json stores for a non-finite value
    # strings and lists carry no plottable number: left out


def _json(data: bytes) -> dict[str, Value]:
    try:
        obj = json.loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise DecodeError(f"not JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise DecodeError(f"JSON frame is a {type(obj).__name__}, not an object")
    out: dict[str, Value] = {}
    _flatten(obj, "", out)
    return out


register_decoder(ENC_LVDS_WORD, _lvds_word, _lvds_word_batch)
register_decoder(ENC_LVDS_UP, _lvds_up, _lvds_up_batch)
register_decoder(ENC_LVDS_DOWN, _lvds_down)
register_decoder(ENC_ETHERCAT, _ethercat)
register_decoder(ENC_ETHERCAT_FCS, _ethercat_fcs)
register_decoder(ENC_SENSOR_RAW, _sensor_raw, _sensor_raw_batch)
register_decoder(ENC_JSON, _json)


# --- encoders (the other direction, for writers and tests) ---------------------------------
def encode_lvds_word(addr: int, data: int) -> bytes:
    """8-byte LE frame of the 45-bit line word of (addr, data) (``lvds.encode_word``)."""
    return lvds.encode_word(addr, data).to_bytes(8, "little")


def encode_lvds_up(registers: np.ndarray | list[int]) -> bytes:
    """Frame of the upstream registers (raw 16-bit words, or signed values), 2 bytes each."""
    r = np.asarray(registers, dtype=np.int64)
    if r.shape != (len(UP_REGISTERS),):
        raise ValueError(f"need {len(UP_REGISTERS)} upstream registers, got shape {r.shape}")
    return (r & 0xFFFF).astype("<u2").tobytes()


def encode_lvds_down(writes: list[tuple[int, int]]) -> bytes:
    """Frame of (addr, data) writes; data is the raw 16-bit word (or a negative s16)."""
    out = bytearray()
    for addr, data in writes:
        if not 0 <= addr <= 0xFF or not -0x8000 <= data <= 0xFFFF:
            raise ValueError(f"write ({addr}, {data}) out of range (addr u8, data 16 bit)")
        out += bytes((addr, data & 0xFF, (data >> 8) & 0xFF))
    return bytes(out)


def encode_sensor_raw(raw: np.ndarray | list[int]) -> bytes:
    """68-byte frame of the 17 raw sensor inputs (each 0..2^32-1)."""
    r = np.asarray(raw, dtype=np.int64)
    if r.shape != (len(RAW_NAMES),) or (r.size and (r.min() < 0 or r.max() > 0xFFFFFFFF)):
        raise ValueError(f"need {len(RAW_NAMES)} raw values in 0..2^32-1, got {r!r}")
    return r.astype("<u4").tobytes()
