"""ESI (EtherCAT Slave Information, ETG.2000) XML for the box types of a topology:
``eha-hil esi --topology hydra_full > Hydra.xml``, for masters configured from ESI files
(TwinCAT, IgH's tools, ...). One ``Device`` per box type (product code), made from the same
descriptions as the SII images the chain serves (:mod:`hil.fieldbus.esc.slaves`), so the
two agree by construction; the tests parse the XML and check it against the SII anyway.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from firmware_model.esc.sii import SlaveDescription
from hil.fieldbus.esc.slaves import VENDOR_ID, describe_all
from hil.fieldbus.topology import Topology

#: ESI data type names of the process-data types.
ESI_TYPES = {"u1": "USINT", "u2": "UINT", "u4": "UDINT", "i1": "SINT", "i2": "INT",
             "i4": "DINT"}


def _hex(value: int, digits: int = 8) -> str:
    return f"#x{value:0{digits}X}"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrs: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrs)
    if text is not None:
        el.text = text
    return el


def _device(devices: ET.Element, d: SlaveDescription, image: bytes) -> None:
    dev = _sub(devices, "Device", Physics="YY")
    _sub(dev, "Type", f"Hydra{d.product_code:08X}", ProductCode=_hex(d.product_code),
         RevisionNo=_hex(d.revision))
    _sub(dev, "Name", d.name)
    _sub(dev, "GroupType", "HydraBoxes")
    _sub(dev, "Fmmu", "Outputs")
    _sub(dev, "Fmmu", "Inputs")
    for sm, what in zip(d.sms, ("Outputs", "Inputs"), strict=True):
        _sub(dev, "Sm", what, StartAddress=_hex(sm.start, 4), ControlByte=_hex(sm.control, 2),
             DefaultSize=str(sm.length), Enable="1" if sm.enable else "0")
    for tag, pdos in (("RxPdo", d.rx_pdos), ("TxPdo", d.tx_pdos)):
        for p in pdos:
            el = _sub(dev, tag, Fixed="1", Mandatory="1", Sm=str(p.sm))
            _sub(el, "Index", _hex(p.index, 4))
            _sub(el, "Name", p.name)
            for e in p.entries:
                en = _sub(el, "Entry")
                _sub(en, "Index", _hex(e.index, 4))
                _sub(en, "SubIndex", str(e.subindex))
                _sub(en, "BitLen", str(e.bits))
                _sub(en, "Name", e.name)
                _sub(en, "DataType", ESI_TYPES[e.dtype])
    _dc_opmodes(dev)
    eep = _sub(dev, "Eeprom")
    _sub(eep, "ByteSize", str(len(image)))
    _sub(eep, "ConfigData", image[:14].hex().upper())


#: DC operation modes: (name, description, AssignActivate: the word a master writes to
#: 0x0980/0x0981 (low byte cyclic unit control, high byte activation), SYNC0 cycle factor).
DC_OPMODES = (("FreeRun", "Free run: the MCU cycles on its own clock", 0x0000, None),
              ("DcSync", "DC synchronous: the MCU samples at SYNC0, one pulse per bus cycle",
               0x0300, 1))


def _dc_opmodes(dev: ET.Element) -> None:
    """The distributed-clock operation modes (firmware_model.esc.dc)."""
    dc = _sub(dev, "Dc")
    for name, desc, assign, factor in DC_OPMODES:
        op = _sub(dc, "OpMode")
        _sub(op, "Name", name)
        _sub(op, "Desc", desc)
        _sub(op, "AssignActivate", _hex(assign, 4))
        if factor is not None:
            _sub(op, "CycleTimeSync0", "0", Factor=str(factor))
            _sub(op, "ShiftTimeSync0", "0")


def esi_xml(topo: Topology) -> str:
    """The ESI document (one Device per distinct product code, in chain order)."""
    root = ET.Element("EtherCATInfo", Version="1.6")
    vendor = _sub(root, "Vendor")
    _sub(vendor, "Id", _hex(VENDOR_ID))
    _sub(vendor, "Name", "Hydra EHA (eha-hil emulated)")
    desc = _sub(root, "Descriptions")
    groups = _sub(desc, "Groups")
    group = _sub(groups, "Group")
    _sub(group, "Type", "HydraBoxes")
    _sub(group, "Name", "Hydra joint boxes")
    devices = _sub(desc, "Devices")
    seen: set[int] = set()
    for d, image in describe_all(topo):
        if d.product_code not in seen:
            seen.add(d.product_code)
            _device(devices, d, image)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, "unicode") + "\n"
