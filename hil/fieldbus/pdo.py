"""Process data of one joint driver box: what the master writes (outputs) and reads (inputs).

Each slot of a box (one driver board, thesis Table 6.4) has a fixed little-endian record,
declared once here as fields; numpy structured dtypes, the SI conversions and the docs
table (docs/fieldbus.md) all come from the declaration. Integers with a stated LSB keep the
image compact (the full robot's 47 actuators fit two standard Ethernet frames per cycle)
and make it bit-exact across transports; values beyond a field's range saturate.

Slot kinds:
* ``actuator``: an EHA (or the neck's electric motor) behind a driver board;
* ``foot_sensor``: a 6-axis foot force sensor board (inputs only);
* ``imu``: the IMU box (inputs only).
The foot sensors and the IMU are not simulated: their inputs stay zero. They are in the map
so that the image, the frame split and the working counters are the robot's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_model.mcu.mcu import CommandMode


@dataclass(frozen=True)
class Field:
    """One process-data field: ``lsb`` SI units per count (1 for codes and flags)."""

    name: str
    dtype: str
    lsb: float
    unit: str
    doc: str


#: Command modes in the ``mode`` output byte.
MODE_CODES = {CommandMode.OFF: 0, CommandMode.FORCE: 1, CommandMode.POSITION: 2}
MODE_NAMES = {v: k for k, v in MODE_CODES.items()}
#: ``flags`` output bits.
FLAG_ENABLE = 0x01
FLAG_CLEAR_FAULT = 0x02

ACTUATOR_OUT = (
    Field("mode", "u1", 1, "", "0 off, 1 force, 2 position"),
    Field("flags", "u1", 1, "", "bit 0 enable (rising edge boots the board), bit 1 clear fault"),
    Field("command", "i4", 0.0, "N or m",
          "force command, 0.01 N per count (mode 1); piston position, 1 nm per count (mode 2)"),
    Field("kp_position", "u2", 10.0, "N/m",
          "local position-loop gain K_pos, 10 N/m per count; 0 keeps the MCU's own"),
    Field("kp_force", "u2", 1e-3, "N/N", "force PD gain K_p, 0.001 per count; 0 keeps the MCU's"),
)
FORCE_CMD_LSB = 0.01
POSITION_CMD_LSB = 1e-9

ACTUATOR_IN = (
    Field("x_piston", "i4", 1e-9, "m", "piston position about mid-stroke"),
    Field("v_piston", "i2", 1e-5, "m/s", "piston speed (position difference over the cycle)"),
    Field("f_pressure", "i2", 0.1, "N", "pressure force k_c (p_cyl_a - p_cyl_b)"),
    Field("f_strain", "i2", 0.1, "N", "strain-gauge force (cos alpha corrected)"),
    Field("f_filtered", "i2", 0.1, "N", "complementary-filtered force (Eq. 4.4)"),
    Field("iq", "i2", 1e-3, "A", "measured q-axis current"),
    Field("temperature", "i2", 0.01, "degC", "oil temperature"),
    Field("status", "u2", 1, "", "MCU status word of the actuator (docs/mcu.md)"),
    Field("err_link_down", "u2", 1, "", "downstream LVDS words the driver board discarded"),
    Field("err_link_up", "u2", 1, "", "upstream LVDS words the MCU board discarded"),
)

FOOT_IN = tuple(Field(n, "i2", 0.1 if n[0] == "f" else 0.01, "N" if n[0] == "f" else "N m",
                      f"foot {n} (not simulated: 0)")
                for n in ("fx", "fy", "fz", "mx", "my", "mz"))
IMU_IN = tuple(Field(n, "i4", 1e-6, "rad/s" if n[0] == "w" else "m/s^2",
                     f"IMU {n} (not simulated: 0)")
               for n in ("wx", "wy", "wz", "ax", "ay", "az"))

#: The box's cycle counter (one per box, not per slot): an optional TxPDO of the EtherCAT
#: slaves (:mod:`hil.fieldbus.esc.slaves`), left out of the default image.
BOX_CYCLE = Field("cycle", "u4", 1, "",
                  "box cycles (1 ms each, on the box's own clock) run when this record was "
                  "published, the one that made it included; wraps at 2^32")

SLOT_FIELDS: dict[str, tuple[tuple[Field, ...], tuple[Field, ...]]] = {
    "actuator": (ACTUATOR_OUT, ACTUATOR_IN),
    "foot_sensor": ((), FOOT_IN),
    "imu": ((), IMU_IN),
}
SLOT_KINDS = tuple(SLOT_FIELDS)


def record_dtype(fields: tuple[Field, ...]) -> np.dtype:
    """Packed little-endian structured dtype of a record (no padding)."""
    return np.dtype([(f.name, "<" + f.dtype) for f in fields])


ACTUATOR_OUT_DTYPE = record_dtype(ACTUATOR_OUT)
ACTUATOR_IN_DTYPE = record_dtype(ACTUATOR_IN)


def slot_sizes(kind: str) -> tuple[int, int]:
    """(output bytes, input bytes) of one slot."""
    out, inp = SLOT_FIELDS[kind]
    return record_dtype(out).itemsize, record_dtype(inp).itemsize


_BOUNDS: dict[str, tuple[int, int]] = {}


def _bounds(dtype: str) -> tuple[int, int]:
    """(min, max) of an integer dtype, cached: np.iinfo is slow and the per-cycle path
    needs them per field."""
    bounds = _BOUNDS.get(dtype)
    if bounds is None:
        info = np.iinfo(np.dtype(dtype))
        bounds = _BOUNDS[dtype] = (int(info.min), int(info.max))
    return bounds


#: (min, max) of the 32-bit commands.
I4_BOUNDS = _bounds("i4")


def to_counts(value: float, lsb: float, dtype: str) -> int:
    """SI value -> integer count, rounded half away from zero and saturated to ``dtype``."""
    lo, hi = _bounds(dtype)
    return saturated_counts(value, lsb, lo, hi)


def saturated_counts(value: float, lsb: float, lo: int, hi: int) -> int:
    """:func:`to_counts` with the bounds given: one call a field on the echo boxes'
    per-cycle path (seven fields per actuator, 47 actuators on the whole robot)."""
    c = float(value) / lsb
    c = int(c + 0.5) if c >= 0 else -int(-c + 0.5)
    return lo if c < lo else (hi if c > hi else c)


def markdown_table(fields: tuple[Field, ...]) -> str:
    """The record as a markdown table: offset, field, type, LSB, unit, meaning."""
    lines = ["| offset | field | type | LSB | unit | meaning |", "|---|---|---|---|---|---|"]
    off = 0
    for f in fields:
        size = np.dtype(f.dtype).itemsize
        t = ("u" if f.dtype[0] == "u" else "s") + str(8 * size)
        lsb = "-" if f.lsb in (0, 1) and not f.unit else f"{f.lsb:g}"
        if f.lsb == 0.0:
            lsb = "by mode"
        lines.append(f"| {off} | `{f.name}` | {t} | {lsb} | {f.unit} | {f.doc} |")
        off += size
    lines.append(f"| | **{off} bytes** | | | | |")
    return "\n".join(lines)
