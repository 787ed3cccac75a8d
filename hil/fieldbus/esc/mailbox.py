"""The boxes' mailbox side: per slave, the CoE server (:mod:`firmware_model.esc.coe`) over
the box's object dictionary (:mod:`firmware_model.esc.objects`), wired to the box model
behind it, run once per box cycle on the box's clock (never in the frame path).

* requests the ESC's SM0 handed over are served, answers and emergencies go to SM1;
* a tunable written (0x2000 + p) goes to the box's MCU (:meth:`Mcu.tune
  <firmware_model.mcu.mcu.Mcu.tune>`, applied at its next step), or on the compiled robot
  engine to that actuator's C program (:meth:`RobotEngine.tune
  <hil.sim.robot.RobotEngine.tune>`: the same float32 constants, put into its state
  between two engine steps); a box model that does not run that part of the MCU (echo:
  only the command timeout) refuses it with the general error, so a master is never told
  a value was taken that changes nothing;
* a PDO assignment written in PREOP (0x1C12 / 0x1C13) makes the box exchange the smaller
  records: :meth:`Mailboxes.expand` and :meth:`Mailboxes.select` cut its full records to
  the assigned PDOs, and the ESC checks the master's sync managers against the new
  lengths at SAFEOP; a TxPDO not assigned by default (the box's cycle counter,
  :data:`~hil.fieldbus.esc.slaves.CYCLE_PDO`) follows the box model's record in the full
  one;
* emergencies: rising edges of each actuator's MCU command watchdog (CMD_TIMEOUT), link
  failure (LINK_ERROR) and driver-board trip (BOARD_FAULT) status bits.

``port`` is the ESCs' application interface: the compiled arrays
(:class:`~firmware_model.esc.compiled.EscArrays`) or a list of readable
:class:`~firmware_model.esc.esc.Esc` (:class:`EscPort`).
"""

from __future__ import annotations

import struct
from importlib.metadata import PackageNotFoundError, version

from firmware_model.calibration import calibration
from firmware_model.esc import coe, objects
from firmware_model.esc.objects import Abort, SdoAbort
from firmware_model.esc.sii import SlaveDescription
from firmware_model.mcu import mcu as mcu_status
from hil.fieldbus import pdo
from plant.config import Config

#: Status bits that raise an emergency on their rising edge: (bit, error code, register).
EMERGENCY_BITS = ((mcu_status.CMD_TIMEOUT, coe.EMCY_MCU_WATCHDOG, coe.ERR_COMMUNICATION),
                  (mcu_status.LINK_ERROR, coe.EMCY_LINK, coe.ERR_COMMUNICATION),
                  (mcu_status.BOARD_FAULT, coe.EMCY_DRIVER_TRIP, coe.ERR_GENERIC))
_STATUS_OFF = pdo.ACTUATOR_IN_DTYPE.fields["status"][1]
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")


def software_version() -> str:
    try:
        return f"eha-hil {version('eha-hil')}"
    except PackageNotFoundError:
        return "eha-hil"


class EscPort:
    """The readable ESCs' application side, as the compiled arrays offer it."""

    def __init__(self, escs: list) -> None:
        self.escs = escs

    def take_mailbox(self, i: int) -> bytes | None:
        return self.escs[i].take_mailbox()

    def mailbox_requests(self) -> list[int]:
        return [i for i, e in enumerate(self.escs) if e.mbx_rx_state == 1]

    def in_init(self) -> list[int]:
        return [i for i, e in enumerate(self.escs) if e.state == 1]

    def post_mailbox(self, i: int, data: bytes) -> bool:
        return self.escs[i].post_mailbox(data)

    def state(self, i: int) -> tuple[int, bool, int]:
        e = self.escs[i]
        return int(e.state), e.error, int(e.code)

    def set_pd_lengths(self, i: int, out_bytes: int, in_bytes: int) -> None:
        self.escs[i].set_pd_lengths(out_bytes, in_bytes)


def _ranges(pdos, assigned: list[int]) -> list[tuple[int, int]]:  # noqa: ANN001
    """(offset, length) in the full record of each assigned PDO, in assignment order."""
    offsets, pos = {}, 0
    for p in pdos:
        offsets[p.index] = (pos, p.bytes)
        pos += p.bytes
    return [offsets[i] for i in assigned]


