"""Distributed clocks of the ESC model (:mod:`firmware_model.esc.dc`) against a master
doing what SOEM's config_dc, dcsync0 and cyclic drift compensation do
(:mod:`tests.fieldbus.dc_master`), on the readable chain: delays measured from the latched
port times, system times kept together by the time control loop, SYNC0 pulses, and the
answers to DC registers written out of order."""

from __future__ import annotations

import struct

import pytest

from firmware_model.esc import dc as fdc
from firmware_model.esc import registers as r
from firmware_model.esc.dc import dc_line
from hil.fieldbus.esc.chain import EscChain
from hil.fieldbus.esc.master import STATION_BASE, EscMaster
from protocols import ethercat as ec
from tests.fieldbus.dc_master import config_dc, dcsync0, frmw
from tests.fieldbus.test_esc import THREE


def _tick(chain: EscChain, dt: int) -> None:
    for e in chain.escs:
        e.tick(dt)


def _spread(chain: EscChain) -> int:
    """Largest difference of a slave's system time from slave 0's at the same instant."""
    now = chain.escs[0].now_ns
    ref = chain.escs[0].dc.system_ns(chain.escs[0].mem, now)
    return max(abs(e.dc.system_ns(e.mem, now) - ref) for e in chain.escs)


@pytest.fixture
def line(cfg, full):
    """hydra_full's 16 slaves in PREOP, clocks +-50 ppm, 500 ns per hop; 5 ms on."""
    chain = EscChain(full, cfg, "echo", dc=dc_line(len(full.boxes), 50.0, 500))
    master = EscMaster(chain)
    master.bring_up(to_op=False)
    _tick(chain, 5_000_000)
    return chain, master


def test_features_announce_64_bit_distributed_clocks(cfg):
    chain = EscChain(THREE, cfg, "echo")
    master = EscMaster(chain)
    d = master.one(ec.Command.BRD, 0, r.FEATURES, bytes(2))
    assert d.wkc == 3 and struct.unpack("<H", d.data)[0] & 0x0C == 0x0C


def test_config_dc_measures_the_simulated_propagation_delays(line):
    chain, master = line
    measured = config_dc(master, len(chain.escs))
    simulated = [e.dc.p.arrive_ns for e in chain.escs]
    assert simulated[-1] == 15 * 500
    assert all(abs(m - s) <= 2 for m, s in zip(measured, simulated, strict=True)), measured


def test_drift_compensation_keeps_the_system_times_within_100_ns(line):
    chain, master = line
    config_dc(master, len(chain.escs))
    assert _spread(chain) > 5_000   # the offsets leave each slave its delay behind
    seen = []
    # The spread falls under 100 ns after ~280 cycles; from cycle 500 on it has to stay there
    # (500 cycles of holding, 0.5 s: the +-50 ppm crystals part by 50 us in that time).
    for _ in range(1000):
        _tick(chain, 1_000_000)
        frmw(master)
        seen.append(_spread(chain))
    assert max(seen[500:]) < 100, max(seen[500:])
    # the master's view: every slave's filtered difference (0x092C) is small
    for i in range(len(chain.escs)):
        raw = struct.unpack("<I", master.one(ec.Command.FPRD, STATION_BASE + i,
                                             r.DC_SYSTEM_DIFF, bytes(4)).data)[0]
        assert raw & 0x7FFFFFFF < 100
    # one frame reading every slave's system time: the values agree
    dgs = [ec.Datagram(ec.Command.FPRD, i, STATION_BASE + i, r.DC_SYSTEM_TIME, bytes(8))
           for i in range(len(chain.escs))]
    times = [struct.unpack("<q", d.data)[0] for d in master.exchange(dgs)]
    assert max(times) - min(times) < 100


