"""What each joint driver box says about itself as an EtherCAT slave: identity, PDOs and
sync managers (:class:`~firmware_model.esc.sii.SlaveDescription`), from the topology and
the process-data declaration (:mod:`hil.fieldbus.pdo`). The SII image and the ESI file
(:mod:`hil.fieldbus.esc.esi`) are both made from these descriptions.

Box types: boxes with the same slots kinds (e.g. three actuators) are one product; the
product code is ``0x48590000 | actuators << 8 | foot sensors << 4 | IMUs``; the serial
number is the box's position in the chain + 1.

Objects: slot ``k`` of a box has RxPDO ``0x1600 + k`` (entries ``0x7000 + 0x10 k``) and
TxPDO ``0x1A00 + k`` (entries ``0x6000 + 0x10 k``), subindex = field number + 1; RxPDOs are
assigned to SM2 (outputs, at 0x1100), TxPDOs to SM3 (inputs, at 0x1200). SM0 and SM1 are
the CoE mailbox (:data:`MBX_SIZE` bytes each, at 0x1000 and 0x1080); the object dictionary
is :mod:`firmware_model.esc.objects`.

With CoE a box also offers TxPDO :data:`CYCLE_PDO`, not assigned by default (the default
image stays the slots' records): its one entry is the box's cycle counter
(:data:`firmware_model.esc.sii.PDO_NOT_ASSIGNED` in the SII, no ``Sm`` in the ESI). A master
that appends it to 0x1C13 in PREOP reads with every input record the number of the box
cycle that made it, so it can tell box cycles apart from its own. ``coe=False`` describes
the same box without a mailbox (process data on SM0/SM1, as before the mailbox existed)
and without that PDO.
"""

from __future__ import annotations

from firmware_model.esc import sii
from firmware_model.esc.sii import Pdo, PdoEntry, SlaveDescription, SyncManager, build_image
from hil.fieldbus import pdo
from hil.fieldbus.topology import Box, Topology

#: Vendor id of the Hydra boxes. Not an ETG-assigned id: a placeholder a real deployment
#: replaces with its own.
VENDOR_ID = 0x00000E4A
REVISION = 0x00010000
SM_OUT_START = 0x1100
SM_IN_START = 0x1200
SM_OUT_CONTROL = 0x64   # buffered, ECAT writes, PDI IRQ, watchdog trigger
SM_IN_CONTROL = 0x20    # buffered, ECAT reads, PDI IRQ
MBX_OUT_START, MBX_IN_START, MBX_SIZE = 0x1000, 0x1080, 128
MBX_OUT_CONTROL = 0x26  # mailbox (1-buffer), ECAT writes, PDI IRQ
MBX_IN_CONTROL = 0x22   # mailbox, ECAT reads, PDI IRQ
#: The optional TxPDO of the box's cycle counter and its entry's object.
CYCLE_PDO, CYCLE_OBJECT = 0x1AFF, 0x6FFF
CYCLE_TX = Pdo(CYCLE_PDO, "box cycle", sii.PDO_NOT_ASSIGNED,
               (PdoEntry(CYCLE_OBJECT, 1, pdo.BOX_CYCLE.name, pdo.BOX_CYCLE.dtype),))


def box_kind_counts(box: Box) -> tuple[int, int, int]:
    """(actuators, foot sensors, IMUs) of a box."""
    kinds = [s.kind for s in box.slots]
    return kinds.count("actuator"), kinds.count("foot_sensor"), kinds.count("imu")


def product_code(box: Box) -> int:
    a, f, i = box_kind_counts(box)
    return 0x48590000 | a << 8 | f << 4 | i


def product_name(box: Box) -> str:
    a, f, i = box_kind_counts(box)
    parts = [f"{a} EHA"] if a else []
    parts += ["foot sensor"] * f + ["IMU"] * i
    return "Hydra box " + " + ".join(parts)


def _pdos(box: Box, direction: int, coe: bool) -> tuple[Pdo, ...]:
    out = []
    for k, s in enumerate(box.slots):
        fields = pdo.SLOT_FIELDS[s.kind][direction]
        if not fields:
            continue
        base = (0x7000 if direction == 0 else 0x6000) + 0x10 * k
        entries = tuple(PdoEntry(base, j + 1, f.name, f.dtype) for j, f in enumerate(fields))
        index = (0x1600 if direction == 0 else 0x1A00) + k
        out.append(Pdo(index, f"slot {k} {s.kind}", direction + (2 if coe else 0), entries))
    return tuple(out)


def describe(box: Box, coe: bool = True) -> SlaveDescription:
    """The slave description of one box (with the CoE mailbox unless ``coe`` is False)."""
    rx, tx = _pdos(box, 0, coe), _pdos(box, 1, coe)
    out_b, in_b = box.out_bytes, box.in_bytes
    if out_b > SM_IN_START - SM_OUT_START:
        raise ValueError(f"box {box.id}: {out_b} output bytes overlap the input buffer")
    pd = (SyncManager(SM_OUT_START, out_b, SM_OUT_CONTROL, out_b > 0, sii.SM_OUTPUTS),
          SyncManager(SM_IN_START, in_b, SM_IN_CONTROL, in_b > 0, sii.SM_INPUTS))
    mbx = (SyncManager(MBX_OUT_START, MBX_SIZE, MBX_OUT_CONTROL, True, sii.SM_MBX_OUT),
           SyncManager(MBX_IN_START, MBX_SIZE, MBX_IN_CONTROL, True, sii.SM_MBX_IN))
    return SlaveDescription(VENDOR_ID, product_code(box), REVISION, box.id + 1,
                            product_name(box), "Hydra joint boxes", rx, tx,
                            mbx + pd if coe else pd, coe=coe,
                            tx_optional=(CYCLE_TX,) if coe else ())


def describe_all(topo: Topology, coe: bool = True) -> list[tuple[SlaveDescription, bytes]]:
    """(description, SII image) of every box, in chain order."""
    return [(d, build_image(d)) for d in (describe(b, coe) for b in topo.boxes)]
