"""The actuators' decoded signals of a block of MCU steps, decoded and encoded in one
compiled call.

:func:`hil.replay.signals.actuator_block` (with :func:`~hil.replay.signals.pc_command_block`
and :meth:`~hil.framelog.protobuf.MessageType.encode_array`) is the readable reference:
numpy over whole columns, ~40 temporary arrays per block and a copy per field into the
message bytes. A whole-robot log decodes 47,000 of these messages per simulated second,
and that path cost ~30 ms of CPU per simulated second, an eighth of what the log adds to
the run. :class:`ActuatorEncoder` computes the same values with the same float64
operations in the same order, one actuator step at a time, and writes them straight into
the protobuf message bytes (the fixed layout of :class:`~hil.framelog.protobuf.MessageType`),
optionally behind the head of the MCAP record each message goes into. The messages and
the :class:`~hil.replay.signals.PistonCarry` it leaves are the reference's, byte for byte
(``tests/replay/test_signal_kernel.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga import layout as B
from firmware_model.mcu import measure
from hil.fieldbus import pdo
from hil.framelog.heads import store as _store
from hil.framelog.protobuf import MessageType
from hil.replay import signals as SG
from protocols import pressure_adc as padc
from protocols.biss import LINEAR_COUNT_M

#: Every field an actuator message has had (:data:`hil.replay.signals.ACTUATOR_ALL_DOUBLE`:
#: today's and the PC's command of older logs), in that order; the kernel writes field
#: ``FIELDS[i]`` at byte ``off[i]`` of a message (-1: not in this message type).
FIELDS = tuple(f.name for f in SG.ACTUATOR_ALL_DOUBLE.fields)
_I = {name: i for i, name in enumerate(FIELDS)}
_ANALOG_NAMES = tuple(field for _, field in SG._ANALOG)  # noqa: SLF001 - one declaration
_STATUS_NAMES = tuple(f.name for f in SG._STATUS_FIELDS)  # noqa: SLF001
# field indices the kernel writes by name (checked against FIELDS below)
F_PC_MODE, F_PC_ENABLE, F_FORCE, F_POSITION = 0, 1, 2, 3
F_IQ_REF, F_ID_REF, F_VQ_FF, F_BOARD_MODE, F_BOARD_CONTROL = 4, 5, 6, 7, 8
F_ANALOG = 9  # the analog inputs, in declaration order
F_F_PRESSURE = F_ANALOG + len(_ANALOG_NAMES)
(F_F_STRAIN, F_X, F_V, F_OMEGA, F_IQ, F_ID, F_IA, F_IB, F_VD, F_VQ, F_STATUS,
 F_STATE) = range(F_F_PRESSURE + 1, F_F_PRESSURE + 13)
F_STATUS_BITS = F_STATE + 1
(F_ERR_SSI, F_ERR_BISS, F_ERR_STRAIN, F_ERR_LINK_DOWN, F_ERR_LINK_UP, F_OC_TRIPS,
 F_WD_TRIPS, F_X_VALID, F_V_VALID, F_UP_VALID) = range(F_STATUS_BITS + len(_STATUS_NAMES),
                                                    F_STATUS_BITS + len(_STATUS_NAMES) + 10)
_NAMED = {
    "pc_mode": F_PC_MODE, "pc_enable": F_PC_ENABLE, "force_command_n": F_FORCE,
    "position_command_m": F_POSITION, "iq_ref_a": F_IQ_REF, "id_ref_a": F_ID_REF,
    "vq_ff_v": F_VQ_FF, "board_mode": F_BOARD_MODE, "board_control": F_BOARD_CONTROL,
    **{name: F_ANALOG + i for i, name in enumerate(_ANALOG_NAMES)},
    "f_pressure_n": F_F_PRESSURE, "f_strain_n": F_F_STRAIN, "x_piston_m": F_X,
    "v_piston_m_s": F_V, "omega_m_rad_s": F_OMEGA, "iq_a": F_IQ, "id_a": F_ID, "ia_a": F_IA,
    "ib_a": F_IB, "vd_v": F_VD, "vq_v": F_VQ, "status": F_STATUS, "state": F_STATE,
    **{name: F_STATUS_BITS + i for i, name in enumerate(_STATUS_NAMES)},
    "err_ssi": F_ERR_SSI, "err_biss": F_ERR_BISS, "err_strain": F_ERR_STRAIN,
    "err_link_down": F_ERR_LINK_DOWN, "err_link_up": F_ERR_LINK_UP,
    "oc_trips": F_OC_TRIPS, "wd_trips": F_WD_TRIPS, "x_piston_valid": F_X_VALID,
    "v_piston_valid": F_V_VALID, "upstream_valid": F_UP_VALID}
if _NAMED != _I:  # a field added to ACTUATOR needs its line here and in the kernel
    raise ImportError("hil.replay.signal_kernel: ACTUATOR's fields changed: "
                      f"{sorted(set(_I) ^ set(_NAMED)) or 'order'}")
#: What the kernel stores in each field (``_u4``, ``_b1``, else ``_fx``): a message type's
#: field of another kind is refused (:class:`ActuatorEncoder`).
_COUNTS = {F_PC_MODE, F_BOARD_MODE, F_BOARD_CONTROL, F_STATUS, F_STATE, F_ERR_SSI,
           F_ERR_BISS, F_ERR_STRAIN, F_ERR_LINK_DOWN, F_ERR_LINK_UP, F_OC_TRIPS, F_WD_TRIPS}
_FLAGS = {F_PC_ENABLE, *range(F_STATUS_BITS, F_STATUS_BITS + len(_STATUS_NAMES)), F_X_VALID,
          F_V_VALID, F_UP_VALID}
_STORES = tuple(("fixed32",) if i in _COUNTS else ("bool",) if i in _FLAGS
                else ("double", "float") for i in range(len(FIELDS)))
#: The fields that are NaN while no upstream sweep has reached the MCU.
_UPSTREAM = np.array(sorted(_I[name] for name in SG.UPSTREAM_VALUES), np.int64)
_TEAR = SG.TEAR_COUNTS
_N_STATUS = len(B.STATUS_BITS)
if [bit for bit, _, _ in B.STATUS_BITS] != list(range(_N_STATUS)):
    raise ImportError("hil.replay.signal_kernel: the status bits are not 0..n-1 in order")
_OUT = pdo.ACTUATOR_OUT_DTYPE
if (_OUT.fields["mode"][1], _OUT.fields["flags"][1], _OUT.fields["command"][1],
        _OUT.fields["command"][0].str) != (0, 1, 2, "<i4"):
    raise ImportError("hil.replay.signal_kernel: the actuator output record changed")


@njit(cache=True, inline="always")
def _fx(out, row, off, single, x):
    """``x`` (a float64) as the field's ``float`` (``single``: rounded to nearest, as
    numpy's cast in ``MessageType.encode_into``) or ``double``."""
    if off >= 0:
        if single:
            _store(out, row, off, np.float32(x))
        else:
            _store(out, row, off, np.float64(x))


