"""The chain of boxes as EtherCAT slaves: one ESC model per box
(:class:`firmware_model.esc.esc.Esc`) in front of the box model (echo or full stack), for a
real master (SOEM, TwinCAT, IgH) on a raw Ethernet link (:mod:`hil.fieldbus.esc.serve`).

A frame passes the slaves in line order: every datagram is handed to slave 0, then 1, ...
each changing data, ADP and working counter as its ESC would on the fly; the frame goes back
with the source MAC's locally-administered bit set, as the first ESC does on the way home.
Frames that are not EtherType 0x88A4 are ignored; EtherCAT frames that do not decode
(truncated, lengths inconsistent) are dropped and counted, as an ESC drops a frame with a
bad FCS.

Time: :meth:`EscChain.cycle` is one 1 ms bus cycle of the boxes (20 ticks): each slave's
watchdog advances, outputs the master wrote in OP (or the safe outputs) are applied, the
box runs, its mailbox side serves CoE (:mod:`hil.fieldbus.esc.mailbox`), and its inputs go
into the slave's input buffer. The project's own master keeps
its preconfigured chain (:class:`hil.fieldbus.chain.Chain`, fixed logical windows, no AL
states), on which the committed logs replay.
"""

from __future__ import annotations

from dataclasses import dataclass

from firmware_model.esc.dc import DcParams, dc_line
from firmware_model.esc.esc import Esc
from hil.fieldbus.boxes import make_box
from hil.fieldbus.chain import CYCLE_TICKS
from hil.fieldbus.esc.mailbox import EscPort, Mailboxes
from hil.fieldbus.esc.slaves import describe_all
from hil.fieldbus.topology import Topology
from plant.config import Config
from protocols import ethercat as ec
from protocols.errors import CodecError

CYCLE_NS = 1_000_000


@dataclass
class EscChainStats:
    frames: int = 0            # EtherCAT frames answered
    dropped_frames: int = 0    # EtherCAT frames that did not decode (e.g. truncated)
    other_frames: int = 0      # not EtherType 0x88A4: ignored
    datagrams: int = 0
    cycles: int = 0


class EscChain:
    """ESCs + box models of a topology. ``stack_boxes``: box ids that get the full stack
    (the others the ``model`` given, echo by default). ``dc``: the slaves' clocks and
    delays (:func:`firmware_model.esc.dc.dc_line` by default)."""

    def __init__(self, topo: Topology, cfg: Config, model: str = "echo",
                 stack_boxes: tuple[int, ...] = (), dc: list[DcParams] | None = None) -> None:
        self.topology = topo
        described = describe_all(topo)
        n = len(topo.boxes)
        dc = dc if dc is not None else dc_line(n)
        self.escs = [Esc(d, img, last=i == n - 1, dc=dc[i])
                     for i, (d, img) in enumerate(described)]
        self.boxes = [make_box("stack" if b.id in stack_boxes else model, b, cfg)
                      for b in topo.boxes]
        for esc, box in zip(self.escs, self.boxes, strict=True):
            esc.set_inputs(box.inputs())
        #: The boxes' mailbox side (CoE), run with the boxes each cycle.
        self.mailboxes = Mailboxes(described, self.boxes, EscPort(self.escs), cfg)
        self.stats = EscChainStats()

    # --- frames -----------------------------------------------------------------------------
    def handle(self, frame: bytes) -> bytes | None:
        """One Ethernet frame in; the frame going back, or None if dropped/ignored."""
        try:
            eth = ec.decode_ethernet(frame)
        except CodecError:
            self.stats.other_frames += 1
            return None
        if eth.ethertype != ec.ETHERTYPE_ETHERCAT:
            self.stats.other_frames += 1
            return None
        try:
            dgs = ec.decode_pdu(eth.payload, allow_trailing=True)
        except CodecError:
            self.stats.dropped_frames += 1
            return None
        out = [self.process(d) for d in dgs]
        self._hand_outputs()
        self.stats.frames += 1
        self.stats.datagrams += len(dgs)
        src = bytes([eth.src[0] | 0x02]) + eth.src[1:]
        return ec.encode_ethernet(ec.encode_pdu(out), eth.dst, src, ec.ETHERTYPE_ETHERCAT)

    def process(self, d: ec.Datagram) -> ec.Datagram:
        """One datagram through every slave in line order."""
        data = bytearray(d.data)
        adp, wkc = d.adp, d.wkc
        for esc in self.escs:
            adp, wkc = esc.process(d.cmd, adp, d.ado, data, wkc)
        return ec.Datagram(d.cmd, d.idx, adp, d.ado, bytes(data), wkc & 0xFFFF, d.irq,
                           d.circulating)

    def _hand_outputs(self) -> None:
        for i, (esc, box) in enumerate(zip(self.escs, self.boxes, strict=True)):
            out = esc.pending_outputs()
            if out is not None:
                box.apply(self.mailboxes.expand(i, out))

    # --- time -------------------------------------------------------------------------------
    def cycle(self) -> None:
        """One 1 ms bus cycle of every slave and box (lockstep: the slaves' clocks are the
        boxes' simulated time)."""
        for esc in self.escs:
            esc.tick(CYCLE_NS)
        self._hand_outputs()
        self.advance_boxes()
        self.publish_inputs()

    def advance_boxes(self) -> None:
        """The boxes' side of one cycle: every box one cycle on (no ESC touched)."""
        for box in self.boxes:
            box.advance(CYCLE_TICKS)
        self.mailboxes.step()
        self.stats.cycles += 1

    def publish_inputs(self) -> None:
        """Every box's input record into its ESC's input buffer."""
        for i, (esc, box) in enumerate(zip(self.escs, self.boxes, strict=True)):
            esc.set_inputs(self.mailboxes.select(i, box.inputs(), self.stats.cycles))

    def watchdog_report(self) -> list[dict]:
        """Per slave: watchdog time, trips and the delay of the last trip [ms]."""
        return [{"box": i, "watchdog_ms": e.watchdog_ns() / 1e6, "trips": e.watchdog_trips,
                 "last_trip_after_ms": e.last_trip_delay_ns / 1e6,
                 "al_status": e.mem[0x130] | e.mem[0x131] << 8,
                 "al_status_code": e.mem[0x134] | e.mem[0x135] << 8}
                for i, e in enumerate(self.escs)]
