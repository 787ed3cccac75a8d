"""ESI (EtherCAT Slave Information, ETG.2000) XML for the box types of a topology:
``eha-hil esi --topology hydra_full > Hydra.xml``, for masters configured from ESI files
(TwinCAT, IgH's tools, ...). One ``Device`` per box type (product code), made from the same
descriptions as the SII images the chain serves (:mod:`hil.fieldbus.esc.slaves`), so the
two agree by construction; the tests parse the XML and check it against the SII anyway.

Each Device has its Mailbox (CoE: SDO, PDO assignment, complete access) and its Profile's
Dictionary: every object of :mod:`firmware_model.esc.objects` with its data type, access
per state, default value, and for the MCU tunables unit and range.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from firmware_model.calibration import calibration
from firmware_model.esc import objects, sii
from firmware_model.esc.sii import SlaveDescription
from hil.fieldbus.esc.mailbox import software_version
from hil.fieldbus.esc.slaves import VENDOR_ID, describe_all
from hil.fieldbus.topology import Box, Topology
from plant.config import Config, load_config

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


_ACCESS = {"ro": ("ro", None), "rw": ("rw", None), "wo": ("wo", None),
           "rw_preop": ("rw", "PREOP")}


def _default(e: objects.Entry) -> str:
    """A string's text, else its bytes as sent (little endian) in hex, as ETG.2000 has it."""
    return str(e.value) if e.dtype == "str" else e.encode().hex().upper()


def _dictionary(profile: ET.Element, od: objects.Dictionary) -> None:
    """ETG.2000 Dictionary: one DataType per object (its subitems), then the Objects."""
    dic = _sub(profile, "Dictionary")
    types = _sub(dic, "DataTypes")
    done: set[str] = set()
    for o in od.objects.values():
        for e in o.entries.values():
            name = objects.ESI_NAMES[e.dtype]
            if e.dtype == "str":
                name = f"STRING({max(e.size, 1)})"
            if name not in done:
                done.add(name)
                dt = _sub(types, "DataType")
                _sub(dt, "Name", name)
                _sub(dt, "BitSize", str(8 * max(e.size, 1)))
        if o.code != "VAR":
            dt = _sub(types, "DataType")
            _sub(dt, "Name", f"DT{o.index:04X}")
            _sub(dt, "BitSize", str(16 + 8 * sum(e.size for e in o.entries.values() if e.sub)))
            offset = 0
            for e in o.entries.values():
                si = _sub(dt, "SubItem")
                _sub(si, "SubIdx", str(e.sub))
                _sub(si, "Name", e.name)
                _sub(si, "Type", objects.ESI_NAMES[e.dtype])
                _sub(si, "BitSize", str(8 * e.size))
                _sub(si, "BitOffs", str(offset))
                offset += 16 if e.sub == 0 else 8 * e.size
                _flags(si, e)
    objs = _sub(dic, "Objects")
    for o in od.objects.values():
        ob = _sub(objs, "Object")
        _sub(ob, "Index", _hex(o.index, 4))
        _sub(ob, "Name", o.name)
        if o.code == "VAR":
            e = o.entries[0]
            _sub(ob, "Type", f"STRING({max(e.size, 1)})" if e.dtype == "str"
                 else objects.ESI_NAMES[e.dtype])
            _sub(ob, "BitSize", str(8 * max(e.size, 1)))
            info = _sub(ob, "Info")
            _sub(info, "DefaultData" if e.dtype != "str" else "DefaultString", _default(e))
            _flags(ob, e)
            continue
        _sub(ob, "Type", f"DT{o.index:04X}")
        _sub(ob, "BitSize", str(16 + 8 * sum(e.size for e in o.entries.values() if e.sub)))
        info = _sub(ob, "Info")
        for e in o.entries.values():
            si = _sub(info, "SubItem")
            _sub(si, "Name", e.name)
            sinfo = _sub(si, "Info")
            if e.low is not None:
                _sub(sinfo, "MinValue", repr(e.low))
                _sub(sinfo, "MaxValue", repr(e.high))
            _sub(sinfo, "DefaultData", _default(e))
            if e.unit:
                _sub(sinfo, "Unit", e.unit)