@njit(cache=True, inline="always")
def _u4(out, row, off, v):
    if off >= 0:
        _store(out, row, off, np.uint32(v & 0xFFFFFFFF))


@njit(cache=True, inline="always")
def _b1(out, row, off, v):
    if off >= 0:
        out[row, off] = 1 if v else 0


@njit(cache=True, inline="always")
def _s16(w):
    w = w & 0xFFFF
    return w - ((w & 0x8000) << 1)


@njit(cache=True, inline="always")
def _count(up, j, i):
    return ((np.int64(up[j, i, B.U_PISTON_HI]) & 0xFFFF) << 16) | (
        np.int64(up[j, i, B.U_PISTON_LO]) & 0xFFFF)


@njit(cache=True, nogil=True)
def _encode(up, down, every, out, off, single, upstream, areg, av0, amul, adiv,
            fk, ik, carry_x, carry_count, carry_off, carry_valid, carry_started, step_valid,
            tick_keep, out_t, out_rows, out_got, box_of, slot_off, last_have, last_t,
            last_img, box_lo, box_hi):
    """See :meth:`ActuatorEncoder.encode`. ``fk``: lsb_v, kc, n per strain code, m per
    piston count, rad/s per speed count, period_s, force and position command lsb; ``ik``:
    strain midscale, BiSS zero count, the enable flag, the force and position mode codes,
    the analog indices of p_cyl_a and p_cyl_b."""
    a, n = up.shape[0], up.shape[1]
    k = n // every
    pc = (off[F_PC_MODE] >= 0 or off[F_PC_ENABLE] >= 0 or off[F_FORCE] >= 0
          or off[F_POSITION] >= 0)
    na = areg.shape[0]
    si = np.empty(na, np.float64)
    x_all = np.empty(n, np.float64)
    for j in range(a):
        # the piston reads of every step: tear offsets (signals.tear_offsets, run
        # sequentially), whether the board's sweeps have started, the position
        before = carry_count[j]
        total = carry_off[j]
        base_t = 0
        started = carry_started[j]
        for i in range(n):
            c = _count(up, j, i)
            d = c - before
            jump = (d + _TEAR // 2) // _TEAR
            if abs(jump) >= 2:
                base_t = total
            else:
                total += jump
            before = c
            if up[j, i, B.U_TICK] != 0:
                started = True
            step_valid[j, i] = (total - base_t == 0) and started
            x_all[i] = (np.float64(c - ik[1]) * fk[3]) if started else math.nan
            if i == n - 1:
                carry_count[j] = c
                carry_off[j] = total - base_t
                carry_started[j] = started
        # the PC's command (older layouts only): this block's output records of the box
        # if it has any, else the last one before (signals.pc_command_block)
        e = box_of[j]
        o = slot_off[j]
        own = False
        for p in range(out_t.shape[0] if pc else 0):
            if out_got[p, e]:
                own = True
                break
        p = 0
        have = False
        src = -1  # row of out_rows, -1: the carried record
        have_t = last_t[e]
        for s in range(k):
            i = s * every + every - 1
            row = j * k + s
            t = tick_keep[s]
            if not pc:
                pass
            elif own:
                while p < out_t.shape[0] and out_t[p] <= t:
                    if out_got[p, e]:
                        src = p
                        have = True
                    p += 1
            else:
                have = last_have[e] and have_t <= t
            if pc:
                rec = out_rows[src] if src >= 0 else last_img
                mode = np.int64(rec[o]) if have else 0
                flags = np.int64(rec[o + 1])
                command = np.int64(np.int32(
                    np.uint32(rec[o + 2]) | (np.uint32(rec[o + 3]) << 8)
                    | (np.uint32(rec[o + 4]) << 16) | (np.uint32(rec[o + 5]) << 24)))
                _u4(out, row, off[F_PC_MODE], mode)
                _b1(out, row, off[F_PC_ENABLE], have and (flags & ik[2]) != 0)
                _fx(out, row, off[F_FORCE], single[F_FORCE],
                    np.float64(command) * fk[6] if mode == ik[3] else math.nan)
                _fx(out, row, off[F_POSITION], single[F_POSITION],
                    np.float64(command) * fk[7] if mode == ik[4] else math.nan)
            # what the MCU wrote
            _fx(out, row, off[F_IQ_REF], single[F_IQ_REF],
                _s16(np.int64(down[j, i, B.D_IQ_REF])) * 1e-3)
            _fx(out, row, off[F_ID_REF], single[F_ID_REF],
                _s16(np.int64(down[j, i, B.D_ID_REF])) * 1e-3)
            _fx(out, row, off[F_VQ_FF], single[F_VQ_FF],
                _s16(np.int64(down[j, i, B.D_VQ_FF])) * 1e-3)
            _u4(out, row, off[F_BOARD_MODE], np.int64(down[j, i, B.D_MODE]) & 0xFFFF)
            _u4(out, row, off[F_BOARD_CONTROL],
                np.int64(down[j, i, B.D_CONTROL]) & 0xFFFF)
            # what it read (measure.upstream_si, signals.actuator_columns)
            for q in range(na):
                w = np.int64(up[j, i, areg[q]]) & 0xFFFF
                si[q] = (w * fk[0] - av0[q]) * amul[q] / adiv[q]
                _fx(out, row, off[F_ANALOG + q], single[F_ANALOG + q], si[q])
            _fx(out, row, off[F_F_PRESSURE], single[F_F_PRESSURE], fk[1] * (si[ik[5]] - si[ik[6]]))
            code = ((np.int64(up[j, i, B.U_STRAIN_HI]) & 0xFF) << 16) | (
                np.int64(up[j, i, B.U_STRAIN_LO]) & 0xFFFF)
            _fx(out, row, off[F_F_STRAIN], single[F_F_STRAIN], (code - ik[0]) * fk[2])
            x = x_all[i]
            if i == 0:
                xb = carry_x[j]
                vb = carry_valid[j]
            else:
                xb = x_all[i - 1]
                vb = step_valid[j, i - 1]
            _fx(out, row, off[F_X], single[F_X], x)
            _fx(out, row, off[F_V], single[F_V], (x - xb) / fk[5])
            _fx(out, row, off[F_OMEGA], single[F_OMEGA],
                _s16(np.int64(up[j, i, B.U_SPEED])) * fk[4])
            _fx(out, row, off[F_IQ], single[F_IQ], _s16(np.int64(up[j, i, B.U_IQ])) * 1e-3)
            _fx(out, row, off[F_ID], single[F_ID], _s16(np.int64(up[j, i, B.U_ID])) * 1e-3)
            _fx(out, row, off[F_IA], single[F_IA], _s16(np.int64(up[j, i, B.U_IA])) * 1e-3)
            _fx(out, row, off[F_IB], single[F_IB], _s16(np.int64(up[j, i, B.U_IB])) * 1e-3)
            _fx(out, row, off[F_VD], single[F_VD], _s16(np.int64(up[j, i, B.U_VD_OUT])) * 1e-3)
            _fx(out, row, off[F_VQ], single[F_VQ], _s16(np.int64(up[j, i, B.U_VQ_OUT])) * 1e-3)
            status = np.int64(up[j, i, B.U_STATUS]) & 0xFFFF
            _u4(out, row, off[F_STATUS], status)
            _u4(out, row, off[F_STATE], np.int64(up[j, i, B.U_STATE]) & 0xFFFF)
            for q in range(_N_STATUS):
                _b1(out, row, off[F_STATUS_BITS + q], (status >> q) & 1)
            _u4(out, row, off[F_ERR_SSI], np.int64(up[j, i, B.U_ERR_SSI]) & 0xFFFF)
            _u4(out, row, off[F_ERR_BISS], np.int64(up[j, i, B.U_ERR_BISS]) & 0xFFFF)
            _u4(out, row, off[F_ERR_STRAIN],
                np.int64(up[j, i, B.U_ERR_STRAIN]) & 0xFFFF)
            _u4(out, row, off[F_ERR_LINK_DOWN],
                np.int64(up[j, i, B.U_ERR_LINK_CRC]) & 0xFFFF)
            _u4(out, row, off[F_ERR_LINK_UP],
                (np.int64(up[j, i, B.UP_WORDS]) & 0xFFFF)
                | ((np.int64(up[j, i, B.UP_WORDS + 1]) & 0xFFFF) << 16))
            _u4(out, row, off[F_OC_TRIPS], np.int64(up[j, i, B.U_OC_TRIPS]) & 0xFFFF)
            _u4(out, row, off[F_WD_TRIPS], np.int64(up[j, i, B.U_WD_TRIPS]) & 0xFFFF)
            xv = step_valid[j, i]
            _b1(out, row, off[F_X_VALID], xv)
            _b1(out, row, off[F_V_VALID], xv and vb and np.isfinite(xb))
            up_ok = x == x  # the sweeps had started at this step: x is a number then
            _b1(out, row, off[F_UP_VALID], up_ok)
            if not up_ok:
                for q in range(upstream.shape[0]):
                    _fx(out, row, off[upstream[q]], single[upstream[q]], math.nan)
        carry_x[j] = x_all[n - 1]
        carry_valid[j] = step_valid[j, n - 1]
    # the boxes' last output records, for the next block
    for e in range(box_lo.shape[0]):
        for p in range(out_t.shape[0] - 1, -1, -1):
            if out_got[p, e]:
                last_have[e] = True
                last_t[e] = out_t[p]
                for b in range(box_lo[e], box_hi[e]):
                    last_img[b] = out_rows[p, b]
                break


class ActuatorEncoder:
    """Decodes the MCU steps of a chain's actuators into :data:`~hil.replay.signals.ACTUATOR`
    messages (``message``: the message type, ACTUATOR or a variant without the unfitted
    inputs) and encodes them, a block at a time: the compiled equivalent of
    :func:`~hil.replay.signals.actuator_block` +
    :func:`~hil.replay.signals.pc_command_block` + ``message.encode_array``.

    ``box_of``/``slot_off``: per actuator, its box (index into the output image's box
    spans ``box_spans``) and the byte offset of its slot's output record in the output
    image of ``image_bytes`` bytes."""

    def __init__(self, cal: FirmwareCalibration, message: MessageType, period_s: float,
                 every: int, box_of: list[int], slot_off: list[int],
                 box_spans: list[tuple[int, int]], image_bytes: int) -> None:
        names = {f.name for f in message.fields}
        unknown = names - set(FIELDS)
        if unknown:
            raise ValueError(f"{message.full_name}: fields {sorted(unknown)} are not "
                             "ActuatorSignals'")
        kinds = {f.name: f.kind for f in message.fields}
        for name, stores in zip(FIELDS, _STORES, strict=True):
            if name in kinds and kinds[name] not in stores:
                raise ValueError(f"{message.full_name}: field {name} is {kinds[name]}, "
                                 f"the kernel writes it as {' or '.join(stores)}")
        self.message = message
        self.every = every
        fields = message.record.fields
        self.off = np.array([fields[n][1] if n in names else -1 for n in FIELDS], np.int64)
        self.single = np.array([kinds.get(n) == "float" for n in FIELDS], np.bool_)
        self.blank = np.ascontiguousarray(message._blank.reshape(-1))  # noqa: SLF001
        dec = [(a.register, *measure.analog_decoder(a, cal)) for a, _ in SG._ANALOG]  # noqa: SLF001
        self.areg = np.array([d[0] for d in dec], np.int64)
        self.av0, self.amul, self.adiv = (np.array([d[q] for d in dec], np.float64)
                                          for q in (1, 2, 3))
        rad_per_count = 2.0 * math.pi / (cal.abi_counts_per_rev
                                         * cal.fpga["speed_window_ticks"] * cal.tick_s)
        self.fk = np.array([padc.DEFAULT.lsb_v, cal.kc_m2, measure.strain_decoder(cal)[1],
                            LINEAR_COUNT_M, rad_per_count, period_s, pdo.FORCE_CMD_LSB,
                            pdo.POSITION_CMD_LSB], np.float64)
        si = [a.si_name for a, _ in SG._ANALOG]  # noqa: SLF001
        self.ik = np.array([measure.strain_decoder(cal)[0], cal.biss_zero_count, pdo.FLAG_ENABLE,
                            pdo.MODE_CODES["force"], pdo.MODE_CODES["position"],
                            si.index("p_cyl_a"), si.index("p_cyl_b")], np.int64)
        self.box_of = np.array(box_of, np.int64)
        self.slot_off = np.array(slot_off, np.int64)
        self.box_lo = np.array([lo for lo, _ in box_spans], np.int64)
        self.box_hi = np.array([hi for _, hi in box_spans], np.int64)
        nb = len(box_spans)
        self.last_have = np.zeros(nb, bool)
        self.last_t = np.zeros(nb, np.int64)
        self.last_img = np.zeros(max(image_bytes, 6), np.uint8)

    def kept(self, n: int) -> np.ndarray:
        """Which of ``n`` steps :meth:`encode` keeps (the last of every ``every``)."""
        return np.arange(self.every - 1, n, self.every)

    def encode(self, up: np.ndarray, down: np.ndarray, carry: SG.PistonCarry,
               step_ticks: np.ndarray, out_t: np.ndarray, out_rows: np.ndarray,
               out_got: np.ndarray, out: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """The messages of ``n`` consecutive MCU steps (ticks ``step_ticks``) of every
        actuator: ``up`` (a, n, 34) uint16, ``down`` (a, n, >= 13) uint16; the cycles'
        output images ``out_rows`` (c, image bytes) taken at ticks ``out_t`` (c,), which
        boxes received theirs ``out_got`` (c, boxes). Returns (the kept steps' indices (k,),
        the messages (a * k, size) uint8, actuator-major) and updates ``carry``. ``out``
        (a * k, size) uint8, rows of any stride (e.g. the messages' places in their MCAP
        records, :meth:`~hil.framelog.writer.FrameLogWriter.write_messages_filled`): the
        messages are written there, every byte, and it is returned."""
        a, n = up.shape[:2]
        every = self.every
        keep = self.kept(n)
        k = len(keep)
        size = len(self.blank)
        if out is None:
            out = np.empty((a * k, size), np.uint8)
        if out.shape != (a * k, size) or out.dtype != np.uint8 or out.strides[1] != 1:
            raise ValueError(f"need out ({a * k}, {size}) uint8, got {out.shape} {out.dtype}")
        if not n:
            carry.valid_in, carry.step_valid = carry.valid, np.zeros((a, 0), bool)
            return keep, out
        if carry.count is None:
            carry.count = measure.piston_count(up[:, 0])
        carry.valid_in = carry.valid.copy()
        step_valid = np.empty((a, n), bool)
        out[:] = self.blank  # every key; the kernel writes every value
        _encode(up, down, every, out, self.off, self.single,
                _UPSTREAM, self.areg, self.av0, self.amul, self.adiv, self.fk, self.ik,
                carry.x, carry.count, carry.offset, carry.valid, carry.started, step_valid,
                np.ascontiguousarray(step_ticks[keep], np.int64),
                np.ascontiguousarray(out_t, np.int64), np.ascontiguousarray(out_rows),
                np.ascontiguousarray(out_got), self.box_of, self.slot_off, self.last_have,
                self.last_t, self.last_img, self.box_lo, self.box_hi)
        carry.step_valid = step_valid
        return keep, out


def warm_up(cal: FirmwareCalibration) -> None:
    """Compile :func:`_encode` for the argument types the recorder passes (the tap's rows
    are a view of a longer array), on one step of one actuator; and the boxes' record
    signals (:func:`hil.replay.signal_records.warm_up`)."""
    from hil.replay import signal_records

    signal_records.warm_up()
    room = np.zeros((1, 2, B.UP_WORDS + 2), np.uint16)
    down = np.zeros((1, 2, B.DOWN_WORDS), np.uint16)
    enc = ActuatorEncoder(cal, SG.ACTUATOR, 200e-6, 1, [0], [0], [(0, _OUT.itemsize)],
                          _OUT.itemsize)
    records = np.zeros((1, SG.ACTUATOR.size + 1), np.uint8)
    for out in (None, records[:, 1:]):  # an array of its own; places in records
        enc.encode(room[:, :1], down[:, :1], SG.PistonCarry.start(1), np.zeros(1, np.int64),
                   np.zeros(1, np.int64), np.zeros((1, _OUT.itemsize), np.uint8),
                   np.ones((1, 1), bool), out)
