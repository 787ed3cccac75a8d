"""SOEM (through pysoem) over CoE against the served chain (hydra_full), over a veth pair in a
network namespace of the test's own (:mod:`hil.fieldbus.esc.veth`), tshark capturing the
master's side: identities by SDO, the process image from CoE equal to the SII's, a PDO
left out of an assignment in PREOP, aborts, emergencies after the watchdogs trip, and
tshark decoding the mailbox traffic as CoE. Needs root, ``ip``, ``tshark`` and pysoem."""

from __future__ import annotations

import signal
import struct
import subprocess

import numpy as np
import pytest

from firmware_model.esc import coe
from firmware_model.esc.objects import Abort
from firmware_model.mcu import mcu
from hil.fieldbus.boxes import make_box
from hil.fieldbus.esc.slaves import describe_all
from hil.fieldbus.esc.veth import MASTER_IF, in_ns, run_master, start_serve, stop_serve
from tests.fieldbus.test_ethercat_pysoem import netns  # noqa: F401  (the fixture)

pytestmark = pytest.mark.slow
REMAP_BOX = 3       # a three-actuator box: its first TxPDO is left out
CYCLES = 300


def _tshark(pcap, *args: str) -> str:
    return subprocess.run(["tshark", "-r", str(pcap), *args], capture_output=True, text=True,
                          check=True).stdout


