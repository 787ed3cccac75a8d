"""The ESC slave chain in this process: working-counter rules, addressing, the AL state
machine's refusals, dropped frames, the watchdog, the ESI against the SII served."""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.esc import registers as r
from firmware_model.esc import sii
from firmware_model.mcu.mcu import CommandMode
from hil.fieldbus.esc.chain import EscChain
from hil.fieldbus.esc.esi import esi_xml
from hil.fieldbus.esc.master import EscMaster
from hil.fieldbus.topology import parse_topology
from protocols import ethercat as ec

THREE = parse_topology("""
[[box]]
slots = ["a", "b"]
[[box]]
slots = [{ name = "imu", kind = "imu" }]
[[box]]
slots = ["c", { name = "foot", kind = "foot_sensor" }]
""", "three boxes")


@pytest.fixture
def chain(cfg):
    return EscChain(THREE, cfg, "echo")


def _one(chain, cmd, adp, ado, data, wkc=0) -> ec.Datagram:
    reply = chain.handle(ec.encode_frame([ec.Datagram(cmd, 7, adp, ado, data, wkc)]))
    return ec.decode_frame(reply)[0]


@pytest.mark.parametrize("cmd", [ec.Command.BRD, ec.Command.BWR, ec.Command.BRW])
def test_broadcast_wkc_is_the_rule_per_slave(chain, cmd):
    d = _one(chain, cmd, 0, r.IRQ_MASK, bytes(2))
    assert d.wkc == ec.expected_wkc(cmd, len(THREE.boxes))
    assert d.adp == len(THREE.boxes)  # every slave incremented the position


@given(pos=st.integers(0, 2), cmd=st.sampled_from([ec.Command.APRD, ec.Command.APWR,
                                                  ec.Command.APRW]),
       wkc0=st.integers(0, 100))
@settings(max_examples=30, deadline=None)
def test_position_addressing_reaches_one_slave(cfg, pos, cmd, wkc0):
    chain = EscChain(THREE, cfg, "echo")
    value = struct.pack("<H", 0x1234 + pos)
    d = _one(chain, cmd, (-pos) & 0xFFFF, r.STATION_ADDRESS, value, wkc0)
    assert d.wkc == wkc0 + ec.expected_wkc(cmd, 1)
    for k, esc in enumerate(chain.escs):
        got = struct.unpack_from("<H", esc.mem, r.STATION_ADDRESS)[0]
        assert got == (0x1234 + pos if k == pos and cmd != ec.Command.APRD else 0)


def test_broadcast_read_ors_the_slaves(chain):
    # Stations 1, 2, 4: a BRD of the station address returns their OR.
    for k in range(3):
        _one(chain, ec.Command.APWR, (-k) & 0xFFFF, r.STATION_ADDRESS,
             struct.pack("<H", 1 << k))
    d = _one(chain, ec.Command.BRD, 0, r.STATION_ADDRESS, bytes(2))
    assert struct.unpack("<H", d.data)[0] == 0b111 and d.wkc == 3


def test_armw_reads_at_the_addressed_slave_and_writes_the_others(chain):
    chain.escs[1].mem[r.IRQ_MASK] = 0x5A  # the shared value
    d = _one(chain, ec.Command.ARMW, (-1) & 0xFFFF, r.IRQ_MASK, b"\x00")
    assert d.data == b"\x5a" and d.wkc == 3
    # slave 0 saw the master's byte, slave 2 the one read from slave 1
    assert [e.mem[r.IRQ_MASK] for e in chain.escs] == [0x00, 0x5A, 0x5A]


@pytest.mark.parametrize("cmd", [ec.Command.FPRD, ec.Command.FPWR, ec.Command.FPRW,
                                 ec.Command.APRD])
def test_datagram_to_nobody_leaves_wkc_and_data(chain, cmd):
    adp = 0x7777 if cmd != ec.Command.APRD else (-5) & 0xFFFF  # no 6th slave
    d = _one(chain, cmd, adp, r.AL_STATUS, b"\xab\xcd", wkc=9)
    assert (d.wkc, d.data) == (9, b"\xab\xcd")


def test_logical_access_outside_every_fmmu_leaves_wkc(cfg):
    chain = EscChain(THREE, cfg, "echo")
    m = EscMaster(chain)
    m.bring_up()
    end = len(m.image)
    d = m.exchange([ec.Datagram.logical(ec.Command.LRW, end + 100, b"\x01" * 8, wkc=4)])[0]
    assert (d.wkc, d.data) == (4, b"\x01" * 8)