def test_the_loop_holds_the_rate_and_a_reset_lets_the_clocks_part(line):
    chain, master = line
    config_dc(master, len(chain.escs))
    for _ in range(800):  # settled after ~280 cycles
        frmw(master)
        _tick(chain, 1_000_000)
    assert _spread(chain) < 100
    _tick(chain, 100_000_000)   # no compare for 100 ms: the learnt rates hold
    assert _spread(chain) < 100
    d = master.one(ec.Command.BWR, 0, r.DC_SPEED_START, struct.pack("<H", 0x1000))
    assert d.wkc == len(chain.escs)   # resets every loop (as SOEM's start-up does)
    assert all(e.mem[r.DC_SYSTEM_DIFF:r.DC_SYSTEM_DIFF + 4] == bytes(4)
               and e.mem[r.DC_SPEED_DIFF:r.DC_SPEED_DIFF + 2] == bytes(2) for e in chain.escs)
    _tick(chain, 100_000_000)   # the crystals alone: 100 ppm apart -> 10 us in 100 ms
    assert _spread(chain) > 9_000


def test_sync0_pulses_at_the_start_time_and_every_cycle(line):
    chain, master = line
    config_dc(master, len(chain.escs))
    for _ in range(800):
        _tick(chain, 1_000_000)
        frmw(master)
    starts = {dcsync0(master, i, 1_000_000) for i in range(len(chain.escs))}
    assert len(starts) == 1   # the slaves agree on the time, so on the first pulse
    start = starts.pop()
    assert all(e.mem[r.DC_ACTIVATION_STATUS] & 1 for e in chain.escs)
    _tick(chain, 50_000)
    for e in chain.escs:
        w = e.dc.next_sync0
        assert e.dc.system_ns(e.mem, w) >= start > e.dc.system_ns(e.mem, w - 1)
    firsts = [e.dc.next_sync0 for e in chain.escs]
    assert max(firsts) - min(firsts) < 100
    for _ in range(150):   # past the start: one pulse per cycle
        _tick(chain, 1_000_000)
        frmw(master)
    e = chain.escs[3]
    w = e.dc.next_sync0
    p = e.dc.system_ns(e.mem, w)
    assert (p - start) % 1_000_000 == 0 and p > start
    # the next-pulse register reads the same pulse
    d = master.one(ec.Command.FPRD, STATION_BASE + 3, r.DC_START_TIME, bytes(8))
    assert struct.unpack("<q", d.data)[0] == p


def _activated(master: EscMaster, start_ahead_ns: int, act: int = 0x03) -> None:
    st = STATION_BASE
    master.one(ec.Command.FPWR, st, r.DC_ACTIVATION, b"\x00")
    t = struct.unpack("<q", master.one(ec.Command.FPRD, st, r.DC_SYSTEM_TIME, bytes(8)).data)[0]
    master.one(ec.Command.FPWR, st, r.DC_START_TIME, struct.pack("<q", t + start_ahead_ns))
    master.one(ec.Command.FPWR, st, r.DC_SYNC0_CYCLE, struct.pack("<I", 1_000_000))
    master.one(ec.Command.FPWR, st, r.DC_ACTIVATION, bytes([act]))


OUT_OF_ORDER = [
    # (what, steps, error code, errors counted, SYNC0 running afterwards, activation status)
    ("start time while active", "restart", fdc.ERR_START_WHILE_ACTIVE, 1, True, 0x01),
    ("cycle while active", "recycle", fdc.ERR_CYCLE_WHILE_ACTIVE, 1, True, 0x01),
    ("start time in the past", "past", fdc.ERR_START_IN_PAST, 1, False, 0x00),
    ("past, plausibility check on", "past-check", 0, 0, True, 0x05),
    # both activation writes (off, then on) refused
    ("sync unit given to the PDI", "pdi", fdc.ERR_PDI_OWNS_SYNC, 2, False, 0x00),
]


@pytest.mark.parametrize("what,steps,code,count,running,status", OUT_OF_ORDER,
                         ids=[o[0] for o in OUT_OF_ORDER])