def test_soem_over_coe_identity_remap_aborts_emergencies(netns, full, tmp_path):  # noqa: F811
    pcap = tmp_path / "coe.pcapng"
    shark = subprocess.Popen(in_ns(netns, "tshark", "-i", MASTER_IF, "-w", str(pcap), "-q"),
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        for line in shark.stderr:
            if "Capturing on" in line:
                break
        serve = start_serve(netns)
        try:
            res = run_master(netns, "coe", str(REMAP_BOX), str(CYCLES))
        finally:
            report = stop_serve(serve)
    finally:
        shark.send_signal(signal.SIGINT)
        shark.communicate(timeout=30)

    described = describe_all(full)
    # 0x1018 by SDO is the SII's identity on every box
    assert res["found"] == len(full.boxes)
    for ident, sii_ident, (d, _img) in zip(res["identity"], res["sii_identity"], described,
                                           strict=True):
        assert ident == [d.vendor_id, d.product_code, d.revision, d.serial]
        assert ident[:3] == sii_ident
    assert res["name"] == described[0][0].name
    # the first TxPDO left out in PREOP: a smaller image, the box sends the rest in order
    d = described[REMAP_BOX][0]
    assert res["assigned_before"] == [p.index for p in d.tx_pdos]
    assert res["assigned_after"] == [p.index for p in d.tx_pdos[1:]]
    assert res["image_bytes"] == 1552 - d.tx_pdos[0].bytes
    assert res["in_bytes"][REMAP_BOX] == d.in_bytes - d.tx_pdos[0].bytes
    assert (res["safeop"], res["op"], res["bad_wkc"]) == (4, 8, 0)
    rec = bytes.fromhex(res["inputs_last"])
    size = d.tx_pdos[0].bytes
    f_pressure = [struct.unpack_from("<h", rec, size * k + 6)[0] * 0.1
                  for k in range(len(d.tx_pdos) - 1)]
    # slots 1 and 2 (commanded 200 N and 300 N) now first; the echo lag has settled
    assert f_pressure == pytest.approx([200.0, 300.0], abs=2.0)
    # aborts with the standard's codes
    assert res["aborts"] == {"missing_object": Abort.NO_OBJECT,
                             "missing_subindex": Abort.NO_SUBINDEX,
                             "read_only": Abort.READ_ONLY, "gain_too_high": Abort.VALUE_HIGH}
    # after the stop: the commanded box's MCU watchdog trips on each actuator, read by SOEM
    emcy = sorted((e[1], e[2], e[3]) for e in res["emergencies"])
    assert emcy == [(coe.EMCY_MCU_WATCHDOG, coe.ERR_COMMUNICATION, k) for k in range(3)]
    assert {e[0] for e in res["emergencies"]} <= {REMAP_BOX, -1}
    assert report["mailbox"][REMAP_BOX]["emergencies"] == 3
    assert sum(s.get("emergencies", 0) for s in report["mailbox"]) == 3
    # tshark: the mailbox traffic decodes as CoE, nothing malformed
    protos = _tshark(pcap, "-T", "fields", "-e", "frame.protocols").split()
    coe_frames = [p for p in protos if "ecat_mailbox" in p]
    assert len(coe_frames) > 2 * len(full.boxes), sorted(set(protos))
    assert all(p.startswith("eth:ethertype:ecatf:ecat") for p in protos)
    assert _tshark(pcap, "-Y", "_ws.malformed").strip() == ""
    sdo_res = _tshark(pcap, "-Y", "ecat_mailbox.coe.type == 3", "-T", "fields", "-e",
                      "frame.number")
    emergencies = _tshark(pcap, "-Y", "ecat_mailbox.coe.type == 1", "-T", "fields", "-e",
                          "frame.number")
    assert sdo_res.split() and len(emergencies.split()) == 3
    assert _tshark(pcap, "-Y", "ecat_mailbox.invalid or ecat_mailbox.coe.invalid").strip() == ""


def test_config_map_from_coe_equals_the_sii_alone(netns):  # noqa: F811
    serve = start_serve(netns, "--no-coe")
    try:
        sii = run_master(netns, "cycles", "10", "0.0")
    finally:
        stop_serve(serve)
    serve = start_serve(netns)
    try:
        over_coe = run_master(netns, "coe", "-1", "10")
    finally:
        report = stop_serve(serve)
    assert sii["image_bytes"] == over_coe["image_bytes"] == 1552
    assert over_coe["bad_wkc"] == sii["bad_wkc"] == 0
    # over CoE the map came from the dictionaries: every slave was asked
    assert all(s.get("sdo_requests", 0) > 4 for s in report["mailbox"])


STEP_N, KP = 300.0, 0.5
#: Box cycles after the step compared with the prediction (it has settled by then), and the
#: largest miss [N] allowed at a sample's own box cycle: 5 % of the step, a sixth of what
#: one cycle changes in the steepest part of either rise (the whole-robot engine's C build
#: of the MCU law and the Python MCU differ by up to ~10 N there).
WINDOW, MISS_N = 30, 0.05 * STEP_N


def _rise_cycles(f: list[float], newtons: float) -> int:
    """Cycles from the first sample above 10 % of the step to the first above 80 %."""
    f = np.asarray(f)
    return int(np.argmax(f > 0.8 * newtons) - np.argmax(f > 0.1 * newtons))


def _predicted(box, cfg, n: int) -> list[float]:  # noqa: ANN001
    """The same protocol on a box model in this process: 200 cycles at 0 N, then the step."""
    rec = bytearray(box.out_dtype.itemsize)
    out = []
    for k in range(n):
        struct.pack_into("<BBi", rec, 0, 1, 1, 0 if k < 200 else round(STEP_N / 0.01))
        box.apply(bytes(rec))
        box.advance(20)
        out.append(struct.unpack_from("<h", box.inputs(), 6)[0] * 0.1)
    return out


def _misses(f: list[float], cycles: list[int], seen: int, predicted: list[float]
            ) -> list[float]:
    """The largest miss [N] of the served samples against the prediction at their own box
    cycles over the step's first WINDOW cycles, for each box cycle the box can have taken
    the step in. The step's frame brought back the record of box cycle ``seen``: the box
    took the step at the start of cycle ``seen + 1``, or of ``seen + 2`` if that one had
    started before the frame came (it takes the newest outputs as a cycle starts). On the
    box's cycles, not the master's: a box thread that fell behind and caught up back to
    back leaves gaps in the cycles the master sees, never a sample at the wrong cycle."""
    f, cycles = np.asarray(f), np.asarray(cycles, dtype=np.int64)
    out = []
    for onset in (seen + 1, seen + 2):
        j = cycles - onset      # step cycles the box ran before the one that made the record
        m = (j >= 0) & (j < WINDOW)
        assert m.any(), "no sample of the step's first cycles"
        out.append(float(np.abs(f[m] - np.asarray(predicted)[200 + j[m]]).max()))
    return out


SERVED = {"stack": ("--stack-box", "0", "--stack-box", "1"), "robot": ("--model", "robot")}
#: The MCUs' command watchdog for the gain test [s]: beyond any stall of the master. SOEM
#: runs at real-time priority and busy-polls for each reply, so on a loaded machine the
#: kernel's RT throttle (95 % of each second) stops it for ~50 ms now and then: no write
#: reaches the ESCs then, and the stock 10 ms would zero the force, rightly, on the
#: master's time. The gain is what is measured here; the watchdog has its own tests
#: (test_fresh_on_schedule.py, the coe test's emergencies, tests/mcu).
COMMAND_TIMEOUT = ("--set", "mcu.command_timeout_s=1.0")


@pytest.mark.parametrize("model", list(SERVED))
def test_force_gain_written_by_soem_changes_that_box_only(netns, full, cfg, model):  # noqa: F811
    """Box 0's Kp written by pysoem (0.5 instead of the calibration's 2): its force step
    rises as slowly as the box model with Kp 0.5 predicts; box 1 (same type, untouched)
    as fast as the calibration's; on the stack boxes (Python MCU) and on the whole-robot
    engine (the MCU law's C build). Judged on the boxes' own cycles (each input record
    stamped by the box's cycle counter), not on the master's: the two run on separate
    clocks. (The F5 bandwidth these gains give: docs.)"""
    serve = start_serve(netns, *SERVED[model], *COMMAND_TIMEOUT)
    try:
        res = run_master(netns, "gain", "0", "1", str(KP), str(STEP_N), "400")
    finally:
        stop_serve(serve)
    assert (res["kp_read"], res["kp_other"]) == (KP, cfg.get("mcu.kp_force"))
    assert (res["op"], res["bad_wkc"]) == (8, 0)
    # The boxes' MCUs had a fresh command every box cycle, on the master's time: a box
    # thread that fell behind and caught up back to back counts the writes that reached
    # the ESCs in each late cycle's millisecond (hil.fieldbus.box_clock), so a trip here
    # means SOEM wrote nothing for COMMAND_TIMEOUT.
    assert not any(st & (mcu.CMD_TIMEOUT | mcu.SAFE_OFF) for st in res["status_seen"]), \
        "an MCU command watchdog ran out: the master did not write for 1 s"
    tuned = _predicted(make_box(
        "stack", full.boxes[0], cfg.with_overrides({"mcu.kp_force": KP}, "kp")), cfg, 400)
    plain = _predicted(make_box("stack", full.boxes[0], cfg), cfg, 400)
    # the prediction tells them apart
    assert _rise_cycles(tuned, STEP_N) >= _rise_cycles(plain, STEP_N) + 4
    for f, cycles, seen, mine, other in zip(res["f_pressure"], res["box_cycle"],
                                            res["step_seen_cycle"], (tuned, plain),
                                            (plain, tuned), strict=True):
        # every sample is its own gain's prediction at its box cycle, for one of the two
        # possible onsets; the other gain's prediction misses at both
        assert min(_misses(f, cycles, seen, mine)) <= MISS_N
        assert min(_misses(f, cycles, seen, other)) > MISS_N