def test_lrw_wkc_counts_outputs_twice_and_inputs_once(cfg):
    chain = EscChain(THREE, cfg, "echo")
    m = EscMaster(chain)
    m.bring_up()
    with_out = sum(1 for b in THREE.boxes if b.out_bytes)
    assert m.cycle() == 2 * with_out + len(THREE.boxes)


def _al(chain, k):
    e = chain.escs[k]
    return struct.unpack_from("<H", e.mem, r.AL_STATUS)[0], struct.unpack_from(
        "<H", e.mem, r.AL_STATUS_CODE)[0]


def test_refused_transitions_set_the_error_bit_and_code(chain):
    # INIT -> OP skips states: refused, INIT + error, 0x0011
    _one(chain, ec.Command.APWR, 0, r.AL_CONTROL, struct.pack("<H", r.AlState.OP))
    assert _al(chain, 0) == (r.AlState.INIT | r.AL_ERROR, r.AlStatusCode.INVALID_STATE_CHANGE)
    # acknowledged, PREOP without the mailbox sync managers: refused, 0x0016
    _one(chain, ec.Command.APWR, 0, r.AL_CONTROL, struct.pack("<H", 0x12))
    assert _al(chain, 0) == (r.AlState.INIT | r.AL_ERROR,
                             r.AlStatusCode.INVALID_MAILBOX_CONFIG)
    # with SM0/SM1 as the SII's mailboxes, PREOP; then SAFEOP without the process data's
    # sync managers: 0x001D
    for k in range(3):
        syncm = sii.categories(chain.escs[k].sii)[sii.CAT_SYNCM]
        _one(chain, ec.Command.APWR, (-k) & 0xFFFF, r.SM0, syncm[:16])
    _one(chain, ec.Command.APWR, 0, r.AL_CONTROL, struct.pack("<H", 0x12))
    assert _al(chain, 0) == (r.AlState.PREOP, 0)
    _one(chain, ec.Command.APWR, 0, r.AL_CONTROL, struct.pack("<H", r.AlState.SAFEOP))
    assert _al(chain, 0) == (r.AlState.PREOP | r.AL_ERROR,
                             r.AlStatusCode.INVALID_OUTPUT_CONFIG)
    # the IMU box has inputs only: its input sync manager is what is missing
    for cmd in (0x12, r.AlState.SAFEOP):
        _one(chain, ec.Command.APWR, (-1) & 0xFFFF, r.AL_CONTROL, struct.pack("<H", cmd))
    assert _al(chain, 1) == (r.AlState.PREOP | r.AL_ERROR,
                             r.AlStatusCode.INVALID_INPUT_CONFIG)
    # bootstrap is not supported
    _one(chain, ec.Command.APWR, (-2) & 0xFFFF, r.AL_CONTROL, struct.pack("<H", 0x13))
    assert _al(chain, 2) == (r.AlState.INIT | r.AL_ERROR,
                             r.AlStatusCode.BOOTSTRAP_NOT_SUPPORTED)


def test_truncated_frame_is_dropped_and_counted(chain):
    frame = ec.encode_frame([ec.Datagram(ec.Command.BRD, 0, 0, r.TYPE, bytes(40))])
    cut = frame[:ec.ETH_HEADER_LEN + 30]  # the EtherCAT length says more than there is
    assert chain.handle(cut) is None
    assert chain.stats.dropped_frames == 1 and chain.stats.frames == 0
    assert chain.handle(frame) is not None and chain.stats.frames == 1


def test_sii_read_through_the_eeprom_interface_is_the_image(chain):
    m = EscMaster(chain)
    _one(chain, ec.Command.APWR, 0, r.STATION_ADDRESS, struct.pack("<H", 0x1001))
    image = m._read_sii(0x1001)
    assert image[:len(chain.escs[0].sii)] == chain.escs[0].sii
    assert sii.strings(image)[0] == chain.escs[0].desc.name


def test_watchdog_trips_after_its_register_time_and_outputs_go_safe(cfg):
    chain = EscChain(THREE, cfg, "echo")
    m = EscMaster(chain)
    m.bring_up()
    o = m.slaves[0].out_lad
    struct.pack_into("<BBi", m.image, o, 1, 1, 30000)  # 300 N, enabled
    for _ in range(5):
        chain.cycle()
        m.cycle()  # the last output write: the watchdog counts from here
    echo = chain.boxes[0].model
    assert echo.enabled[0] and echo.cmd[0][0] == CommandMode.FORCE
    div, t_wd = (struct.unpack("<H", m.one(ec.Command.FPRD, 0x1001, a, bytes(2)).data)[0]
                 for a in (r.WD_DIVIDER, r.WD_TIME_PD))
    wd_cycles = (div + 2) * 40 * t_wd / 1e6  # [ms] = bus cycles
    n = 0  # bus cycles (1 ms) without outputs until the trip
    while _al(chain, 0)[0] == r.AlState.OP:
        chain.cycle()
        n += 1
    assert n == wd_cycles
    assert _al(chain, 0) == (r.AlState.SAFEOP | r.AL_ERROR, r.AlStatusCode.SM_WATCHDOG)
    assert not echo.enabled[0] and echo.cmd[0][0] == CommandMode.OFF  # safe outputs
    assert _al(chain, 1)[0] == r.AlState.OP  # the IMU box has no outputs to watch