def test_dc_registers_written_out_of_order(cfg, what, steps, code, count, running, status):
    chain = EscChain(THREE, cfg, "echo")
    master = EscMaster(chain)
    master.bring_up(to_op=False)
    _tick(chain, 1_000_000)
    esc = chain.escs[0]
    if steps == "pdi":
        master.one(ec.Command.FPWR, STATION_BASE, r.DC_CYCLIC_CONTROL, b"\x01")
    if steps in ("past", "past-check"):
        _activated(master, -5_000, 0x23 if steps == "past-check" else 0x03)
    else:
        _activated(master, 100_000_000)
    kept = bytes(esc.mem[r.DC_START_TIME:r.DC_SYNC0_CYCLE + 4])
    if steps == "restart":
        d = master.one(ec.Command.FPWR, STATION_BASE, r.DC_START_TIME, struct.pack("<q", 1))
        assert d.wkc == 1   # the datagram is answered; the value is not taken
    if steps == "recycle":
        master.one(ec.Command.FPWR, STATION_BASE, r.DC_SYNC0_CYCLE, struct.pack("<I", 7))
    if steps in ("restart", "recycle"):
        assert esc.dc.sync_start == struct.unpack_from("<q", kept, 0)[0]
        assert esc.dc.sync_cycle == 1_000_000
    assert esc.dc.errors == count and esc.dc.last_error == code
    assert (esc.dc.sync_state == fdc.SYNC_RUNNING) == running
    assert esc.mem[r.DC_ACTIVATION_STATUS] == status
    _tick(chain, 2_000_000)
    assert (esc.dc.next_sync0 >= 0) == running
    # the others were not touched
    assert all(e.dc.errors == 0 and e.dc.sync_state == fdc.SYNC_OFF for e in chain.escs[1:])


def test_esi_offers_free_run_and_dc_synchronous_and_they_work(cfg, full):
    """The ESI's DC operation modes: a master writes AssignActivate to 0x0980 as a word
    (low byte cyclic unit control, high byte activation) after start time and cycle:
    DcSync starts SYNC0 on the model, FreeRun leaves it off."""
    import xml.etree.ElementTree as ET

    from hil.fieldbus.esc.esi import esi_xml

    root = ET.fromstring(esi_xml(full))
    for dev in root.iter("Device"):
        modes = {op.find("Name").text: op for op in dev.findall("Dc/OpMode")}
        assert set(modes) == {"FreeRun", "DcSync"}
        assert modes["DcSync"].find("CycleTimeSync0").get("Factor") == "1"
    for name, running in (("FreeRun", False), ("DcSync", True)):
        assign = int(modes[name].find("AssignActivate").text[2:], 16)
        chain = EscChain(THREE, cfg, "echo")
        master = EscMaster(chain)
        master.bring_up(to_op=False)
        t = struct.unpack("<q", master.one(ec.Command.FPRD, STATION_BASE, r.DC_SYSTEM_TIME,
                                           bytes(8)).data)[0]
        master.one(ec.Command.FPWR, STATION_BASE, r.DC_START_TIME,
                   struct.pack("<q", t + 100_000_000))
        master.one(ec.Command.FPWR, STATION_BASE, r.DC_SYNC0_CYCLE,
                   struct.pack("<I", 1_000_000))
        master.one(ec.Command.FPWR, STATION_BASE, r.DC_CYCLIC_CONTROL,
                   struct.pack("<H", assign))
        esc = chain.escs[0]
        assert (esc.dc.sync_state == fdc.SYNC_RUNNING) == running and esc.dc.errors == 0


@pytest.mark.parametrize("argv, says", [
    (["--dc-drift-ppm", "1,2"], "--dc-drift-ppm: 2 drifts for 16 slaves (hydra_full)"),
    (["--dc-drift-ppm", "600"], "each drift must be within +-500 ppm"),
    (["--dc-drift-ppm", "fast"], "'fast' is not a number"),
    (["--dc-hop-ns", "-1"], "--dc-hop-ns: -1: need an integer in 0..100000 ns"),
])
def test_serve_dc_options_mistakes_are_one_line(capsys, argv, says):
    from hil.cli import main

    try:
        code = main(["serve", "--transport", "ethercat", "--topology", "hydra_full",
                     "--interface", "nosuch0", *argv])
    except SystemExit as exc:   # argparse's own checks
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and says in err and len(err.splitlines()) == 1, err
