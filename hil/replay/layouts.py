"""The byte layouts of the raw channels a ``bus run`` log writes (their MCAP schemas).

One function per frame encoding of :mod:`hil.replay.record`; each returns a
:class:`hil.framelog.layout.Layout` built from the declarations the frames come from
(the register maps of ``firmware_model/fpga/layout.py``, the process records of
:mod:`hil.fieldbus.pdo`, the trace columns of :mod:`hil.sim.actuator`), so schema and frames
cannot drift apart.
"""

from __future__ import annotations

from firmware_model.fpga import layout as B
from firmware_model.lvds import link as LK
from hil.fieldbus import pdo
from hil.fieldbus.topology import Box
from hil.framelog.formats import ENC_MCU_UP, MCU_UP_WIDTH, MCU_UP_WIDTH_U32
from hil.framelog.layout import Layout, LayoutField, words
from hil.sim.actuator import (
    TRACE_DOWN,
    TRACE_LINK,
    TRACE_ON,
    TRACE_RAW,
    TRACE_UP,
    TRACE_WIDTH,
    TRACE_WORDS,
)

ENC_MCU_DOWN = "eha-hil/lvds-down-registers"  # 13 downstream registers, uint16
ENC_RECORD = "eha-hil/process-record"  # a box's fieldbus record, bytes
ENC_TRACE = "eha-hil/fpga-trace"
ENC_LVDS_WORD = "eha-hil/lvds-word"
ENC_SENSOR_RAW = "eha-hil/sensor-raw"

_UP = [(name, "s16" if t == "s16" else "u16") for _, name, t, *_ in B.UP_REGISTERS]
_DOWN = [(name, "s16" if t == "s16" else "u16") for _, name, t, *_ in B.DOWN_REGISTERS]
_PDO_TYPES = {"u1": "u8", "u2": "u16", "i2": "s16", "i4": "i32"}


def mcu_up() -> Layout:
    """The 32 upstream registers as read by the MCU (u16 or s16 each), then its upstream
    CRC-error count (u32 at byte 64): 68 bytes, written as uint16 x 34."""
    return words(ENC_MCU_UP, _UP, 2, [("up_crc_errors", "u32")], MCU_UP_WIDTH)


def mcu_up_u32() -> Layout:
    """The layout of logs before :func:`mcu_up`: each register in a u32 (read from its low
    half), then the CRC-error count: 132 bytes, uint32 x 33 (tests write such logs)."""
    return words(ENC_MCU_UP, _UP, 4, [("up_crc_errors", "u32")], MCU_UP_WIDTH_U32)


def mcu_down() -> Layout:
    """The 13 downstream registers after an MCU step (words 13..15 unused), u16 each."""
    return words(ENC_MCU_DOWN, _DOWN, 2, total=B.DOWN_WORDS)


def process_record(box: Box, direction: str) -> Layout:
    """A box's ``outputs`` or ``inputs`` record: per slot ``s<k>_<field>``, scaled to SI;
    the output ``command`` stays a count (0.01 N in force mode, 1 nm in position mode)."""
    which = 0 if direction == "outputs" else 1
    fields, off = [], 0
    for k, s in enumerate(box.slots):
        for f in pdo.SLOT_FIELDS[s.kind][which]:
            scale = f.lsb if f.lsb not in (0.0,) and f.unit else 1.0
            fields.append(LayoutField(f"s{k}_{f.name}", off, _PDO_TYPES[f.dtype], scale,
                                      f.unit if f.lsb and f.unit else ""))
            off += int(f.dtype[1])
    return Layout(ENC_RECORD, max(off, 1), tuple(fields))


def fpga_trace() -> Layout:
    """One driver-board tick (int64 each): raw sensor words, downstream memory, link
    watchdog and CRC counts, upstream memory, PWM on, compare counts, word logs."""
    names = [(f"raw_{n}", TRACE_RAW + i) for i, n in enumerate(B.RAW_NAMES)]
    names += [(f"down_{n}", TRACE_DOWN + i) for i, (n, _) in enumerate(_DOWN)]
    names += [("link_since_valid", TRACE_LINK), ("link_crc_errors", TRACE_LINK + 1)]
    names += [(f"up_{n}", TRACE_UP + i) for i, (n, _) in enumerate(_UP)]
    names += [("pwm_on", TRACE_ON), ("duty_a", TRACE_ON + 1), ("duty_b", TRACE_ON + 2),
              ("duty_c", TRACE_ON + 3)]
    for d, side in enumerate(("down", "up")):
        names += [(f"{side}_wordlog_{i}", TRACE_WORDS + d * LK.WORDS_W + i)
                  for i in range(LK.WORDS_W)]
    fields = tuple(LayoutField(n, 8 * col, "i64") for n, col in names)
    return Layout(ENC_TRACE, 8 * TRACE_WIDTH, fields)


def lvds_word() -> Layout:
    """One 45-bit LVDS line word in a u64."""
    return Layout(ENC_LVDS_WORD, 8, (LayoutField("word", 0, "u64"),))


def sensor_raw() -> Layout:
    """The sensor masters' 17 raw words of one tick, u32 each."""
    return words(ENC_SENSOR_RAW, [(n, "u32") for n in B.RAW_NAMES], 4)
