"""Names and byte layouts shared by the frame-log writer, reader and decoders.

Everything here is a plain constant or a pure function; ``docs/framelog.md`` explains the
choices. Times are integer nanoseconds of *simulated* time throughout the package.
"""

from __future__ import annotations

import struct

import numpy as np

#: MCAP header profile of our logs (a custom profile: MCAP allows any string).
PROFILE = "eha-hil"
#: Name of the Metadata record that holds the run's description (level, config, seed, ...).
METADATA_NAME = "eha-hil"

# --- frame encodings (the ``encoding`` of a channel: what one frame's bytes mean) --------
ENC_LVDS_WORD = "eha-hil/lvds-word"
ENC_LVDS_UP = "eha-hil/lvds-up"
ENC_LVDS_DOWN = "eha-hil/lvds-down"
ENC_ETHERCAT = "eha-hil/ethercat"
ENC_ETHERCAT_FCS = "eha-hil/ethercat-fcs"  # an EtherCAT PDU + its Ethernet FCS (bus run)
ENC_SENSOR_RAW = "eha-hil/sensor-raw"
ENC_JSON = "json"
#: What one MCU step read from a driver board (``bus run --log``): the 32 upstream words
#: and the MCU side's upstream CRC-error count. Written as uint16 x 34 (the words, then
#: the count as one little-endian u32, low half first: 68 bytes); logs before that hold
#: uint32 x 33 (each word in a u32, then the count: 132 bytes). :func:`split_mcu_up`
#: reads either.
ENC_MCU_UP = "eha-hil/mcu-up"
MCU_UP_WORDS = 32
MCU_UP_WIDTH = MCU_UP_WORDS + 2     # uint16 elements per frame
MCU_UP_WIDTH_U32 = MCU_UP_WORDS + 1  # uint32 elements per frame (logs before)

#: MCAP message encoding of a block channel; the frame encoding is in the channel metadata.
BLOCK_MESSAGE_ENCODING = "eha-hil/block"
#: Channel metadata keys we set (MCAP channel metadata is str -> str).
META_FRAMING = "eha-hil.framing"          # "single" | "block"
META_FRAME_ENCODING = "eha-hil.frame_encoding"
META_DTYPE = "eha-hil.dtype"              # block channels: numpy dtype name, e.g. "uint16"
META_WIDTH = "eha-hil.width"              # block channels: elements per frame
META_UNITS = "eha-hil.units"              # decoded-signal channels: JSON {field: SI unit}
META_LAYOUT = "eha-hil.layout"            # raw channels: one frame's byte layout (JSON)
META_CONTAINER = "eha-hil.container"      # raw channels: "protobuf" = frames wrapped (rawpb)

# --- levels of detail -------------------------------------------------------------------
#: Link kinds a simulation may log; a level includes the kinds listed for it.
LEVELS: dict[str, tuple[str, ...]] = {
    "bus": ("fieldbus", "signals"),
    "mcu": ("fieldbus", "signals", "lvds"),
    "full": ("fieldbus", "signals", "lvds", "sensors"),
}


def level_includes(level: str, kind: str) -> bool:
    """True if a log at ``level`` records links of ``kind`` (fieldbus, signals, lvds, sensors).

    ValueError for an unknown level; an unknown kind is simply not included.
    """
    try:
        return kind in LEVELS[level]
    except KeyError:
        raise ValueError(f"unknown log level {level!r} (use {', '.join(LEVELS)})") from None


# --- topic names --------------------------------------------------------------------------
FIELDBUS_TOPIC = "/fieldbus/frames"


def lvds_topic(board: str | int, direction: str) -> str:
    """``/lvds/<board>/up`` or ``/lvds/<board>/down``."""
    if direction not in ("up", "down", "up/words", "down/words"):
        raise ValueError(f"LVDS direction {direction!r} is not up, down, up/words, down/words")
    return f"/lvds/{board}/{direction}"


def sensor_topic(board: str | int, sensor: str) -> str:
    """``/sensors/<board>/<sensor>``."""
    return f"/sensors/{board}/{sensor}"


def signal_topic(name: str) -> str:
    """``/signals/<name>``: a JSON channel of decoded or computed signals."""
    return f"/signals/{name.lstrip('/')}"