def _flags(parent: ET.Element, e: objects.Entry) -> None:
    access, states = _ACCESS[e.access]
    flags = _sub(parent, "Flags")
    if states:
        _sub(flags, "Access", access, WriteRestrictions=states)
    else:
        _sub(flags, "Access", access)


def _device(devices: ET.Element, d: SlaveDescription, image: bytes, box: Box,
            cfg: Config) -> None:
    dev = _sub(devices, "Device", Physics="YY")
    _sub(dev, "Type", f"Hydra{d.product_code:08X}", ProductCode=_hex(d.product_code),
         RevisionNo=_hex(d.revision))
    _sub(dev, "Name", d.name)
    _sub(dev, "GroupType", "HydraBoxes")
    _sub(dev, "Fmmu", "Outputs")
    _sub(dev, "Fmmu", "Inputs")
    whats = ("MBoxOut", "MBoxIn", "Outputs", "Inputs") if d.coe else ("Outputs", "Inputs")
    for sm, what in zip(d.sms, whats, strict=True):
        _sub(dev, "Sm", what, StartAddress=_hex(sm.start, 4), ControlByte=_hex(sm.control, 2),
             DefaultSize=str(sm.length), Enable="1" if sm.enable else "0")
    for tag, pdos in (("RxPdo", d.rx_pdos), ("TxPdo", d.tx_pdos + d.tx_optional)):
        for p in pdos:
            # with CoE a master may leave a PDO out of the assignment (0x1C12 / 0x1C13); one
            # not assigned by default has no Sm (ETG.2000)
            sm = {} if p.sm == sii.PDO_NOT_ASSIGNED else {"Sm": str(p.sm)}
            el = _sub(dev, tag, Fixed="1", Mandatory="0" if d.coe else "1", **sm)
            _sub(el, "Index", _hex(p.index, 4))
            _sub(el, "Name", p.name)
            for e in p.entries:
                en = _sub(el, "Entry")
                _sub(en, "Index", _hex(e.index, 4))
                _sub(en, "SubIndex", str(e.subindex))
                _sub(en, "BitLen", str(e.bits))
                _sub(en, "Name", e.name)
                _sub(en, "DataType", ESI_TYPES[e.dtype])
    if d.coe:
        mbx = _sub(dev, "Mailbox", DataLinkLayer="1")
        _sub(mbx, "CoE", SdoInfo="0", PdoAssign="1", PdoConfig="0", CompleteAccess="1",
             SegmentedSdo="1")
        profile = _sub(dev, "Profile")
        _sub(profile, "ProfileNo", "0")
        od = objects.build(d, len(box.actuators), calibration(cfg).mcu, software_version())
        _dictionary(profile, od)
        dev.remove(profile)
        dev.insert(3, profile)  # ETG.2000's order: Type, Name, GroupType, Profile, Fmmu, ...
    _dc_opmodes(dev)  # after Mailbox, before Eeprom
    eep = _sub(dev, "Eeprom")
    # the EEPROM's size as the image declares it (word 0x3E), not the bytes it fills
    _sub(eep, "ByteSize", str(sii.eeprom_bytes(image)))
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


def esi_xml(topo: Topology, cfg: Config | None = None) -> str:
    """The ESI document (one Device per distinct product code, in chain order); ``cfg``:
    the configuration whose MCU calibration gives the tunables' defaults (the default
    preset's if None)."""
    cfg = cfg if cfg is not None else load_config()
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
    for (d, image), box in zip(describe_all(topo), topo.boxes, strict=True):
        if d.product_code not in seen:
            seen.add(d.product_code)
            _device(devices, d, image, box, cfg)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, "unicode") + "\n"
