"""The SII EEPROM image of a slave (ETG.2010), built from its process-data description.

Layout (16-bit words, little endian):

* words 0x00..0x07: ESC configuration area (PDI control, station alias, CRC-8 in word 7);
* 0x08 vendor id, 0x0A product code, 0x0C revision, 0x0E serial number (u32 each);
* 0x14..0x17: bootstrap mailbox (none); 0x18/0x19 receive mailbox (master -> slave, SM0)
  offset and size, 0x1A/0x1B send mailbox (SM1), 0x1C the mailbox protocols (CoE); all zero
  for a slave without a mailbox (a master then builds the process image from the
  TxPDO/RxPDO categories below);
* 0x3E EEPROM size, 0x3F version;
* from 0x40, categories (type u16, size in words u16, data): Strings (10), General (30),
  FMMU (40), SyncM (41), TxPDO (50), RxPDO (51), end marker 0xFFFF.

Strings are numbered from 1; string 1 is the device name (what SOEM shows as the slave's
name), and the General category points at it too.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

CAT_STRINGS = 10
CAT_GENERAL = 30
CAT_FMMU = 40
CAT_SYNCM = 41
CAT_TXPDO = 50
CAT_RXPDO = 51
CAT_END = 0xFFFF

#: CoE data type codes of the entries' types (ETG.1000.6 Table "Basic data types").
DATA_TYPES = {"i1": 0x0002, "i2": 0x0003, "i4": 0x0004, "u1": 0x0005, "u2": 0x0006,
              "u4": 0x0007}
BITS = {"i1": 8, "i2": 16, "i4": 32, "u1": 8, "u2": 16, "u4": 32}

#: FMMU category codes.
FMMU_OUTPUTS, FMMU_INPUTS = 1, 2
#: General category, PhysicalPort: 4 bits per port (0 not used, 1 MII, 3 EBUS).
PORTS_MII_MII = 0x0011
#: Word 0x3E: EEPROM size in KiBit, minus 1 (0x000F: 16 KiBit).
EEPROM_SIZE_CODE = 0x000F
#: Sync manager types (SyncM category byte 7, object 0x1C00): mailbox out (master ->
#: slave), mailbox in, process-data outputs, process-data inputs.
SM_MBX_OUT, SM_MBX_IN, SM_OUTPUTS, SM_INPUTS = 1, 2, 3, 4
#: Mailbox protocol bits (SII word 0x1C) and CoE details (General category byte 5).
MBX_PROTO_COE = 0x0004
COE_SDO, COE_SDO_INFO, COE_PDO_ASSIGN, COE_PDO_CONFIG, COE_UPLOAD, COE_SDO_CA = (
    0x01, 0x02, 0x04, 0x08, 0x10, 0x20)
#: SyncM byte of a PDO category entry for a PDO not assigned by default (no sync manager:
#: a master sizing the image from the SII, as SOEM does, counts only PDOs whose sync
#: manager is in range; with CoE a master may assign it through 0x1C12 / 0x1C13).
PDO_NOT_ASSIGNED = 0xFF


@dataclass(frozen=True)
class PdoEntry:
    index: int
    subindex: int
    name: str
    dtype: str          # key of DATA_TYPES

    @property
    def bits(self) -> int:
        return BITS[self.dtype]


@dataclass(frozen=True)
class Pdo:
    index: int          # 0x16xx (RxPDO, outputs) or 0x1Axx (TxPDO, inputs)
    name: str
    sm: int             # sync manager it is assigned to (PDO_NOT_ASSIGNED: none by default)
    entries: tuple[PdoEntry, ...]

    @property
    def bytes(self) -> int:
        return sum(e.bits for e in self.entries) // 8


@dataclass(frozen=True)
class SyncManager:
    start: int          # physical start address
    length: int         # bytes
    control: int        # SM control byte
    enable: bool
    kind: int = 0       # SM_MBX_OUT .. SM_INPUTS (0: not said)


@dataclass(frozen=True)
class SlaveDescription:
    """What the SII (and the ESI) says about one slave type and instance."""

    vendor_id: int
    product_code: int
    revision: int
    serial: int
    name: str
    group: str
    rx_pdos: tuple[Pdo, ...]        # outputs (master -> slave)
    tx_pdos: tuple[Pdo, ...]        # inputs (slave -> master)
    sms: tuple[SyncManager, ...]    # with a mailbox: SM0/SM1 mailbox, SM2 outputs, SM3
    #                                 inputs; without: SM0 outputs, SM1 inputs
    pdi_control: int = 0x05         # PDI: SPI slave (the ESC talks to the MCU over SPI)
    alias: int = 0
    coe: bool = False               # a mailbox (SM0/SM1) speaking CoE
    #: TxPDOs not assigned by default (after ``tx_pdos`` in the SII, the ESI and the full
    #: input record); a master assigns them through 0x1C13 in PREOP.
    tx_optional: tuple[Pdo, ...] = ()

    @property
    def out_sm(self) -> int:
        """Index of the process-data output sync manager."""
        return 2 if self.coe else 0

    @property
    def in_sm(self) -> int:
        """Index of the process-data input sync manager."""
        return 3 if self.coe else 1

    @property
    def out_bytes(self) -> int:
        return sum(p.bytes for p in self.rx_pdos)

    @property
    def in_bytes(self) -> int:
        return sum(p.bytes for p in self.tx_pdos)


def crc8_config(data: bytes) -> int:
    """CRC-8 of the configuration area words 0..6 (polynomial x^8+x^2+x+1, init 0xFF)."""
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


class _Strings:
    def __init__(self) -> None:
        self.items: list[bytes] = []

    def add(self, s: str) -> int:
        raw = s.encode("ascii", "replace")[:255]
        if raw in self.items:
            return self.items.index(raw) + 1
        self.items.append(raw)
        return len(self.items)


def _category(kind: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return struct.pack("<HH", kind, len(data) // 2) + data


def _pdo_category(pdos: tuple[Pdo, ...], strings: _Strings) -> bytes:
    out = bytearray()
    for p in pdos:
        out += struct.pack("<HBBBBH", p.index, len(p.entries), p.sm, 0, strings.add(p.name), 0)
        for e in p.entries:
            out += struct.pack("<HBBBBH", e.index, e.subindex, strings.add(e.name),
                               DATA_TYPES[e.dtype], e.bits, 0)
    return bytes(out)


def build_image(d: SlaveDescription) -> bytes:
    """The EEPROM contents (bytes; even length) for slave ``d``."""
    cfg = struct.pack("<HHHHHHH", d.pdi_control, 0, 0, 0, d.alias, 0, 0)
    head = bytearray(cfg + struct.pack("<H", crc8_config(cfg)))
    head += struct.pack("<IIII", d.vendor_id, d.product_code, d.revision, d.serial)
    head += bytes(0x18 * 2 - len(head))
    if d.coe:
        rx, tx = d.sms[0], d.sms[1]
        head += struct.pack("<HHHHH", rx.start, rx.length, tx.start, tx.length,
                            MBX_PROTO_COE)
    head += bytes(0x3E * 2 - len(head))
    head += struct.pack("<HH", EEPROM_SIZE_CODE, 0x0001)  # version 1
    strings = _Strings()
    name_idx = strings.add(d.name)  # string 1: the device name
    group_idx = strings.add(d.group)
    txpdo = _pdo_category(d.tx_pdos + d.tx_optional, strings)
    rxpdo = _pdo_category(d.rx_pdos, strings)
    general = bytearray(32)
    general[0] = group_idx
    general[1] = 0                  # image
    general[2] = name_idx           # order
    general[3] = name_idx           # name
    # bytes 5..9: CoE/FoE/EoE/SoE details: SDO, PDO assignment, complete access with CoE
    general[5] = COE_SDO | COE_PDO_ASSIGN | COE_SDO_CA if d.coe else 0
    struct.pack_into("<h", general, 12, 0)  # current on E-bus [mA]: none (MII ports)
    struct.pack_into("<H", general, 16, PORTS_MII_MII)  # ports 0,1: MII; 2,3: not used
    fmmu = bytes([FMMU_OUTPUTS, FMMU_INPUTS])
    syncm = b"".join(struct.pack("<HHBBBB", s.start, s.length, s.control, 0,
                                 1 if s.enable else 0, s.kind) for s in d.sms)
    str_data = bytes([len(strings.items)]) + b"".join(
        bytes([len(s)]) + s for s in strings.items)
    body = (_category(CAT_STRINGS, str_data) + _category(CAT_GENERAL, bytes(general))
            + _category(CAT_FMMU, fmmu) + _category(CAT_SYNCM, syncm))
    if txpdo:
        body += _category(CAT_TXPDO, txpdo)
    if rxpdo:
        body += _category(CAT_RXPDO, rxpdo)
    body += struct.pack("<H", CAT_END)
    image = bytes(head) + body
    image += bytes(-len(image) % 8)
    if len(image) > eeprom_bytes(image):
        raise ValueError(f"{d.name}: SII image of {len(image)} bytes does not fit the "
                         f"{eeprom_bytes(image)}-byte EEPROM it declares")
    return image


# --- reading an image back (for the ESI cross-check and the docs) ---------------------------
def categories(image: bytes) -> dict[int, bytes]:
    """Category type -> data of an image."""
    out, pos = {}, 0x40 * 2
    while pos + 2 <= len(image):
        kind = struct.unpack_from("<H", image, pos)[0]
        if kind == CAT_END:
            break
        size = struct.unpack_from("<H", image, pos + 2)[0] * 2
        out[kind] = image[pos + 4:pos + 4 + size]
        pos += 4 + size
    return out


def eeprom_bytes(image: bytes) -> int:
    """The EEPROM size the image declares (word 0x3E: KiBit - 1), in bytes."""
    return (struct.unpack_from("<H", image, 0x3E * 2)[0] + 1) * 1024 // 8


def mailbox(image: bytes) -> tuple[int, int, int, int, int]:
    """(receive offset, size, send offset, size, protocols) of an image's mailbox."""
    return struct.unpack_from("<HHHHH", image, 0x18 * 2)


def identity(image: bytes) -> tuple[int, int, int, int]:
    """(vendor id, product code, revision, serial) of an image."""
    return struct.unpack_from("<IIII", image, 0x08 * 2)


def strings(image: bytes) -> list[str]:
    """The Strings category (index 1 first)."""
    data = categories(image).get(CAT_STRINGS, b"\x00")
    out, pos = [], 1
    for _ in range(data[0]):
        n = data[pos]
        out.append(data[pos + 1:pos + 1 + n].decode("ascii"))
        pos += 1 + n
    return out


def pdo_bits(image: bytes, kind: int) -> int:
    """Total mapped bits of the PDOs the TxPDO (50) or RxPDO (51) category assigns to a
    sync manager (those not assigned by default left out)."""
    data, pos, total = categories(image).get(kind, b""), 0, 0
    while pos + 8 <= len(data):
        n, assigned = data[pos + 2], data[pos + 3] != PDO_NOT_ASSIGNED
        pos += 8
        for _ in range(n):
            total += data[pos + 5] if assigned else 0
            pos += 8
    return total
