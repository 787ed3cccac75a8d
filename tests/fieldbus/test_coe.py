"""The boxes' CoE mailbox in this process: SDO transfers through the readable ESC chain's
SM0/SM1 (requests written and answers read as a master does, one box cycle between), every
abort path with its standard code, malformed mailbox headers answered with the mailbox
error and counted, segmented transfers, emergencies, and tunables reaching the MCU.
SOEM against the served chain over a veth pair: tests/fieldbus/test_ethercat_coe.py."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from firmware_model.esc import coe, objects, sii
from firmware_model.esc import registers as r
from firmware_model.esc.objects import Abort
from firmware_model.mcu.mcu import CMD_TIMEOUT
from hil.fieldbus.boxes import make_box
from hil.fieldbus.esc.chain import EscChain
from hil.fieldbus.esc.master import STATION_BASE, EscMaster
from hil.fieldbus.esc.slaves import CYCLE_PDO
from protocols import ethercat as ec
from tests.fieldbus.test_esc import THREE

MBX = 128


class Client:
    """A master's side of one slave's mailbox (SM0 at 0x1000, SM1 at 0x1080)."""

    def __init__(self, chain: EscChain, station: int = STATION_BASE) -> None:
        self.chain, self.station = chain, station
        self.m = EscMaster(chain)
        self.counter = 0

    def raw(self, message: bytes) -> bytes | None:
        """Write a mailbox message (padded to SM0's size), one box cycle, read SM1."""
        d = self.m.one(ec.Command.FPWR, self.station, 0x1000, message.ljust(MBX, b"\0"))
        assert d.wkc == 1, "SM0 refused the request"
        self.chain.cycle()
        d = self.m.one(ec.Command.FPRD, self.station, 0x1080, bytes(MBX))
        return d.data if d.wkc == 1 else None

    def coe(self, sdo: bytes, counter: int | None = None) -> bytes:
        """An SDO request (command byte onwards, at least 8 bytes); the answer's CoE part."""
        if counter is None:
            self.counter = self.counter % 7 + 1
            counter = self.counter
        body = struct.pack("<H", coe.COE_SDO_REQUEST << 12) + sdo.ljust(8, b"\0")
        reply = self.raw(struct.pack("<HHBB", len(body), 0, 0, coe.TYPE_COE | counter << 4)
                         + body)
        assert reply is not None
        length = struct.unpack_from("<H", reply)[0]
        return reply[6:6 + length]

    def upload(self, index: int, sub: int, ca: bool = False) -> bytes:
        ans = self.coe(struct.pack("<BHB", 0x40 | 0x10 * ca, index, sub))
        cmd = ans[2]
        if cmd == 0x80:
            raise objects.SdoAbort(Abort(struct.unpack_from("<I", ans, 6)[0]))
        if cmd & 0x02:
            return ans[6:10][:4 - (cmd >> 2 & 3)]
        size = struct.unpack_from("<I", ans, 6)[0]
        data, toggle = ans[10:], 0
        while len(data) < size:  # segments (the frame's data: length - 3, n if 7)
            seg = self.coe(bytes([0x60 | toggle << 4]))
            chunk = seg[3:]
            if seg[2] & 1 and len(chunk) == 7:
                chunk = chunk[:7 - (seg[2] >> 1 & 7)]
            data += chunk
            toggle ^= 1
        return data[:size]

    def download(self, index: int, sub: int, data: bytes, ca: bool = False) -> int:
        """Expedited up to 4 bytes (not complete access), else normal: 0 or the abort code."""
        if len(data) <= 4 and not ca:
            ans = self.coe(struct.pack("<BHB", 0x23 | (4 - len(data)) << 2, index, sub)
                           + data.ljust(4, b"\0"))
        else:
            ans = self.coe(struct.pack("<BHBI", 0x21 | 0x10 * ca, index, sub, len(data)) + data)
        return struct.unpack_from("<I", ans, 6)[0] if ans[2] == 0x80 else 0


@pytest.fixture
def preop(cfg):
    chain = EscChain(THREE, cfg, "echo")
    c = Client(chain)
    c.m.bring_up(to_op=False)
    return c


def test_identity_and_dictionary_objects_read_over_sdo(preop):
    d = preop.chain.escs[0].desc
    ident = [struct.unpack("<I", preop.upload(0x1018, k))[0] for k in range(1, 5)]
    assert ident == [d.vendor_id, d.product_code, d.revision, d.serial]
    assert preop.upload(0x1008, 0).decode() == d.name
    ca = preop.upload(0x1C12, 0, ca=True)   # complete access: sub 0 as 16 bits, then 1..n
    assert list(struct.unpack(f"<H{len(d.rx_pdos)}H", ca)) == [len(d.rx_pdos)] + [
        p.index for p in d.rx_pdos]
    mapping = preop.upload(0x1A00, 0, ca=True)
    n = mapping[0]
    bits = [e & 0xFF for e in struct.unpack_from(f"<{n}I", mapping, 2)]
    assert sum(bits) // 8 == d.tx_pdos[0].bytes
    assert preop.upload(0x1C00, 0, ca=True)[2:] == bytes([1, 2, 3, 4])


def _op(c: Client) -> None:
    for state in (r.AlState.SAFEOP, r.AlState.OP):
        assert c.m.set_state(STATION_BASE, state)[0] == state


ABORTS = [  # (what, state, (upload index, sub) or (download index, sub, data), code)
    ("object does not exist", "preop", (0x3000, 0), Abort.NO_OBJECT),
    ("subindex does not exist", "preop", (0x1018, 9), Abort.NO_SUBINDEX),
    ("read only", "preop", (0x1018, 1, b"\0\0\0\0"), Abort.READ_ONLY),
    ("write only", "preop", (0x2100, 0), Abort.WRITE_ONLY),
    ("length too high", "preop", (0x1C12, 1, b"\0\0\x16\0"), Abort.LENGTH_HIGH),
    ("length too low", "preop", (0x2000, 1, b"\0\0"), Abort.LENGTH_LOW),
    ("value too high", "preop", (0x2000, 1, struct.pack("<f", 1e6)), Abort.VALUE_HIGH),
    ("value too low", "preop", (0x2000, 1, struct.pack("<f", -1.0)), Abort.VALUE_LOW),
    ("value range", "preop", (0x1C13, 0, b"\x09"), Abort.VALUE_RANGE),
    ("entry written while sub 0 is not 0", "preop", (0x1C13, 1, struct.pack("<H", 0x1A01)),
     Abort.SUB0_NOT_ZERO),
    ("PDO that does not exist", "sub0=0", (0x1C13, 1, struct.pack("<H", 0x1A07)),
     Abort.VALUE_RANGE),
    ("PDO assigned twice", "twice", (0x1C13, 0, b"\x02"), Abort.PARAMETER_INCOMPATIBLE),
    ("not in this state", "op", (0x1C13, 0, b"\x01"), Abort.STATE),
    ("restore without its signature", "preop", (0x2100, 0, b"save"), Abort.NOT_STORED),
    ("general error: the echo model has no force loop", "preop",
     (0x2000, 1, struct.pack("<f", 1.0)), Abort.GENERAL),
]


@pytest.mark.parametrize("what, state, req, code", ABORTS, ids=[a[0] for a in ABORTS])
def test_every_abort_path_answers_its_standard_code(preop, what, state, req, code):
    if state == "op":
        _op(preop)
    if state in ("sub0=0", "twice"):  # ETG.1000.6's order: sub 0 to 0, then the entries
        assert preop.download(0x1C13, 0, b"\0") == 0
    if state == "twice":
        for k in (1, 2):
            assert preop.download(0x1C13, k, struct.pack("<H", 0x1A00)) == 0
    od = preop.chain.mailboxes.each[0].od
    before = {(o.index, e.sub): e.value for o in od.objects.values() for e in o.entries.values()}
    if len(req) == 2:
        with pytest.raises(objects.SdoAbort) as exc:
            preop.upload(*req)
        got = exc.value.code
    else:
        got = preop.download(*req)
    assert got == code
    after = {(o.index, e.sub): e.value for o in od.objects.values() for e in o.entries.values()}
    assert after == before   # an abort changes nothing
    assert preop.chain.mailboxes.stats()[0][f"abort_{int(code):#010x}"] == 1


def test_protocol_aborts(preop):
    """Command specifier, toggle, a segment nobody asked for, an oversize segment, complete
    access to a variable."""
    c = preop
    ans = c.coe(bytes([0xE0]))
    assert ans[2] == 0x80 and struct.unpack_from("<I", ans, 6)[0] == Abort.COMMAND
    ans = c.coe(bytes([0x00]) + bytes(7))          # download segment without an initiate
    assert struct.unpack_from("<I", ans, 6)[0] == Abort.COMMAND
    # normal download of 6 bytes announced, 2 sent: segments expected
    ans = c.coe(struct.pack("<BHBI", 0x21 | 0x10, 0x1C13, 0, 6) + b"\x02\x00")
    assert ans[2] == 0x60
    ans = c.coe(bytes([0x10]) + bytes(7))          # toggle must start at 0
    assert struct.unpack_from("<I", ans, 6)[0] == Abort.TOGGLE
    ans = c.coe(struct.pack("<BHBI", 0x21 | 0x10, 0x1C13, 0, 6) + b"\x02\x00")
    ans = c.coe(bytes([0x01]) + bytes(9))          # 9 bytes where 4 were left: too many
    assert struct.unpack_from("<I", ans, 6)[0] == Abort.LENGTH_HIGH
    ans = c.coe(struct.pack("<BHB", 0x50, 0x1000, 0))
    assert struct.unpack_from("<I", ans, 6)[0] == Abort.UNSUPPORTED_ACCESS
    ans = c.coe(struct.pack("<BHBI", 0x21, 0x1C13, 1, 2) + b"\x00\x1a\x00\x00")
    assert struct.unpack_from("<I", ans, 6)[0] == Abort.LENGTH_MISMATCH
    # and the server still answers
    assert preop.upload(0x1018, 2) == struct.pack("<I", c.chain.escs[0].desc.product_code)


MALFORMED = [  # (what, mailbox message (counter 0), mailbox error detail)
    ("length beyond the mailbox", struct.pack("<HHBB", 200, 0, 0, 0x03), 0x08),
    ("no CoE header", struct.pack("<HHBB", 1, 0, 0, 0x03) + b"\0", 0x06),
    ("SoE, not offered", struct.pack("<HHBB", 10, 0, 0, 0x05) + bytes(10), 0x02),
    ("channel 1", struct.pack("<HHBB", 10, 0, 1, 0x03) + bytes(10), 0x03),
    ("SDO information, not offered", struct.pack("<HHBB", 10, 0, 0, 0x03) + b"\0\x80"
     + bytes(8), 0x04),
    ("SDO request shorter than 8 bytes", struct.pack("<HHBB", 4, 0, 0, 0x03) + b"\0\x20"
     + bytes(2), 0x06),
]


@pytest.mark.parametrize("what, message, detail", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_mailbox_headers_get_the_mailbox_error_and_are_counted(preop, what, message,
                                                                         detail):
    reply = preop.raw(message)
    assert reply is not None
    length, _a, _c, kind = struct.unpack_from("<HHBB", reply)
    assert (kind & 0x0F, length) == (coe.TYPE_ERROR, 4)
    assert struct.unpack_from("<HH", reply, 6) == (0x0001, detail)
    assert preop.chain.mailboxes.stats()[0][f"mailbox_error_{detail:#04x}"] == 1
    assert preop.upload(0x1018, 1)  # never a crash: the next request is served


def test_a_repeated_counter_is_not_served_twice(preop):
    preop.coe(struct.pack("<BHB", 0x40, 0x1018, 1), counter=5)
    d = preop.m.one(ec.Command.FPWR, STATION_BASE, 0x1000,
                    (struct.pack("<HHBB", 10, 0, 0, 0x53) + struct.pack("<HBHB", 0x2000, 0x40,
                                                                       0x1018, 1)).ljust(MBX,
                                                                                         b"\0"))
    assert d.wkc == 1
    preop.chain.cycle()
    assert preop.m.one(ec.Command.FPRD, STATION_BASE, 0x1080, bytes(MBX)).wkc == 0  # no answer
    assert preop.chain.mailboxes.stats()[0]["mailbox_repeats_ignored"] == 1


def test_segmented_upload_and_download_through_a_small_mailbox(cfg):
    """A 16-byte mailbox: the device name (no room in the first answer) comes in segments, and a
    complete-access assignment written in segments is taken whole."""
    chain = EscChain(THREE, cfg, "echo")
    mb = chain.mailboxes.each[0]
    server = coe.CoeServer(mb.od, 16, lambda: 2)
    sent = []

    def ask(sdo: bytes) -> bytes:
        body = struct.pack("<H", coe.COE_SDO_REQUEST << 12) + sdo.ljust(8, b"\0")
        server.receive(struct.pack("<HHBB", len(body), 0, 0, 0x03) + body)
        msg = server.outgoing()
        server.sent()
        sent.append(msg)
        assert len(msg) <= 16
        return msg[6:6 + struct.unpack_from("<H", msg)[0]]

    name = mb.desc.name.encode()
    ans = ask(struct.pack("<BHB", 0x40, 0x1008, 0))
    assert ans[2] == 0x41 and struct.unpack_from("<I", ans, 6)[0] == len(name)
    got, toggle = ans[10:], 0
    while len(got) < len(name):
        seg = ask(bytes([0x60 | toggle << 4]))
        assert seg[2] >> 4 & 1 == toggle
        chunk = seg[3:]
        if seg[2] & 1 and len(chunk) == 7:
            chunk = chunk[:7 - (seg[2] >> 1 & 7)]
        got += chunk
        toggle ^= 1
    assert got == name and len(sent) == 4  # the last segment: 1 byte, n = 6
    # download: 0x1C12 complete access, [1, 0, 0x1601] in two pieces
    data = struct.pack("<BBH", 1, 0, 0x1601)
    assert ask(struct.pack("<BHBI", 0x31, 0x1C12, 0, len(data)) + data[:2])[2] == 0x60
    assert ask(bytes([0x01 | (7 - 2) << 1]) + data[2:] + bytes(5))[2] == 0x20
    assert mb.od.assignment(0x1C12) == [0x1601]
    assert chain.escs[0].out_bytes == mb.desc.rx_pdos[1].bytes


def test_remapped_box_exchanges_the_smaller_records(preop):
    """0x1C13 without the first TxPDO: SAFEOP refused with the SII's length, the box's
    inputs are its full record without that PDO."""
    d = preop.chain.escs[0].desc
    keep = [p.index for p in d.tx_pdos[1:]]
    assert preop.download(0x1C13, 0, struct.pack(f"<BB{len(keep)}H", len(keep), 0, *keep),
                          ca=True) == 0
    assert preop.chain.escs[0].in_bytes == d.in_bytes - d.tx_pdos[0].bytes
    # the master still configures the SII's length: refused with 0x001E
    status, code = preop.m.set_state(STATION_BASE, r.AlState.SAFEOP)
    assert (status, code) == (r.AlState.PREOP | r.AL_ERROR, r.AlStatusCode.INVALID_INPUT_CONFIG)
    start = d.sms[d.in_sm].start
    preop.chain.cycle()
    full = preop.chain.boxes[0].inputs()
    mem = bytes(preop.chain.escs[0].mem[start:start + d.in_bytes])
    assert mem[:len(full) - d.tx_pdos[0].bytes] == full[d.tx_pdos[0].bytes:]


def test_cycle_counter_pdo_assigned_stamps_each_record_with_its_box_cycle(preop):
    """TxPDO 0x1AFF appended to 0x1C13 in PREOP: the inputs are the box's full record, then
    the number of box cycles run, the one that made the record included (not the bus's:
    cycles without a frame count too)."""
    d = preop.chain.escs[0].desc
    keep = [p.index for p in d.tx_pdos] + [CYCLE_PDO]
    assert preop.download(0x1C13, 0, struct.pack(f"<BB{len(keep)}H", len(keep), 0, *keep),
                          ca=True) == 0
    assert preop.chain.escs[0].in_bytes == d.in_bytes + 4
    start = d.sms[d.in_sm].start
    for _ in range(3):
        preop.chain.cycle()
        mem = bytes(preop.chain.escs[0].mem[start:start + d.in_bytes + 4])
        assert mem[:d.in_bytes] == preop.chain.boxes[0].inputs()
        assert struct.unpack_from("<I", mem, d.in_bytes)[0] == preop.chain.stats.cycles > 0
    # not assigned by default: the SII's sizes and the default image leave it out
    assert CYCLE_PDO not in [p.index for p in d.tx_pdos]
    assert sii.pdo_bits(preop.chain.escs[0].sii, sii.CAT_TXPDO) == 8 * d.in_bytes


def test_mcu_watchdog_trip_sends_its_emergency(cfg):
    chain = EscChain(THREE, cfg, "echo")
    c = Client(chain)
    c.m.bring_up()
    mb = chain.mailboxes.each[0]
    rec = bytearray(chain.boxes[0].out_dtype.itemsize)
    struct.pack_into("<BBi", rec, 0, 1, 1, 10_000)
    chain.boxes[0].apply(bytes(rec))       # one command, then none: the watchdog trips
    for _ in range(15):
        chain.cycle()
    status = struct.unpack_from("<H", chain.boxes[0].inputs(), 16)[0]
    assert status & CMD_TIMEOUT
    d = c.m.one(ec.Command.FPRD, STATION_BASE, 0x1080, bytes(MBX))
    assert d.wkc == 1
    length, _a, _c, kind = struct.unpack_from("<HHBB", d.data)
    coe_head, code, register, slot = struct.unpack_from("<HHBB", d.data, 6)
    assert (kind & 0x0F, length, coe_head >> 12) == (coe.TYPE_COE, 10, coe.COE_EMERGENCY)
    assert (code, register, slot) == (coe.EMCY_MCU_WATCHDOG, coe.ERR_COMMUNICATION, 0)
    assert mb.server.stats["emergencies"] == 1


def _stack_chain(cfg) -> tuple[EscChain, Client]:
    chain = EscChain(THREE, cfg, "echo", stack_boxes=(0, 2))
    c = Client(chain)
    c.m.bring_up(to_op=False)
    return chain, c


def test_tunable_write_reaches_the_mcu_at_its_next_step_and_only_that_box(cfg):
    chain, c = _stack_chain(cfg)
    mcu = chain.boxes[0].board.mcu
    other = chain.boxes[2].board.mcu
    kp0 = float(mcu.ctrl[1].kp)
    assert c.download(0x2000, 2, struct.pack("<f", 0.5)) == 0
    assert c.upload(0x2000, 2) == struct.pack("<f", 0.5)
    # taken by the MCU (the cycle after the write ran its steps): actuator 1 only
    assert (float(mcu.ctrl[1].kp), float(mcu.ctrl[0].kp)) == (0.5, kp0)
    assert float(other.ctrl[0].kp) == kp0
    # out of range: aborted, nothing changed
    assert c.download(0x2000, 2, struct.pack("<f", 25.0)) == Abort.VALUE_HIGH
    chain.cycle()
    assert float(mcu.ctrl[1].kp) == 0.5
    # restore: the calibration's value again
    assert c.download(0x2100, 0, struct.pack("<I", objects.RESTORE_SIGNATURE)) == 0
    chain.cycle()
    assert float(mcu.ctrl[1].kp) == kp0


def test_force_gain_by_sdo_gives_the_response_the_model_predicts(cfg):
    """Box 0's Kp written by SDO; then a force step on both stack boxes through process
    data. Box 0's inputs equal a box built with that Kp in its calibration, bit for bit;
    box 2's equal the untouched calibration's; and the two differ."""
    kp = 0.5
    chain, c = _stack_chain(cfg)
    assert c.download(0x2000, 1, struct.pack("<f", kp)) == 0
    chain.cycle()
    tuned = make_box("stack", THREE.boxes[0], cfg.with_overrides({"mcu.kp_force": kp}, "kp"))
    plain = make_box("stack", THREE.boxes[0], cfg)
    for _ in range(chain.stats.cycles):  # as long idle (drives off) as the served box
        tuned.advance(20)
        plain.advance(20)
    rec = bytearray(chain.boxes[0].out_dtype.itemsize)
    struct.pack_into("<BBi", rec, 0, 1, 1, 30_000)   # slot 0: 300 N
    rows = {"sdo": [], "tuned": [], "plain": []}
    for box in (chain.boxes[0], tuned, plain):   # (the served box is one cycle ahead)
        box.apply(bytes(rec))
    for _ in range(60):
        for name, box in (("sdo", chain.boxes[0]), ("tuned", tuned), ("plain", plain)):
            box.apply(bytes(rec))
            box.advance(20)
            rows[name].append(struct.unpack_from("<h", box.inputs(), 6)[0])
    sdo, tuned_f, plain_f = (np.array(rows[k]) for k in ("sdo", "tuned", "plain"))
    assert np.array_equal(sdo, tuned_f)
    assert not np.array_equal(sdo, plain_f)


def test_a_new_master_after_init_is_served_from_its_first_counter(preop):
    """A master's session ends with INIT; the next one starts its counter at 1 again, which
    must not be taken for a repeat of the last request."""
    preop.coe(struct.pack("<BHB", 0x40, 0x1018, 1), counter=1)
    preop.m.set_state(STATION_BASE, r.AlState.INIT)
    preop.chain.cycle()
    c = Client(preop.chain)
    c.m.bring_up(to_op=False)
    ans = c.coe(struct.pack("<BHB", 0x40, 0x1018, 2), counter=1)
    assert struct.unpack_from("<I", ans, 6)[0] == preop.chain.escs[0].desc.product_code


def test_lvds_link_failure_and_driver_trip_send_their_emergencies(cfg):
    """The LVDS link to box 0's first driver board dead for 10 ms (a fault plan): the link
    failure, then the board's trip on its own watchdog, each one emergency, read from SM1."""
    from hil.fieldbus.faults import parse_faults
    from hil.fieldbus.stack_faults import install_box_faults

    chain = EscChain(THREE, cfg, "echo", stack_boxes=(0,))
    install_box_faults(chain, parse_faults({"fault": [
        {"link": "lvds.down", "kind": "dead", "box": 0, "slot": 0, "start_s": 0.05,
         "end_s": 0.06}]}, "test"))
    c = Client(chain)
    c.m.bring_up(to_op=False)
    rec = bytearray(chain.boxes[0].out_dtype.itemsize)
    struct.pack_into("<BBi", rec, 0, 1, 1, 20_000)
    seen = []
    for _ in range(80):
        chain.boxes[0].apply(bytes(rec))    # (as OP would hand it: the commands stay fresh)
        chain.cycle()
        d = c.m.one(ec.Command.FPRD, STATION_BASE, 0x1080, bytes(MBX))
        if d.wkc:
            head, code, register, slot = struct.unpack_from("<HHBB", d.data, 6)
            assert head >> 12 == coe.COE_EMERGENCY
            seen.append((code, register, slot))
    assert seen == [(coe.EMCY_LINK, coe.ERR_COMMUNICATION, 0),
                    (coe.EMCY_DRIVER_TRIP, coe.ERR_GENERIC, 0)]
