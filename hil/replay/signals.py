"""The decoded signals of a fieldbus run, in SI units, as protobuf messages a viewer plots.

Beside the raw frames the replay needs (:mod:`hil.replay.record`), a ``bus run`` log
carries what those frames mean, one message per sample (``docs/framelog.md``):

* ``/signals/actuator/<b>.<k>`` (:data:`ACTUATOR`), each MCU step: the MCU's references
  to the board, what the MCU read from the board (pressures, forces, piston, motor,
  currents, voltages, temperature) and the board's status bits and error counters (the
  PC's command it worked to is the box's outputs channel's, :data:`PC_COMMAND`). Decoded
  from the MCU's side of the LVDS link (the words it read and wrote) with the MCU's
  conversions (:func:`firmware_model.mcu.measure.upstream_si`) and the run's firmware
  calibration; one field per analog input of the board
  (``firmware_model.fpga.layout.ANALOG_INPUTS``: the five pressures, the oil and rod
  temperatures).
* ``/signals/box/<b>/outputs`` and ``.../inputs``, each fieldbus cycle: the box's process
  record (:mod:`hil.fieldbus.pdo`) field by field, in SI units.
* ``/signals/bus``, each fieldbus cycle: the master's counters and the cycle's WKC.

Each function here turns buffered raw data into columns (field -> numpy array); encoding
them is :meth:`hil.framelog.protobuf.MessageType.encode`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga import layout as B
from firmware_model.mcu import measure
from firmware_model.mcu.measure import upstream_si
from hil.fieldbus import pdo
from hil.fieldbus.topology import Box
from hil.framelog.formats import split_mcu_up
from hil.framelog.protobuf import Field, MessageType

PACKAGE = "eha_hil"
#: One field per analog input of the board (pressures, temperatures), from its declaration.
_ANALOG_UNIT_SUFFIX = {"Pa": "pa", "degC": "c"}
_ANALOG = tuple((a, f"{a.name}_{_ANALOG_UNIT_SUFFIX.get(a.unit, a.unit.lower())}")
                for a in B.ANALOG_INPUTS)
#: How a decoded value is stored (docs/framelog.md, "Float or double"): ``float`` when it
#: is one word of at most 24 significant bits times constants (a 16-bit ADC or register
#: word, the 24-bit strain code): every distinct word gives a distinct float32, so the
#: float32 holds all the word says (and the pressure force, whose two words are fields of
#: the same message); ``double`` when it comes from more bits (the two-word piston
#: position and its speed, a 32-bit command).
WORD = "float"
WIDE = "double"
_ANALOG_FIELDS = tuple(Field(field, WORD, a.unit, a.meaning.split(",")[0])
                       for a, field in _ANALOG)
_STATUS_FIELDS = tuple(Field(name.lower(), "bool", "", f"board status bit {bit}: {doc}")
                       for bit, name, doc in B.STATUS_BITS)

#: The PC's command in force at each step, which the actuator messages of older logs
#: carried first: the same values are the latest ``/signals/box/<b>/outputs`` message's
#: (``s<k>_mode``, ``s<k>_flags``, ``s<k>_force_command_n``, ...) at or before the step,
#: so today's actuator messages leave them out (:data:`ACTUATOR_ALL_DOUBLE` has them).
PC_COMMAND = (
    Field("pc_mode", "fixed32", "", "PC command mode: 0 off, 1 force, 2 position"),
    Field("pc_enable", "bool", "", "PC enable flag"),
    Field("force_command_n", WIDE, "N", "PC force command (NaN unless mode 1)"),
    Field("position_command_m", WIDE, "m", "PC position command (NaN unless mode 2)"),
)

#: The actuator message's fields grouped by where they come from (what the MCU wrote,
#: what it read, status and errors, validity), in the order (and so with the field
#: numbers) that logs before :data:`ACTUATOR`'s order had (:data:`ACTUATOR_SOURCE_ORDER`).
_BY_SOURCE = (
    # what the MCU wrote to the board
    Field("iq_ref_a", WORD, "A", "q-axis current reference the MCU wrote"),
    Field("id_ref_a", WORD, "A", "d-axis current reference the MCU wrote"),
    Field("vq_ff_v", WORD, "V", "q-axis voltage feed-forward the MCU wrote"),
    Field("board_mode", "fixed32", "", "board mode register: 0 off, 1 current, 2 voltage"),
    Field("board_control", "fixed32", "", "board control register: bit 0 enable, 1 clear"),
    # what the MCU read
    *_ANALOG_FIELDS,
    # float: its two words are the message's p_cyl_a_pa and p_cyl_b_pa (docs/framelog.md)
    Field("f_pressure_n", WORD, "N", "pressure force k_c (p_cyl_a - p_cyl_b)"),
    Field("f_strain_n", WORD, "N", "strain-gauge force"),
    Field("x_piston_m", WIDE, "m", "piston position about mid-stroke"),
    Field("v_piston_m_s", WIDE, "m/s", "piston speed: position change over the MCU step"),
    Field("omega_m_rad_s", WORD, "rad/s", "motor speed (ABI count over the speed window)"),
    Field("iq_a", WORD, "A", "measured q-axis current"),
    Field("id_a", WORD, "A", "measured d-axis current"),
    Field("ia_a", WORD, "A", "phase a current"),
    Field("ib_a", WORD, "A", "phase b current"),
    Field("vd_v", WORD, "V", "d-axis voltage applied"),
    Field("vq_v", WORD, "V", "q-axis voltage applied"),
    # status and errors
    Field("status", "fixed32", "", "board status word (the bits below)"),
    Field("state", "fixed32", "", "board state: 0 disabled, 1 enabled, 2 fault"),
    *_STATUS_FIELDS,
    Field("err_ssi", "fixed32", "", "SSI frames rejected"),
    Field("err_biss", "fixed32", "", "BiSS frames rejected"),
    Field("err_strain", "fixed32", "", "AD7195 reads rejected"),
    Field("err_link_down", "fixed32", "", "downstream LVDS words the board discarded (CRC)"),
    Field("err_link_up", "fixed32", "", "upstream LVDS words the MCU discarded (CRC)"),
    Field("oc_trips", "fixed32", "", "over-current trips"),
    Field("wd_trips", "fixed32", "", "link watchdog trips"),
    # validity of what the MCU read (appended: the fields above keep their numbers)
    Field("x_piston_valid", "bool", "",
          "false: the MCU read the piston position torn between its two 16-bit words "
          "(docs/framelog.md)"),
    Field("v_piston_valid", "bool", "",
          "false: the speed's difference has a torn position at one end"),
    Field("upstream_valid", "bool", "",
          "false: no upstream sweep of the board has reached the MCU yet (its words all 0): "
          "the values read from the board are NaN"),
)

#: The values of an actuator message that change from one sample to the next on a
#: running actuator (the noisy sensor words, the current loop, the piston): field
#: numbers 1 to 15, whose protobuf keys are one byte (16 and up take two). Then
#: :data:`SLOW_VALUES` (steady for many samples: a word that flips by one, a
#: temperature, a reference that is mostly 0), then the rest (modes, status, counters,
#: flags: constant for long stretches) as in :data:`_BY_SOURCE`. A chunk compressor
#: at zstd's fast levels stores what it finds no match for as it is, so the values
#: that differ from the previous sample are best together and small, and the steady
#: fields one long run that matches the previous message's (docs/framelog.md,
#: "Field order"): on a whole-robot log 7 % fewer bytes and 10 % less zstd time on
#: the signal chunks than :data:`ACTUATOR_SOURCE_ORDER`.
EVERY_SAMPLE = ("iq_ref_a", "p_pump_a_pa", "p_pump_b_pa", "p_cyl_a_pa", "p_cyl_b_pa",
                "f_pressure_n", "f_strain_n", "x_piston_m", "v_piston_m_s", "iq_a", "id_a",
                "ia_a", "ib_a", "vd_v", "vq_v")
SLOW_VALUES = ("p_acc_pa", "temperature_c", "rod_temperature_c", "vq_ff_v", "omega_m_rad_s",
               "id_ref_a")
_FIELD = {f.name: f for f in _BY_SOURCE}
if len(EVERY_SAMPLE) > 15 or not set(EVERY_SAMPLE + SLOW_VALUES) <= set(_FIELD):
    raise ImportError("hil.replay.signals: EVERY_SAMPLE must name at most 15 fields of the "
                      "actuator message, SLOW_VALUES fields of it")
ACTUATOR = MessageType(f"{PACKAGE}.ActuatorSignals", (
    *(_FIELD[name] for name in EVERY_SAMPLE + SLOW_VALUES),
    *(f for f in _BY_SOURCE if f.name not in EVERY_SAMPLE + SLOW_VALUES),
), "one actuator, each MCU step")

#: :data:`ACTUATOR` as logs before its field order wrote it: the same fields numbered
#: in :data:`_BY_SOURCE` order.
ACTUATOR_SOURCE_ORDER = MessageType(ACTUATOR.full_name, _BY_SOURCE, ACTUATOR.doc)

#: :data:`ACTUATOR` as logs before the float fields wrote it: :data:`PC_COMMAND` first,
#: every float a double, in source order (what the readers of old logs and the
#: kernel's tests use).
ACTUATOR_ALL_DOUBLE = MessageType(ACTUATOR.full_name, tuple(
    Field(f.name, WIDE if f.kind == WORD else f.kind, f.unit, f.doc)
    for f in (*PC_COMMAND, *_BY_SOURCE)), ACTUATOR.doc)

#: The fields of :data:`ACTUATOR` read from the board (upstream words) as numbers: NaN
#: while no upstream sweep has reached the MCU (0 V through the MCU's formulas is not a
#: measurement: -3 MPa, -20.5 degC, the piston 42 mm off).
UPSTREAM_VALUES = (*(f for _, f in _ANALOG), "f_pressure_n", "f_strain_n", "x_piston_m",
                   "v_piston_m_s", "omega_m_rad_s", "iq_a", "id_a", "ia_a", "ib_a", "vd_v",
                   "vq_v")

_UNFITTED_SUFFIX = "_no_"


def actuator_message(unfitted: tuple[str, ...] = (), base: MessageType = ACTUATOR
                     ) -> MessageType:
    """:data:`ACTUATOR` (or ``base``, e.g. :data:`ACTUATOR_ALL_DOUBLE`) without the fields
    of the analog inputs ``unfitted`` (names of ``ANALOG_INPUTS`` whose part is not
    mounted: an empty input reads 0 V, which the MCU's formula would turn into a
    confident value; the signal is left out instead)."""
    if not unfitted:
        return base
    drop = {field for a, field in _ANALOG if a.name in unfitted}
    return MessageType(base.full_name + "".join(_UNFITTED_SUFFIX + n for n in unfitted),
                       tuple(f for f in base.fields if f.name not in drop), base.doc)


def unfitted_inputs(sensors: dict) -> tuple[str, ...]:
    """The analog inputs whose part the configuration's ``[sensors]`` table says is not
    fitted (``sensors.<fitted_key>`` false), in declaration order."""
    return tuple(a.name for a, _ in _ANALOG
                 if a.fitted_key is not None and not sensors.get(a.fitted_key, False))

BUS = MessageType(f"{PACKAGE}.BusCycle", (
    Field("cycle", "fixed64", "", "fieldbus cycle number"),
    Field("frames", "fixed32", "", "frames sent this cycle"),
    Field("wkc", "fixed32", "", "sum of the working counters of this cycle's replies"),
    Field("wkc_expected", "fixed32", "", "sum of the working counters the plan expects"),
    Field("frames_sent", "fixed64", "", "master counter: frames sent"),
    Field("frames_ok", "fixed64", "", "master counter: replies applied"),
    Field("wkc_errors", "fixed64", "", "master counter: replies with a wrong working counter"),
    Field("bad_frames", "fixed64", "", "master counter: replies that failed FCS/PDU checks"),
    Field("stale_frames", "fixed64", "", "master counter: replies from another cycle"),
    Field("lost_frames", "fixed64", "", "master counter: frames that did not come back"),
), "the fieldbus, each cycle")

#: The master counters in BUS, in MasterStats' names.
MASTER_COUNTERS = ("frames_sent", "frames_ok", "wkc_errors", "bad_frames", "stale_frames",
                   "lost_frames")


#: Slot kinds whose inputs the simulation fills (the others stay 0 on the bus, see
#: :mod:`hil.fieldbus.pdo`): their decoded signals are left out, not shown as a confident 0.
SIMULATED_KINDS = ("actuator",)


def _record_fields(fields: tuple[pdo.Field, ...], prefix: str) -> list[Field]:
    out = []
    for f in fields:
        if f.lsb == 0.0:  # the command: its unit depends on the mode
            out += [Field(f"{prefix}force_command_n", WIDE, "N", "force command (mode 1)"),
                    Field(f"{prefix}position_command_m", WIDE, "m",
                          "position command (mode 2)")]
        elif f.unit:
            kind = WORD if np.dtype(f.dtype).itemsize <= 2 else WIDE  # 32-bit counts: double
            out.append(Field(f"{prefix}{f.name}_{_suffix(f.unit)}", kind, f.unit, f.doc))
        else:
            out.append(Field(f"{prefix}{f.name}", "fixed32", "", f.doc))
    return out


def _suffix(unit: str) -> str:
    return {"m/s^2": "m_s2", "N m": "nm", "N/N": "n_n", "degC": "c"}.get(
        unit, unit.lower().replace("/", "_"))


def record_message(box: Box, direction: str) -> MessageType:
    """The message of box ``box``'s ``outputs`` or ``inputs`` record: per simulated slot
    (:data:`SIMULATED_KINDS`) ``s<k>_`` fields in SI units (one type per slot layout,
    shared by boxes of the same layout). No fields (a box of sensors that are not
    simulated, or the outputs of a box that has none): the box gets no such channel."""
    which = 0 if direction == "outputs" else 1
    fields = []
    for k, s in enumerate(box.slots):
        if s.kind in SIMULATED_KINDS:
            fields += _record_fields(pdo.SLOT_FIELDS[s.kind][which], f"s{k}_")
    if direction == "inputs":  # appended: the fields above keep their numbers
        for k in _actuator_slots(box):
            fields += [Field(f"s{k}_x_piston_valid", "bool", "",
                             "false: the MCU read this piston position torn between its two "
                             "16-bit words (docs/framelog.md)"),
                       Field(f"s{k}_v_piston_valid", "bool", "",
                             "false: this speed's difference has a torn position at one end, "
                             "or no record before it")]
    kinds = "_".join(s.kind for s in box.slots if s.kind in SIMULATED_KINDS) or "empty"
    return MessageType(f"{PACKAGE}.Box{direction.capitalize()}_{kinds}", fields,
                       f"the {direction} record of a box, each cycle")


def _actuator_slots(box: Box) -> list[int]:
    return [k for k, s in enumerate(box.slots) if s.kind == "actuator"]


def record_columns(box: Box, direction: str, records: np.ndarray,
                   piston: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> dict[str, np.ndarray]:
    """SI columns of ``records`` ((n, bytes) uint8 rows of the box's record); for the
    inputs, ``piston`` = (x valid, v valid), each (actuator slots, n) bool
    (:func:`report_flags`), gives the validity flags of each actuator slot's piston.
    Adjacent slots of one kind are decoded together (one numpy operation per field for
    all of them, a column per slot a view of it)."""
    cols: dict[str, np.ndarray] = {}
    n = len(records)
    for off, dt, m, fields in _record_plan(tuple(s.kind for s in box.slots), direction):
        rec = np.ascontiguousarray(records[:, off:off + m * dt.itemsize]).view(dt)
        for name, lsb, columns in fields:
            if lsb == 0.0:  # the command: its unit depends on the mode
                both = _commands(rec["mode"], rec[name].astype(np.int64))
                for j, prefix in enumerate(columns):
                    for what, v in both.items():
                        cols[prefix + what] = v[:, j]
                continue
            v = rec[name] * lsb if lsb is not None else rec[name]
            for j, column in enumerate(columns):
                cols[column] = v[:, j] if m > 1 else v.reshape(n)
    if direction == "inputs" and _actuator_slots(box):
        if piston is None:
            raise ValueError("the inputs of a box with actuators need their piston flags")
        for i, k in enumerate(_actuator_slots(box)):
            cols[f"s{k}_x_piston_valid"] = piston[0][i]
            cols[f"s{k}_v_piston_valid"] = piston[1][i]
    return cols


@functools.cache
def _record_plan(kinds: tuple[str, ...], direction: str
                 ) -> tuple[tuple[int, np.dtype, int,
                                  tuple[tuple[str, float | None, tuple[str, ...]], ...]], ...]:
    """How :func:`record_columns` reads a record of slots ``kinds``, worked out once per
    slot layout (a block of records is decoded 20 times per simulated second per box):
    per run of ``m`` adjacent slots of one kind with a record, (byte offset, the slot's
    dtype, m, per field (name, lsb: 0.0 the command, None a count, per slot its column
    or, for the command, its columns' prefix))."""
    which = 0 if direction == "outputs" else 1
    plan: list[tuple[int, np.dtype, str, list[int]]] = []  # off, dt, kind, slots
    off = 0
    for k, kind in enumerate(kinds):
        dt = pdo.record_dtype(pdo.SLOT_FIELDS[kind][which])
        if not dt.itemsize:
            continue
        if plan and plan[-1][2] == kind and plan[-1][0] + len(plan[-1][3]) * dt.itemsize == off:
            plan[-1][3].append(k)
        else:
            plan.append((off, dt, kind, [k]))
        off += dt.itemsize
    out = []
    for start, dt, kind, slots in plan:
        fields = []
        for f in pdo.SLOT_FIELDS[kind][which]:
            if f.lsb == 0.0:
                fields.append((f.name, 0.0, tuple(f"s{k}_" for k in slots)))
            elif f.unit:
                fields.append((f.name, f.lsb, tuple(f"s{k}_{f.name}_{_suffix(f.unit)}"
                                                    for k in slots)))
            else:
                fields.append((f.name, None, tuple(f"s{k}_{f.name}" for k in slots)))
        out.append((start, dt, len(slots), tuple(fields)))
    return tuple(out)


def pc_command_block(parts: list[tuple[np.ndarray, np.ndarray, Box, int]],
                     step_ticks: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`pc_command_columns` of each ``(out_ticks, out_records, box, slot)`` of
    ``parts`` at the same ``step_ticks``, concatenated part-major: the parts whose output
    records have the same times (every box of a chain, mostly) looked up together."""
    n = len(step_ticks)
    dt = pdo.ACTUATOR_OUT_DTYPE
    mode = np.zeros((len(parts), n), np.int64)
    flags = np.zeros((len(parts), n), np.int64)
    command = np.zeros((len(parts), n), np.int64)
    have = np.zeros((len(parts), n), bool)
    groups: dict[bytes, tuple[np.ndarray, list[tuple[int, np.ndarray]]]] = {}
    for a, (out_t, out_f, box, slot) in enumerate(parts):
        if len(out_t):
            off = sum(s.sizes[0] for s in box.slots[:slot])
            groups.setdefault(np.asarray(out_t).tobytes(), (out_t, []))[1].append(
                (a, out_f[:, off:off + dt.itemsize]))
    for out_t, members in groups.values():
        i = np.searchsorted(out_t, step_ticks, side="right") - 1
        h = i >= 0
        rows = [a for a, _ in members]
        rec = np.ascontiguousarray(np.stack([f for _, f in members])).view(dt)[..., 0]
        r = rec[:, np.maximum(i, 0)]
        have[rows] = h
        mode[rows] = np.where(h, r["mode"], 0)
        flags[rows] = r["flags"]
        command[rows] = r["command"]
    mode, command = mode.reshape(-1), command.reshape(-1)
    return {"pc_mode": mode,
            "pc_enable": (have & ((flags & pdo.FLAG_ENABLE) != 0)).reshape(-1),
            **_commands(mode, command)}


def report_flags(carry: PistonCarry, t_steps: np.ndarray, in_t: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per actuator and cycle ((a, c) each): whether the piston position a box reports at
    the end of each cycle (ticks ``in_t``) is whole -- it is the MCU's read at the last MCU
    step before the end, whose validity the last :func:`actuator_block` of the steps
    ``t_steps`` (ticks) left in ``carry`` -- and whether the speed it reports, the
    difference to the previous report's position, has whole reads at both ends."""
    sv = carry.step_valid if carry.step_valid is not None else \
        np.zeros((len(carry.report_valid), 0), bool)
    both = np.concatenate([carry.valid_in[:, None], sv], axis=1)
    idx = np.searchsorted(np.asarray(t_steps), np.asarray(in_t), side="left")
    x_ok = both[:, np.minimum(idx, both.shape[1] - 1)]
    v_ok = x_ok & np.concatenate([carry.report_valid[:, None], x_ok[:, :-1]], axis=1)
    if x_ok.shape[1]:
        carry.report_valid = x_ok[:, -1].copy()
    return x_ok, v_ok


def _commands(mode: np.ndarray, command: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    force = mode == pdo.MODE_CODES["force"]
    pos = mode == pdo.MODE_CODES["position"]
    return {f"{prefix}force_command_n": np.where(force, command * pdo.FORCE_CMD_LSB, math.nan),
            f"{prefix}position_command_m": np.where(pos, command * pdo.POSITION_CMD_LSB,
                                                    math.nan)}


#: A read of the piston position whose 16-bit words come from either side of a carry
#: is off by a multiple of this many counts (docs/fpga.md, "Multi-word values").
TEAR_COUNTS = 1 << 16


def piston_counts(up: np.ndarray) -> np.ndarray:
    """The BiSS piston count (int64) the MCU assembles from its two upstream words."""
    return measure.piston_count(up)


def tear_offsets(counts: np.ndarray, count_before: np.ndarray,
                 offset_before: np.ndarray) -> np.ndarray:
    """Per read of the piston position (``counts``, (actuators, n) consecutive MCU steps),
    how many :data:`TEAR_COUNTS` it is off by (0: a whole read). The two words are read
    at most one board tick apart, in which the piston moves far less than TEAR_COUNTS, so
    a torn read is off by exactly one TEAR_COUNTS (plus that motion): a step between two
    reads that rounds to +-1 TEAR_COUNTS (more than half of it, 0.17 mm in one MCU step,
    0.87 m/s: beyond any piston speed) is a torn read starting or ending, and these add
    up. A step of two or more (the link's first words after start, a sensor fault) is a
    real jump: the count after it is taken as whole. ``count_before``/``offset_before``
    (actuators,): the read before the first and its offset (from the previous block)."""
    c = np.asarray(counts, dtype=np.int64)
    n = c.shape[-1]
    d = np.diff(c, axis=-1, prepend=np.asarray(count_before, np.int64)[..., None])
    jumps = np.floor_divide(d + TEAR_COUNTS // 2, TEAR_COUNTS)
    reset = np.abs(jumps) >= 2
    total = np.cumsum(np.where(reset, 0, jumps), axis=-1) + np.asarray(
        offset_before, np.int64)[..., None]
    # from a real jump on, count from 0 again: less the total at the last one
    last = np.maximum.accumulate(np.where(reset, np.arange(n), -1), axis=-1)
    base = np.where(last >= 0, np.take_along_axis(total, np.maximum(last, 0), axis=-1), 0)
    return total - base


def piston_x(cal: FirmwareCalibration, up: np.ndarray) -> np.ndarray:
    """Piston position, m, of upstream frames ``up`` (n, >= 31 words), as the MCU reads it."""
    return upstream_si(np.asarray(up)[:, :len(B.UP_REGISTERS)], cal)["x_piston"]


def actuator_columns(cal: FirmwareCalibration, up: np.ndarray, down: np.ndarray,
                     x_before: float | np.ndarray, period_s: float) -> dict[str, np.ndarray]:
    """SI columns of ``n`` MCU steps of one board: ``up`` the words the MCU read (32 words +
    its upstream CRC-error count: (n, 34) uint16 or, from older logs, (n, 33) uint32;
    :func:`~hil.framelog.formats.split_mcu_up`), ``down`` (n, 16) the registers it wrote.
    ``x_before``: the piston position one MCU step (``period_s``) before each sample, (n,);
    or, for consecutive steps, a float: the position before the first (NaN: unknown)."""
    u, crc_up = split_mcu_up(up)
    d = np.asarray(down).astype(np.int64) & 0xFFFF

    def s16(a: np.ndarray) -> np.ndarray:
        a = a & 0xFFFF
        return a - ((a & 0x8000) << 1)

    si = upstream_si(u[:, :len(B.UP_REGISTERS)], cal)
    rad_per_count = 2.0 * math.pi / (cal.abi_counts_per_rev * cal.fpga["speed_window_ticks"]
                                     * cal.tick_s)
    x = si["x_piston"]
    status = u[:, B.U_STATUS] & 0xFFFF
    cols = {
        "iq_ref_a": s16(d[:, B.D_IQ_REF]) * 1e-3, "id_ref_a": s16(d[:, B.D_ID_REF]) * 1e-3,
        "vq_ff_v": s16(d[:, B.D_VQ_FF]) * 1e-3, "board_mode": d[:, B.D_MODE],
        "board_control": d[:, B.D_CONTROL],
        "f_pressure_n": cal.kc_m2 * (si["p_cyl_a"] - si["p_cyl_b"]),
        "f_strain_n": si["f_strain_raw"], "x_piston_m": x,
        "v_piston_m_s": (x - x_before if isinstance(x_before, np.ndarray) else
                         np.diff(x, prepend=x_before)) / period_s,
        "omega_m_rad_s": s16(u[:, B.U_SPEED]) * rad_per_count,
        "iq_a": si["iq"], "id_a": s16(u[:, B.U_ID]) * 1e-3, "ia_a": s16(u[:, B.U_IA]) * 1e-3,
        "ib_a": s16(u[:, B.U_IB]) * 1e-3, "vd_v": s16(u[:, B.U_VD_OUT]) * 1e-3,
        "vq_v": s16(u[:, B.U_VQ_OUT]) * 1e-3,
        "status": status, "state": u[:, B.U_STATE] & 0xFFFF,
        "err_ssi": u[:, B.U_ERR_SSI], "err_biss": u[:, B.U_ERR_BISS],
        "err_strain": u[:, B.U_ERR_STRAIN], "err_link_down": u[:, B.U_ERR_LINK_CRC],
        "err_link_up": crc_up, "oc_trips": u[:, B.U_OC_TRIPS],
        "wd_trips": u[:, B.U_WD_TRIPS],
    }
    for a, field in _ANALOG:
        cols[field] = si[a.si_name]
    for (bit, _, _), f in zip(B.STATUS_BITS, _STATUS_FIELDS, strict=True):
        cols[f.name] = (status >> bit) & 1
    return cols


@dataclass
class PistonCarry:
    """What the decoding of one block of MCU steps leaves for the next, per actuator: the
    last piston position (m, NaN: none yet), its count, its tear offset and validity, and
    whether an upstream sweep of the board has reached the MCU."""

    x: np.ndarray
    count: np.ndarray | None
    offset: np.ndarray
    valid: np.ndarray
    started: np.ndarray
    #: of the last block: the validity of the read before it and of each of its reads
    #: ((a, n)); whether the last box report's position was whole (False: none yet)
    valid_in: np.ndarray
    step_valid: np.ndarray | None
    report_valid: np.ndarray

    @classmethod
    def start(cls, actuators: int) -> PistonCarry:
        return cls(np.full(actuators, math.nan), None, np.zeros(actuators, np.int64),
                   np.ones(actuators, bool), np.zeros(actuators, bool),
                   np.ones(actuators, bool), None, np.zeros(actuators, bool))


def actuator_block(cal: FirmwareCalibration, up: np.ndarray, down: np.ndarray, every: int,
                   period_s: float, carry: PistonCarry) -> tuple[np.ndarray,
                                                                 dict[str, np.ndarray]]:
    """The decoded signals of ``n`` consecutive MCU steps of ``a`` actuators: ``up``
    (a, n, 34) uint16 the words each MCU read (or (a, n, 33) uint32), ``down`` (a, n,
    >= 13) those it wrote. Every ``every``-th step is kept (the last of each group):
    returns (the kept steps' indices (k,), columns of a * k samples, actuator-major) and
    updates ``carry``. The piston
    speed is the position's change over the step before each kept one; ``x_piston_valid``
    and ``v_piston_valid`` flag torn reads (:func:`tear_offsets`)."""
    a, n = up.shape[:2]
    keep = np.arange(every - 1, n, every)
    if not n:
        carry.valid_in, carry.step_valid = carry.valid, np.zeros((a, 0), bool)
        return keep, {}
    counts = piston_counts(up)
    before = counts[:, 0] if carry.count is None else carry.count
    off = tear_offsets(counts, before, carry.offset)
    # the MCU's memory is 0 until the board's first upstream sweep reaches it; the sweep
    # ends with the board's tick counter, then non-zero (and the piston read after it is
    # a real jump from 0, not a tear)
    started = carry.started[:, None] | (np.cumsum(up[:, :, B.U_TICK] != 0, axis=1) > 0)
    valid = (off == 0) & started
    x = np.where(started, measure.piston_x(counts, cal), math.nan)
    x_before = np.concatenate([carry.x[:, None], x], axis=1)[:, keep]
    valid_before = np.concatenate([carry.valid[:, None], valid], axis=1)[:, keep]
    k = len(keep)
    cols = actuator_columns(cal, up[:, keep].reshape(a * k, -1),
                            down[:, keep].reshape(a * k, -1), x_before.reshape(a * k),
                            period_s)
    cols["x_piston_valid"] = valid[:, keep].reshape(a * k)
    cols["v_piston_valid"] = (cols["x_piston_valid"] & valid_before.reshape(a * k)
                              & np.isfinite(x_before.reshape(a * k)))
    up_ok = started[:, keep].reshape(a * k)
    cols["upstream_valid"] = up_ok
    if not up_ok.all():
        for name in UPSTREAM_VALUES:
            if name in cols:
                cols[name] = np.where(up_ok, cols[name], math.nan)
    carry.valid_in, carry.step_valid = carry.valid, valid
    carry.x, carry.count = x[:, -1].copy(), counts[:, -1].copy()
    carry.offset, carry.valid = off[:, -1].copy(), valid[:, -1].copy()
    carry.started = started[:, -1].copy()
    return keep, cols


def pc_command_columns(out_ticks: np.ndarray, out_records: np.ndarray, box: Box, slot: int,
                       step_ticks: np.ndarray) -> dict[str, np.ndarray]:
    """The PC's command to actuator slot ``slot`` as it stood at each MCU step: the output
    record of the latest cycle applied at or before the step (none yet: mode 0, NaN)."""
    off = sum(s.sizes[0] for s in box.slots[:slot])
    dt = pdo.ACTUATOR_OUT_DTYPE
    n = len(step_ticks)
    if len(out_ticks) == 0:
        return {"pc_mode": np.zeros(n, np.int64), "pc_enable": np.zeros(n, bool),
                **_commands(np.zeros(n, np.int64), np.zeros(n, np.int64))}
    rec = np.ascontiguousarray(out_records[:, off:off + dt.itemsize]).view(dt)[:, 0]
    i = np.searchsorted(out_ticks, step_ticks, side="right") - 1
    have = i >= 0
    j = np.maximum(i, 0)
    mode = np.where(have, rec["mode"][j], 0)
    return {"pc_mode": mode,
            "pc_enable": have & ((rec["flags"][j] & pdo.FLAG_ENABLE) != 0),
            **_commands(mode, rec["command"][j].astype(np.int64))}
