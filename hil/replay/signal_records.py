"""The boxes' process records as decoded-signal messages, decoded and encoded in one
compiled call per block.

:func:`hil.replay.signals.record_columns` + :meth:`~hil.framelog.protobuf.MessageType.encode_into`
is the readable reference: numpy per field of the record (a column each, then a strided
copy of each into the message bytes), ~100 small numpy operations per group of boxes and
block. A whole-robot log writes 30,000 of these messages per simulated second (both
directions of 15 boxes, each cycle): that path cost ~6 ms CPU per simulated second
(``record_columns`` ~2.9, the copies into the messages ~3), this one ~1.6 (``python -m
hil.bench.log_parts 3 hydra_full 2``, load 12-15, interleaved).
:class:`RecordEncoder` reads each field straight from the record bytes and writes its value
into the message's place, with the same float64 operations (count x lsb; the command x its
mode's lsb, NaN in the other modes) and the same rounding of a ``float`` field: the
messages are the reference's, byte for byte (``tests/replay/test_signal_records.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hil.fieldbus import pdo
from hil.fieldbus.topology import Box
from hil.framelog.protobuf import MessageType
from hil.replay import signals as SG
from hil.replay.signal_kernel import _b1, _fx, _u4

#: Columns of a plan row (one per message field read from the record).
P_SRC, P_TYPE, P_OP, P_DST, P_SINGLE, P_MODE, P_CODE = range(7)
#: How a field is read: its record dtype.
_TYPES = {"u1": 0, "u2": 1, "i2": 2, "i4": 3, "u4": 4}
#: What is written: the raw count (fixed32), count x lsb, count x lsb in one mode else NaN.
OP_COUNT, OP_SCALE, OP_BY_MODE = 0, 1, 2


@njit(cache=True, inline="always")
def _read(rows, b, i, off, code):
    """The record field at byte ``off`` of ``rows[b, i]`` (little endian), as int64."""
    v = np.int64(rows[b, i, off])
    if code == 0:
        return v
    v |= np.int64(rows[b, i, off + 1]) << 8
    if code == 1:
        return v
    if code == 2:
        return v - ((v & 0x8000) << 1)
    v |= (np.int64(rows[b, i, off + 2]) << 16) | (np.int64(rows[b, i, off + 3]) << 24)
    if code == 3:
        return v - ((v & 0x80000000) << 1)
    return v


@njit(cache=True, nogil=True)
def _encode(rows, plan, scale, x_ok, v_ok, pick, flag_off, out):
    """See :meth:`RecordEncoder.encode`. A field at a time over every message, with one
    loop per operation (as numpy's column operations, without their temporaries): one
    loop that branched on the field's operation inside ran 10x slower."""
    m, c = rows.shape[0], rows.shape[1]
    for f in range(plan.shape[0]):
        src, typ, op, at = plan[f, P_SRC], plan[f, P_TYPE], plan[f, P_OP], plan[f, P_DST]
        single, lsb = plan[f, P_SINGLE] != 0, scale[f]
        if op == OP_COUNT:
            for b in range(m):
                for i in range(c):
                    _u4(out, b * c + i, at, _read(rows, b, i, src, typ))
        elif op == OP_SCALE:
            for b in range(m):
                for i in range(c):
                    _fx(out, b * c + i, at, single, np.float64(_read(rows, b, i, src, typ)) * lsb)
        else:  # OP_BY_MODE: the value in its mode, NaN in any other
            mode_at, code = plan[f, P_MODE], plan[f, P_CODE]
            for b in range(m):
                for i in range(c):
                    x = math.nan
                    if np.int64(rows[b, i, mode_at]) == code:
                        x = np.float64(_read(rows, b, i, src, typ)) * lsb
                    _fx(out, b * c + i, at, single, x)
    for s in range(pick.shape[0]):
        x_at, v_at = flag_off[s, 0], flag_off[s, 1]
        for b in range(m):
            a = pick[s, b]
            for i in range(c):
                _b1(out, b * c + i, x_at, x_ok[a, i])
                _b1(out, b * c + i, v_at, v_ok[a, i])


class RecordEncoder:
    """Encodes blocks of ``box``'s ``direction`` records (``outputs``/``inputs``) as
    ``message`` (:func:`hil.replay.signals.record_message` of a box of that slot layout):
    the compiled equivalent of :func:`~hil.replay.signals.record_columns` +
    ``message.encode_into``."""

    def __init__(self, box: Box, direction: str, message: MessageType) -> None:
        which = 0 if direction == "outputs" else 1
        fields = message.record.fields
        kinds = {f.name: f.kind for f in message.fields}
        plan, scale, flags = [], [], []
        covered = set()

        def dst(name: str, *allowed: str) -> int:
            if kinds.get(name) not in allowed:
                raise ValueError(f"{message.full_name}: field {name} is "
                                 f"{kinds.get(name, 'missing')}, expected {' or '.join(allowed)}")
            covered.add(name)
            return fields[name][1]

        base = 0  # the slot's first byte in the record
        for k, slot in enumerate(box.slots):
            dt = pdo.record_dtype(pdo.SLOT_FIELDS[slot.kind][which])
            if slot.kind in SG.SIMULATED_KINDS:
                mode_at = base + dt.fields["mode"][1] if "mode" in dt.names else -1
                for f in pdo.SLOT_FIELDS[slot.kind][which]:
                    src, typ = base + dt.fields[f.name][1], _TYPES[f.dtype]
                    if f.lsb == 0.0:  # the command: its unit by the mode
                        for mode, lsb, name in (
                                (pdo.MODE_CODES["force"], pdo.FORCE_CMD_LSB,
                                 f"s{k}_force_command_n"),
                                (pdo.MODE_CODES["position"], pdo.POSITION_CMD_LSB,
                                 f"s{k}_position_command_m")):
                            plan.append((src, typ, OP_BY_MODE, dst(name, "double"),
                                         0, mode_at, mode))
                            scale.append(lsb)
                    elif f.unit:
                        name = f"s{k}_{f.name}_{SG._suffix(f.unit)}"  # noqa: SLF001
                        plan.append((src, typ, OP_SCALE, dst(name, "double", "float"),
                                     int(kinds[name] == "float"), -1, 0))
                        scale.append(f.lsb)
                    else:
                        plan.append((src, typ, OP_COUNT, dst(f"s{k}_{f.name}", "fixed32"),
                                     0, -1, 0))
                        scale.append(0.0)
            base += dt.itemsize
        if direction == "inputs":
            for k in SG._actuator_slots(box):  # noqa: SLF001
                flags.append((dst(f"s{k}_x_piston_valid", "bool"),
                              dst(f"s{k}_v_piston_valid", "bool")))
        if covered != set(kinds):
            raise ValueError(f"{message.full_name}: fields {sorted(set(kinds) - covered)} "
                             f"are not in box {box.id}'s {direction} record")
        self.message = message
        self.bytes = base
        self.plan = np.array(plan, np.int64).reshape(-1, 7)
        self.scale = np.array(scale, np.float64)
        self.flag_off = np.array(flags, np.int64).reshape(-1, 2)
        self.blank = np.ascontiguousarray(message._blank.reshape(-1))  # noqa: SLF001
        self._no_flags = np.zeros((1, 1), bool)

    def encode(self, rows: np.ndarray, out: np.ndarray,
               flags: tuple[np.ndarray, np.ndarray] | None = None,
               pick: np.ndarray | None = None) -> np.ndarray:
        """The messages of ``rows`` ((m boxes, c cycles, record bytes) uint8) into ``out``
        ((m * c, size) uint8, box-major, rows of any stride: every byte written);
        ``flags``: every actuator's (x valid, v valid) per cycle, (actuators, c) bool each
        (:func:`hil.replay.signals.report_flags`), ``pick``: (actuator slots per box, m)
        the row of each box's actuators in them (the inputs of boxes with actuators)."""
        m, c = rows.shape[:2]
        size = len(self.blank)
        if rows.ndim != 3 or rows.shape[2] != self.bytes or rows.dtype != np.uint8:
            raise ValueError(f"need rows (m, c, {self.bytes}) uint8, got {rows.shape} "
                             f"{rows.dtype}")
        if out.shape != (m * c, size) or out.dtype != np.uint8 or out.strides[1] != 1:
            raise ValueError(f"need out ({m * c}, {size}) uint8, got {out.shape} {out.dtype}")
        n_flags = len(self.flag_off)
        if n_flags and (flags is None or pick is None):
            raise ValueError("the inputs of a box with actuators need their piston flags")
        if n_flags:
            x_ok, v_ok = flags
            pick = np.ascontiguousarray(pick, np.int64)
            if pick.shape != (n_flags, m) or x_ok.shape[1] != c or v_ok.shape != x_ok.shape:
                raise ValueError(f"need pick ({n_flags}, {m}) and flags (a, {c}), got "
                                 f"{pick.shape}, {x_ok.shape}, {v_ok.shape}")
        else:
            x_ok = v_ok = self._no_flags
            pick = np.zeros((0, m), np.int64)
        out[:] = self.blank  # every key; the kernel writes every value
        _encode(np.ascontiguousarray(rows), self.plan, self.scale,
                np.ascontiguousarray(x_ok, np.bool_), np.ascontiguousarray(v_ok, np.bool_),
                pick, self.flag_off, out)
        return out


def warm_up() -> None:
    """Compile :func:`_encode` for the argument types the recorder passes (messages into
    an array of their own, and into their places in records), on one box of each kind."""
    from hil.fieldbus.topology import Slot

    box = Box(0, (Slot("s0", "actuator"),))
    for d in ("outputs", "inputs"):
        message = SG.record_message(box, d)
        enc = RecordEncoder(box, d, message)
        rows = np.zeros((1, 1, enc.bytes), np.uint8)
        flags = (np.ones((1, 1), bool), np.ones((1, 1), bool))
        records = np.zeros((1, message.size + 1), np.uint8)
        for out in (np.empty((1, message.size), np.uint8), records[:, 1:]):
            enc.encode(rows, out, flags, np.zeros((1, 1), np.int64))