class BoxMailbox:
    """Slave ``i``'s server and its box model ``box``."""

    def __init__(self, i: int, desc: SlaveDescription, box, port, cfg: Config) -> None:  # noqa: ANN001
        self.i, self.desc, self.box, self.port = i, desc, box, port
        cal = calibration(cfg)
        self.actuators = list(box.box.actuators)
        self.od = objects.build(desc, len(self.actuators), cal.mcu, software_version())
        self.od.on_tune = self._tune
        self.od.on_assign = self._assign
        self.server = coe.CoeServer(self.od, desc.sms[0].length, lambda: port.state(i)[0])
        self.out_ranges = _ranges(desc.rx_pdos, [p.index for p in desc.rx_pdos])
        self.in_ranges = _ranges(desc.tx_pdos + desc.tx_optional,
                                 [p.index for p in desc.tx_pdos])
        self.remapped = False
        self._status = [0] * len(self.actuators)
        self._status_at = [box._in_off[slot] + _STATUS_OFF for slot in self.actuators]

    # --- the dictionary's effects ---------------------------------------------------------
    def _tune(self, entry: objects.Entry, value: float) -> None:
        slot = entry.sub - 1
        key = entry.tunable
        box = self.box
        engine = getattr(box, "engine", None)
        if engine is not None:  # the compiled robot engine: that actuator's C program
            engine.tune(box, slot, key, value)
            return
        board = getattr(box, "board", None)
        if board is not None:
            board.mcu.tune(slot, key, value)
            return
        model = getattr(box, "model", None)
        if key == "command_timeout_s" and model is not None and hasattr(model, "timeout"):
            off = model.off - model.timeout
            model.timeout = round(value / box.tick_s)
            model.off = model.timeout + off
            return
        raise SdoAbort(Abort.GENERAL)

    def _assign(self, rx: list[int], tx: list[int]) -> None:
        self.out_ranges = _ranges(self.desc.rx_pdos, rx)
        self.in_ranges = _ranges(self.desc.tx_pdos + self.desc.tx_optional, tx)
        self.remapped = True
        self.port.set_pd_lengths(self.i, sum(n for _o, n in self.out_ranges),
                                 sum(n for _o, n in self.in_ranges))

    # --- records ------------------------------------------------------------------------------
    def expand(self, rec: bytes) -> bytes:
        """The master's (assigned) output record as the box's full one (left-out PDOs 0)."""
        if not self.remapped:
            return rec
        full = bytearray(self.desc.out_bytes)
        rec = rec.ljust(sum(n for _o, n in self.out_ranges), b"\0")
        pos = 0
        for off, n in self.out_ranges:
            full[off:off + n] = rec[pos:pos + n]
            pos += n
        return bytes(full)

    def select(self, rec: bytes, cycle: int) -> bytes:
        """The box's input record (made by box cycle number ``cycle``) cut to the assigned
        PDOs."""
        if not self.remapped:
            return rec
        if self.desc.tx_optional:  # the full record: the box model's, then the counter
            rec += _U32.pack(cycle & 0xFFFFFFFF)
        return b"".join(rec[off:off + n] for off, n in self.in_ranges)

    # --- once per box cycle -----------------------------------------------------------------
    def receive(self) -> None:
        req = self.port.take_mailbox(self.i)
        if req is not None:
            self.server.receive(req)

    def flush(self) -> None:
        """The next answer or emergency into SM1's hand-over, if it is free."""
        msg = self.server.outgoing()
        if msg is not None and self.port.post_mailbox(self.i, msg):
            self.server.sent()

    def watch(self) -> None:
        """Emergencies on the rising edges of the actuators' status bits (the box's record
        as it stands after its cycle)."""
        buf = self.box._in_buf
        for j, at in enumerate(self._status_at):
            status = _U16.unpack_from(buf, at)[0]
            rising = status & ~self._status[j]
            self._status[j] = status
            if rising:
                for bit, code, register in EMERGENCY_BITS:
                    if rising & bit:
                        self.server.emergency(code, register, bytes([self.actuators[j]]))


class Mailboxes:
    """Every slave's :class:`BoxMailbox` (slaves without a mailbox: None)."""

    def __init__(self, described: list[tuple[SlaveDescription, bytes]], boxes: list, port,  # noqa: ANN001
                 cfg: Config) -> None:
        self.each = [BoxMailbox(i, d, b, port, cfg) if d.coe else None
                     for i, ((d, _img), b) in enumerate(zip(described, boxes, strict=True))]
        self.active = [m for m in self.each if m is not None]
        self.port = port

    def step(self) -> None:
        """One box cycle: waiting requests served, emergencies looked for, answers out. A
        slave in INIT forgets its mailbox session (the next master starts counting anew)."""
        each = self.each
        for i in self.port.in_init():
            if each[i] is not None:
                each[i].server.reset()
        for i in self.port.mailbox_requests():
            if each[i] is not None:
                each[i].receive()
        for m in self.active:
            m.watch()
            if m.server.outgoing() is not None:
                m.flush()

    def expand(self, i: int, rec: bytes) -> bytes:
        m = self.each[i]
        return rec if m is None else m.expand(rec)

    def select(self, i: int, rec: bytes, cycle: int) -> bytes:
        """Box ``i``'s input record, made by its cycle number ``cycle`` (box cycles run so
        far, that one included), as its assignment has it."""
        m = self.each[i]
        return rec if m is None else m.select(rec, cycle)

    def stats(self) -> list[dict]:
        return [dict(m.server.stats) if m is not None else {} for m in self.each]
