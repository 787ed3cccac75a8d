"""`eha-hil esi` states nothing its SII images do not: every field of every Device of the
ESI is compared with the image the chain serves, the image read here with the byte layout
of ETG.2010 (not with the project's reader)."""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET

import pytest

from hil.fieldbus.esc.esi import esi_xml
from hil.fieldbus.esc.slaves import describe_all
from hil.fieldbus.topology import load_topology

#: ETG.2010 category types, CoE data type codes -> ESI names, port codes -> ESI Physics.
STRINGS, GENERAL, FMMU, SYNCM, TXPDO, RXPDO = 10, 30, 40, 41, 50, 51
DATA_TYPES = {0x0002: "SINT", 0x0003: "INT", 0x0004: "DINT", 0x0005: "USINT",
              0x0006: "UINT", 0x0007: "UDINT"}
PHYSICS = {0x1: "Y", 0x3: "K", 0x4: "H"}
FMMU_USE = {1: "Outputs", 2: "Inputs", 3: "MBoxState"}
SM_TYPE = {1: "MBoxOut", 2: "MBoxIn", 3: "Outputs", 4: "Inputs"}
#: A PDO category's SyncM for a PDO not assigned by default (no sync manager; a master
#: sizing the image from the SII, as SOEM does, skips it); its ESI TxPdo has no Sm.
NO_SM = 0xFF


def _image(image: bytes) -> dict:
    """What an ETG.2010 reader finds in an SII image."""
    cats, pos = {}, 0x40 * 2
    while True:
        kind = struct.unpack_from("<H", image, pos)[0]
        if kind == 0xFFFF:
            break
        words = struct.unpack_from("<H", image, pos + 2)[0]
        cats[kind] = image[pos + 4:pos + 4 + 2 * words]
        pos += 4 + 2 * words
    s, strings, p = cats[STRINGS], [], 1
    for _ in range(s[0]):
        strings.append(s[p + 1:p + 1 + s[p]].decode("ascii"))
        p += 1 + s[p]

    def text(i: int) -> str:
        return strings[i - 1] if i else ""

    def pdos(data: bytes) -> list[dict]:
        out, p = [], 0
        while p < len(data):
            index, n, sm, _sync, name, _flags = struct.unpack_from("<HBBBBH", data, p)
            p += 8
            entries = []
            for _ in range(n):
                e_index, sub, e_name, dtype, bits, _f = struct.unpack_from("<HBBBBH", data, p)
                p += 8
                entries.append((e_index, sub, bits, text(e_name), DATA_TYPES[dtype]))
            out.append({"index": index, "sm": sm, "name": text(name), "entries": entries})
        return out

    gen = cats[GENERAL]
    ports = struct.unpack_from("<H", gen, 16)[0]
    vendor, product, revision, _serial = struct.unpack_from("<IIII", image, 0x08 * 2)
    return {
        "vendor": vendor, "product": product, "revision": revision,
        "group": text(gen[0]), "name": text(gen[3]),
        "physics": "".join(PHYSICS[(ports >> (4 * k)) & 0xF] for k in range(4)
                           if (ports >> (4 * k)) & 0xF),
        "fmmu": [FMMU_USE[b] for b in cats[FMMU] if b],
        "sm": [struct.unpack_from("<HHBBBB", cats[SYNCM], 8 * k)
               for k in range(len(cats[SYNCM]) // 8)],
        "rx": pdos(cats.get(RXPDO, b"")), "tx": pdos(cats.get(TXPDO, b"")),
        "eeprom_bytes": (struct.unpack_from("<H", image, 0x3E * 2)[0] + 1) * 1024 // 8,
        "config": image[:14],
    }


def _int(s: str) -> int:
    return int(s[2:], 16) if s.startswith("#x") else int(s)


@pytest.mark.parametrize("topology", ["bench_one_box", "hydra_full"])
def test_every_esi_field_is_what_the_sii_image_says(topology: str) -> None:
    topo = load_topology(topology)
    root = ET.fromstring(esi_xml(topo))
    groups = {g.find("Type").text: g.find("Name").text for g in root.iter("Group")}
    devices = {_int(d.find("Type").get("ProductCode")): d for d in root.iter("Device")}
    images = describe_all(topo)
    assert set(devices) == {d.product_code for d, _ in images}
    for _, image in images:
        img = _image(image)
        assert _int(root.find("Vendor/Id").text) == img["vendor"]
        dev = devices[img["product"]]
        assert dev.get("Physics") == img["physics"]
        assert _int(dev.find("Type").get("RevisionNo")) == img["revision"]
        assert dev.find("Name").text == img["name"]
        assert groups[dev.find("GroupType").text] == img["group"]
        assert [f.text for f in dev.findall("Fmmu")] == img["fmmu"]
        sms = dev.findall("Sm")
        assert len(sms) == len(img["sm"])
        for sm, (start, length, control, _status, enable, kind) in zip(sms, img["sm"],
                                                                       strict=True):
            assert (_int(sm.get("StartAddress")), _int(sm.get("DefaultSize")),
                    _int(sm.get("ControlByte")), _int(sm.get("Enable")), sm.text) == \
                (start, length, control, enable & 1, SM_TYPE[kind])
        for tag, key in (("RxPdo", "rx"), ("TxPdo", "tx")):
            esi = [{"index": _int(p.find("Index").text), "sm": _int(p.get("Sm", str(NO_SM))),
                    "name": p.find("Name").text,
                    "entries": [(_int(e.find("Index").text), _int(e.find("SubIndex").text),
                                 _int(e.find("BitLen").text), e.find("Name").text,
                                 e.find("DataType").text) for e in p.findall("Entry")]}
                   for p in dev.findall(tag)]
            assert esi == img[key], tag
        eep = dev.find("Eeprom")
        assert _int(eep.find("ByteSize").text) == img["eeprom_bytes"] >= len(image)
        assert bytes.fromhex(eep.find("ConfigData").text) == img["config"]