# --- block messages -----------------------------------------------------------------------
#: Block header: magic "EHB1", frame count u32, elements per frame u32, dtype code u8, 3 pad.
#: 16 bytes, so the int64 times that follow start 8-byte aligned within the message.
BLOCK_HEADER = struct.Struct("<4sIIB3x")
BLOCK_MAGIC = b"EHB1"

#: dtype code -> numpy dtype (little endian on disk whatever the host).
DTYPE_CODES: dict[int, np.dtype] = {
    1: np.dtype("<u1"), 2: np.dtype("<u2"), 3: np.dtype("<u4"), 4: np.dtype("<u8"),
    5: np.dtype("<i1"), 6: np.dtype("<i2"), 7: np.dtype("<i4"), 8: np.dtype("<i8"),
    9: np.dtype("<f4"), 10: np.dtype("<f8"),
}
_CODE_OF = {dt.str: code for code, dt in DTYPE_CODES.items()}
_TIMES = np.dtype("<i8")


def dtype_code(dtype: np.dtype | str | type) -> int:
    """The block dtype code of a numpy dtype; ValueError for anything not in the table."""
    dt = np.dtype(dtype).newbyteorder("<")
    try:
        return _CODE_OF[dt.str]
    except KeyError:
        raise ValueError(f"dtype {np.dtype(dtype)} cannot be logged in a block "
                         f"(use one of {', '.join(str(d) for d in DTYPE_CODES.values())})"
                         ) from None


def pack_block(t_ns: np.ndarray, frames: np.ndarray) -> bytes:
    """One block message: header, ``count`` int64 times (ns), then the frames row by row.

    ``frames`` has shape (count, width); it is written little endian.
    """
    count, width = frames.shape
    code = dtype_code(frames.dtype)
    dt = DTYPE_CODES[code]
    return b"".join((
        BLOCK_HEADER.pack(BLOCK_MAGIC, count, width, code),
        np.ascontiguousarray(t_ns, dtype=_TIMES).tobytes(),
        np.ascontiguousarray(frames, dtype=dt).tobytes(),
    ))


def unpack_block(data: bytes | memoryview) -> tuple[np.ndarray, np.ndarray]:
    """``(t_ns (count,) int64, frames (count, width))`` of a block message (views, no copy).

    ValueError if the header or the length is wrong.
    """
    if len(data) < BLOCK_HEADER.size:
        raise ValueError(f"block of {len(data)} bytes is shorter than its 16-byte header")
    magic, count, width, code = BLOCK_HEADER.unpack_from(data)
    if magic != BLOCK_MAGIC:
        raise ValueError(f"block magic {magic!r} is not {BLOCK_MAGIC!r}")
    dt = DTYPE_CODES.get(code)
    if dt is None:
        raise ValueError(f"block dtype code {code} unknown")
    need = BLOCK_HEADER.size + count * 8 + count * width * dt.itemsize
    if len(data) != need:
        raise ValueError(f"block of {count} x {width} {dt} frames needs {need} bytes, "
                         f"has {len(data)}")
    t = np.frombuffer(data, _TIMES, count, BLOCK_HEADER.size)
    frames = np.frombuffer(data, dt, count * width, BLOCK_HEADER.size + count * 8)
    return t, frames.reshape(count, width)


def split_mcu_up(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(words (..., 32) int64, crc_errors (...) int64)`` of ``eha-hil/mcu-up`` frames
    ``(..., 34)`` uint16 (this layout) or ``(..., 33)`` uint32 (logs before it).
    ValueError for any other shape."""
    f = np.asarray(frames)
    width = f.shape[-1] if f.ndim else 0
    if width == MCU_UP_WIDTH and f.dtype.itemsize == 2:
        crc = f[..., MCU_UP_WORDS].astype(np.int64) | (
            f[..., MCU_UP_WORDS + 1].astype(np.int64) << 16)
    elif width == MCU_UP_WIDTH_U32 and f.dtype.itemsize == 4:
        crc = f[..., MCU_UP_WORDS].astype(np.int64)
    else:
        raise ValueError(f"{ENC_MCU_UP} frames are {MCU_UP_WIDTH} x uint16 (or "
                         f"{MCU_UP_WIDTH_U32} x uint32 in older logs), not {width} x "
                         f"{f.dtype}")
    return f[..., :MCU_UP_WORDS].astype(np.int64), crc
