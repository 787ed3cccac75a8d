"""The CoE object dictionary of one box (ETG.1000.6 / CiA 301 object layout), generated from
its slave description (:class:`~firmware_model.esc.sii.SlaveDescription`) and the MCU's
tunables (:mod:`firmware_model.mcu.tunables`):

* 0x1000 device type, 0x1008 name, 0x1009 hardware and 0x100A software version;
* 0x1018 identity (equal to the SII's);
* 0x1600 + k / 0x1A00 + k: the fixed PDO mappings of slot k (read only), and of the
  TxPDOs not assigned by default;
* 0x1C00 sync manager types; 0x1C12 / 0x1C13 PDO assignment of SM2 / SM3 (writable in
  PREOP only: a master may drop PDOs, the box then exchanges the smaller records);
* 0x1C32 / 0x1C33: sync manager parameters (free run, 1 ms cycle);
* 0x2000 + p: MCU tunable p, one REAL32 per actuator (subindex = actuator + 1), with unit
  and range; 0x2100 restores every tunable to the calibration values (write ``"load"``).

Reads and writes go through :meth:`Dictionary.read` / :meth:`Dictionary.write`, which raise
:class:`SdoAbort` with the standard's abort code; complete access (sub 0 as 16 bits, then
the subindexes in order) is :meth:`read_complete` / :meth:`write_complete`.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from firmware_model.esc.sii import SlaveDescription
from firmware_model.mcu import tunables as tn


class Abort(enum.IntEnum):
    """SDO abort codes (ETG.1000.6 Table 41, CiA 301) this dictionary answers with."""

    TOGGLE = 0x05030000               # toggle bit not alternated
    TIMEOUT = 0x05040000              # SDO protocol timed out
    COMMAND = 0x05040001              # client/server command specifier not valid or unknown
    UNSUPPORTED_ACCESS = 0x06010000   # unsupported access to an object
    WRITE_ONLY = 0x06010001           # attempt to read a write only object
    READ_ONLY = 0x06010002            # attempt to write a read only object
    SUB0_NOT_ZERO = 0x06010003        # subindex cannot be written, SI0 must be 0
    NO_OBJECT = 0x06020000            # the object does not exist in the dictionary
    PARAMETER_INCOMPATIBLE = 0x06040043  # general parameter incompatibility
    LENGTH_MISMATCH = 0x06070010      # data type does not match, length does not match
    LENGTH_HIGH = 0x06070012          # data type does not match, length too high
    LENGTH_LOW = 0x06070013           # data type does not match, length too low
    NO_SUBINDEX = 0x06090011          # subindex does not exist
    VALUE_RANGE = 0x06090030          # value range of parameter exceeded
    VALUE_HIGH = 0x06090031           # value of parameter written too high
    VALUE_LOW = 0x06090032            # value of parameter written too low
    GENERAL = 0x08000000              # general error
    NOT_STORED = 0x08000020           # data cannot be transferred or stored
    STATE = 0x08000022                # ... because of the present device state


class SdoAbort(Exception):
    def __init__(self, code: Abort) -> None:
        super().__init__(f"SDO abort {int(code):#010x} ({code.name})")
        self.code = code


#: CoE data types: (code, struct format; strings have none).
DTYPES = {"bool": (0x0001, "<?"), "i8": (0x0002, "<b"), "i16": (0x0003, "<h"),
          "i32": (0x0004, "<i"), "u8": (0x0005, "<B"), "u16": (0x0006, "<H"),
          "u32": (0x0007, "<I"), "f32": (0x0008, "<f"), "str": (0x0009, "")}
ESI_NAMES = {"bool": "BOOL", "i8": "SINT", "i16": "INT", "i32": "DINT", "u8": "USINT",
             "u16": "UINT", "u32": "UDINT", "f32": "REAL", "str": "STRING"}
_SII_TO_DTYPE = {"i1": "i8", "i2": "i16", "i4": "i32", "u1": "u8", "u2": "u16", "u4": "u32"}

# Access: "ro", "rw" (any state from PREOP), "rw_preop" (PREOP only), "wo".
READABLE = ("ro", "rw", "rw_preop")
PREOP = 2
RESTORE_SIGNATURE = 0x64616F6C   # "load", CiA 301's restore signature

DEVICE_TYPE = 0x00000000         # no standard device profile
HW_VERSION = "MCU board 1 (STM32F4) + ESC"
SYNC_FREE_RUN = 0x0000
SYNC_MODES_SUPPORTED = 0x0001    # free run only (bit 0)


@dataclass
class Entry:
    sub: int
    name: str
    dtype: str
    access: str
    value: int | float | str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    tunable: str | None = None   # MCU tunable key (its actuator is ``sub - 1``)

    @property
    def size(self) -> int:
        """Bytes of the value (a string's current length)."""
        if self.dtype == "str":
            return len(str(self.value).encode("ascii"))
        return struct.calcsize(DTYPES[self.dtype][1])

    def encode(self) -> bytes:
        if self.dtype == "str":
            return str(self.value).encode("ascii")
        return struct.pack(DTYPES[self.dtype][1], self.value)

    def decode(self, data: bytes) -> int | float:
        return struct.unpack(DTYPES[self.dtype][1], data)[0]


@dataclass
class Obj:
    index: int
    name: str
    code: str                    # "VAR", "ARRAY" or "RECORD"
    entries: dict[int, Entry] = field(default_factory=dict)

    def add(self, *entries: Entry) -> Obj:
        for e in entries:
            self.entries[e.sub] = e
        return self


def _var(index: int, name: str, dtype: str, value: int | str, access: str = "ro") -> Obj:
    return Obj(index, name, "VAR").add(Entry(0, name, dtype, access, value))


def _count(n: int, access: str = "ro", high: int | None = None) -> Entry:
    return Entry(0, "Number of entries", "u8", access, n, low=0, high=high)


class Dictionary:
    """The objects of one box (``objects``: index -> :class:`Obj`), their values now.

    ``on_tune(entry, value)``: a tunable was written (raise SdoAbort to refuse it);
    ``on_assign(rx, tx)``: the PDO assignment changed (lists of PDO indexes)."""

    def __init__(self, objects: dict[int, Obj]) -> None:
        self.objects = dict(sorted(objects.items()))
        self.on_tune: Callable[[Entry, float], None] = lambda e, v: None
        self.on_assign: Callable[[list[int], list[int]], None] = lambda rx, tx: None
        self.defaults = {(o.index, e.sub): e.value for o in self.objects.values()
                         for e in o.entries.values() if e.tunable}

    # --- lookups ------------------------------------------------------------------------
    def entry(self, index: int, sub: int) -> Entry:
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(Abort.NO_OBJECT)
        e = obj.entries.get(sub)
        if e is None:
            raise SdoAbort(Abort.NO_SUBINDEX)
        return e

    def assignment(self, index: int) -> list[int]:
        o = self.objects[index]
        return [int(o.entries[k].value) for k in range(1, int(o.entries[0].value) + 1)]

    # --- reads --------------------------------------------------------------------------
    def read(self, index: int, sub: int) -> bytes:
        e = self.entry(index, sub)
        if e.access == "wo":
            raise SdoAbort(Abort.WRITE_ONLY)
        return e.encode()

    def read_complete(self, index: int, sub: int) -> bytes:
        """Complete access from ``sub`` (0 or 1): sub 0 as 16 bits, then subindexes 1..n."""
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(Abort.NO_OBJECT)
        if obj.code == "VAR" or sub > 1:
            raise SdoAbort(Abort.UNSUPPORTED_ACCESS)
        n = int(obj.entries[0].value)
        out = struct.pack("<H", n) if sub == 0 else b""
        for k in range(1, n + 1):
            e = obj.entries.get(k)
            if e is None:
                raise SdoAbort(Abort.UNSUPPORTED_ACCESS)
            if e.access == "wo":
                raise SdoAbort(Abort.WRITE_ONLY)
            out += e.encode()
        return out

    # --- writes -------------------------------------------------------------------------
    def _check_write(self, index: int, e: Entry, state: int) -> None:
        if e.access == "ro":
            raise SdoAbort(Abort.READ_ONLY)
        if e.access == "rw_preop" and state != PREOP:
            raise SdoAbort(Abort.STATE)

    def _value(self, e: Entry, data: bytes) -> int | float:
        if e.dtype == "str":
            raise SdoAbort(Abort.READ_ONLY)
        if len(data) > e.size:
            raise SdoAbort(Abort.LENGTH_HIGH)
        if len(data) < e.size:
            raise SdoAbort(Abort.LENGTH_LOW)
        v = e.decode(data)
        if e.tunable is not None:
            side = tn.in_range(e.tunable, float(v))
            if side:
                raise SdoAbort(Abort.VALUE_HIGH if side > 0 else Abort.VALUE_LOW)
        elif (e.low is not None and v < e.low) or (e.high is not None and v > e.high):
            raise SdoAbort(Abort.VALUE_RANGE)
        return v

    def write(self, index: int, sub: int, data: bytes, state: int) -> None:
        e = self.entry(index, sub)
        self._check_write(index, e, state)
        v = self._value(e, data)
        obj = self.objects[index]
        if index in (0x1C12, 0x1C13):
            if sub and obj.entries[0].value:  # entries change only while sub 0 is 0
                raise SdoAbort(Abort.SUB0_NOT_ZERO)
            self._write_assignment(obj, {sub: int(v)})
            return
        if index == 0x2100:
            if v != RESTORE_SIGNATURE:
                raise SdoAbort(Abort.NOT_STORED)
            self._restore()
            return
        if e.tunable is not None:
            self.on_tune(e, float(v))
        e.value = v

    def write_complete(self, index: int, sub: int, data: bytes, state: int) -> None:
        """Complete access write from ``sub`` (0: sub 0 as 16 bits first, then 1..n)."""
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(Abort.NO_OBJECT)
        if obj.code == "VAR" or sub > 1:
            raise SdoAbort(Abort.UNSUPPORTED_ACCESS)
        for e in obj.entries.values():
            if e.sub >= sub:
                self._check_write(index, e, state)
        if sub == 0:
            if len(data) < 2:
                raise SdoAbort(Abort.LENGTH_LOW)
            n = struct.unpack_from("<H", data)[0]
            pos = 2
        else:
            n, pos = int(obj.entries[0].value), 0
        subs = [obj.entries.get(k) for k in range(1, n + 1)]
        if any(e is None for e in subs) or n > 255:
            raise SdoAbort(Abort.VALUE_RANGE)
        need = pos + sum(e.size for e in subs)
        if len(data) < need:
            raise SdoAbort(Abort.LENGTH_LOW)
        if len(data) > pos + sum(e.size for e in obj.entries.values() if e.sub):
            raise SdoAbort(Abort.LENGTH_HIGH)
        values: dict[int, int | float] = {}
        for e in subs:
            values[e.sub] = self._value(e, data[pos:pos + e.size])
            pos += e.size
        if sub == 0:
            values[0] = self._value(obj.entries[0], bytes([n]))
        if index in (0x1C12, 0x1C13):
            self._write_assignment(obj, values)
            return
        for k, v in values.items():  # (only the assignments have writable arrays today)
            obj.entries[k].value = v

    # --- the special objects ----------------------------------------------------------------
    def _write_assignment(self, obj: Obj, values: dict[int, int]) -> None:
        """0x1C12 / 0x1C13 (ETG.1000.6: sub 0 set to 0, the entries written, sub 0 set to
        their number): every index written must be one of this direction's PDOs, each
        assigned once; the box takes the new assignment (and the ESC its lengths) at once."""
        now = {k: int(e.value) for k, e in obj.entries.items()}
        now.update(values)
        n = now[0]
        pdo_base = 0x1600 if obj.index == 0x1C12 else 0x1A00
        assigned = [now[k] for k in range(1, n + 1)]
        written = [v for k, v in values.items() if k]
        if any(not (pdo_base <= p < pdo_base + 0x200 and p in self.objects)
               for p in assigned + written):
            raise SdoAbort(Abort.VALUE_RANGE)
        if len(set(assigned)) != len(assigned):
            raise SdoAbort(Abort.PARAMETER_INCOMPATIBLE)
        for k, v in now.items():
            obj.entries[k].value = v
        self.on_assign(self.assignment(0x1C12), self.assignment(0x1C13))

    def _restore(self) -> None:
        for (index, sub), v in self.defaults.items():
            e = self.objects[index].entries[sub]
            self.on_tune(e, float(v))
            e.value = v


def _mapping(index: int, name: str, entries) -> Obj:  # noqa: ANN001
    obj = Obj(index, name, "RECORD").add(_count(len(entries)))
    for k, pe in enumerate(entries, start=1):
        obj.add(Entry(k, f"{pe.name} ({pe.index:#06x}:{pe.subindex})", "u32", "ro",
                      pe.index << 16 | pe.subindex << 8 | pe.bits))
    return obj


def _assignment(index: int, name: str, pdos, optional=()) -> Obj:  # noqa: ANN001
    """An assignment object: the default PDOs, and a (zero) entry more for each PDO
    not assigned by default, so that a master can assign every PDO at once."""
    n = len(pdos) + len(optional)
    obj = Obj(index, name, "ARRAY").add(_count(len(pdos), "rw_preop", high=n))
    for k in range(1, n + 1):
        obj.add(Entry(k, f"PDO {k}", "u16", "rw_preop", pdos[k - 1].index if k <= len(pdos)
                      else 0))
    return obj


def _sync_parameters(index: int, name: str, cycle_ns: int) -> Obj:
    obj = Obj(index, name, "RECORD").add(_count(12))
    for sub, sub_name, dtype, access, value, unit in (
            (1, "Sync mode", "u16", "rw_preop", SYNC_FREE_RUN, ""),
            (2, "Cycle time", "u32", "ro", cycle_ns, "ns"),
            (3, "Shift time", "u32", "ro", 0, "ns"),
            (4, "Sync modes supported", "u16", "ro", SYNC_MODES_SUPPORTED, ""),
            (5, "Minimum cycle time", "u32", "ro", cycle_ns, "ns"),
            (6, "Calc and copy time", "u32", "ro", 0, "ns"),
            (7, "Minimum delay time", "u32", "ro", 0, "ns"),
            (8, "Get cycle time", "u16", "ro", 0, ""),
            (9, "Delay time", "u32", "ro", 0, "ns"),
            (10, "Sync0 cycle time", "u32", "ro", 0, "ns"),
            (11, "SM event missed", "u16", "ro", 0, ""),
            (12, "Cycle time too small", "u16", "ro", 0, "")):
        low_high = (SYNC_FREE_RUN, SYNC_FREE_RUN) if sub == 1 else (None, None)
        obj.add(Entry(sub, sub_name, dtype, access, value, unit, *low_high))
    return obj


def build(desc: SlaveDescription, actuators: int, mcu_defaults: dict[str, float],
          software: str, cycle_ns: int = 1_000_000) -> Dictionary:
    """The dictionary of a box: ``desc`` (identity, PDOs), its number of actuators, the
    MCU's calibration values of the tunables, its software version text."""
    objs = [
        _var(0x1000, "Device type", "u32", DEVICE_TYPE),
        _var(0x1008, "Device name", "str", desc.name),
        _var(0x1009, "Hardware version", "str", HW_VERSION),
        _var(0x100A, "Software version", "str", software),
        Obj(0x1018, "Identity", "RECORD").add(
            _count(4), Entry(1, "Vendor ID", "u32", "ro", desc.vendor_id),
            Entry(2, "Product code", "u32", "ro", desc.product_code),
            Entry(3, "Revision", "u32", "ro", desc.revision),
            Entry(4, "Serial number", "u32", "ro", desc.serial)),
    ]
    for p in desc.rx_pdos + desc.tx_pdos + desc.tx_optional:
        objs.append(_mapping(p.index, p.name, p.entries))
    kinds = [sm.kind for sm in desc.sms]
    objs.append(Obj(0x1C00, "Sync manager type", "ARRAY").add(
        _count(len(kinds)), *(Entry(k + 1, f"SM{k}", "u8", "ro", v) for k, v in enumerate(kinds))))
    objs.append(_assignment(0x1C12, "RxPDO assign", desc.rx_pdos))
    objs.append(_assignment(0x1C13, "TxPDO assign", desc.tx_pdos, desc.tx_optional))
    objs.append(_sync_parameters(0x1C32, "SM output parameter", cycle_ns))
    objs.append(_sync_parameters(0x1C33, "SM input parameter", cycle_ns))
    if actuators:
        for p, t in enumerate(tn.TUNABLES):
            obj = Obj(0x2000 + p, t.name, "ARRAY").add(_count(actuators))
            for a in range(actuators):
                obj.add(Entry(a + 1, f"Actuator {a}", "f32", "rw",
                              float(struct.unpack("<f", struct.pack("<f", mcu_defaults[t.key]))[0]),
                              t.unit, t.low, t.high, t.key))
            objs.append(obj)
        objs.append(_var(0x2100, "Restore tunables", "u32", 0, "wo"))
    return Dictionary({o.index: o for o in objs})


def pdo_entry_dtype(sii_dtype: str) -> str:
    """The dictionary's type name of a PDO entry's SII type."""
    return _SII_TO_DTYPE[sii_dtype]