def test_esi_matches_the_sii_the_chain_serves(cfg, full):
    root = ET.fromstring(esi_xml(full))
    vendor = int(root.find("Vendor/Id").text[2:], 16)
    devices = {int(d.find("Type").get("ProductCode")[2:], 16): d
               for d in root.iter("Device")}
    chain = EscChain(full, cfg, "echo")
    for esc in chain.escs:
        man, product, rev, _serial = sii.identity(esc.sii)
        assert man == vendor
        dev = devices[product]
        assert int(dev.find("Type").get("RevisionNo")[2:], 16) == rev
        assert dev.find("Name").text == sii.strings(esc.sii)[0]
        syncm = sii.categories(esc.sii)[sii.CAT_SYNCM]
        for k, sm in enumerate(dev.findall("Sm")):
            start, length, control = struct.unpack_from("<HHB", syncm, 8 * k)
            assert (int(sm.get("StartAddress")[2:], 16), int(sm.get("DefaultSize")),
                    int(sm.get("ControlByte")[2:], 16)) == (start, length, control)
        for tag, cat in (("RxPdo", sii.CAT_RXPDO), ("TxPdo", sii.CAT_TXPDO)):
            # the default image: the PDOs assigned to a sync manager (those without Sm may
            # be assigned by a master over CoE)
            bits = sum(int(e.text) for p in dev.findall(tag) if p.get("Sm") is not None
                       for e in p.iter("BitLen"))
            assert bits == sii.pdo_bits(esc.sii, cat)


@pytest.mark.parametrize("argv, says", [
    (["--interface", "nosuch0"], "--interface nosuch0: no such network interface"),
    ([], "--interface: required with --transport ethercat"),
    (["--interface", "lo", "--stack-box", "16"], "--stack-box 16: hydra_full has boxes 0..15"),
    (["--interface", "lo", "--capture", "x.pcapng"], "--capture: not with --transport ethercat"),
])
def test_serve_ethercat_mistakes_are_one_line(capsys, argv, says):
    from hil.cli import main

    code = main(["serve", "--transport", "ethercat", "--topology", "hydra_full", *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2 and says in err and len(err.splitlines()) == 1, err


def test_esi_dictionary_is_the_dictionary_the_boxes_serve(cfg, full):
    """Every Device's Dictionary lists the objects its boxes answer over CoE, with the
    identity's values, the assignments' PREOP write restriction and the tunables' ranges."""
    from firmware_model.mcu.tunables import TUNABLES

    root = ET.fromstring(esi_xml(full, cfg))
    devices = {int(d.find("Type").get("ProductCode")[2:], 16): d for d in root.iter("Device")}
    chain = EscChain(full, cfg, "echo")
    for esc, mb in zip(chain.escs, chain.mailboxes.each, strict=True):
        dev = devices[esc.desc.product_code]
        assert dev.find("Mailbox/CoE").get("CompleteAccess") == "1"
        objs = {int(o.find("Index").text[2:], 16): o
                for o in dev.findall("Profile/Dictionary/Objects/Object")}
        assert sorted(objs) == sorted(mb.od.objects)
        ident = [si.find("Info/DefaultData").text for si in objs[0x1018].findall("Info/SubItem")]
        assert [int.from_bytes(bytes.fromhex(v), "little") for v in ident[1:]][:3] == [
            esc.desc.vendor_id, esc.desc.product_code, esc.desc.revision]
        dt = {d.find("Name").text: d for d in dev.findall("Profile/Dictionary/DataTypes/DataType")}
        access = dt["DT1C13"].findall("SubItem/Flags/Access")
        assert {(a.text, a.get("WriteRestrictions")) for a in access} == {("rw", "PREOP")}
        for p, t in enumerate(TUNABLES):
            if 0x2000 + p not in mb.od.objects:
                continue
            sub = objs[0x2000 + p].findall("Info/SubItem")[1]
            assert (float(sub.find("Info/MinValue").text), float(sub.find("Info/MaxValue").text),
                    sub.find("Info/Unit").text) == (t.low, t.high, t.unit)
