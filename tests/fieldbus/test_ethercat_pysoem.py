"""SOEM (through pysoem) against the ESC chain over a veth pair in a network namespace of
the test's own, with tshark capturing the master's side.

Needs root, ``ip``, ``tshark`` and pysoem; skipped with the reason otherwise. The
namespace (and with it the veth pair) is created for each test and deleted at its end
(:mod:`hil.fieldbus.esc.veth`); the master is :mod:`hil.fieldbus.esc.soem_master`.
"""

from __future__ import annotations

import shutil
import signal
import struct
import subprocess
from collections import Counter

import pytest

from hil.fieldbus.boxes import make_box
from hil.fieldbus.esc.slaves import describe_all
from hil.fieldbus.esc.veth import (
    MASTER_IF,
    NamespaceError,
    in_ns,
    run_master,
    start_serve,
    stop_serve,
    veth_namespace,
)
from hil.fieldbus.pdo import slot_sizes
from hil.fieldbus.traffic import read_capture, summary

CYCLES = 3_000
FORCE_N = 450.0
SOEM_SOURCE_MAC_NOTE = "Source MAC must not be a group address: IEEE 802.3-2002, Section 3.2.3(b)"

pytestmark = pytest.mark.slow


@pytest.fixture
def netns():
    if shutil.which("tshark") is None:
        pytest.skip("needs `tshark` (make system-deps)")
    try:
        import pysoem  # noqa: F401
    except ImportError:
        pytest.skip("needs pysoem (pip install -e .[test])")
    try:
        with veth_namespace() as name:
            yield name
    except NamespaceError as exc:
        pytest.skip(str(exc))


def test_soem_brings_hydra_full_to_op_and_cycles(netns, full, tmp_path):
    pcap = tmp_path / "master_side.pcapng"
    shark = subprocess.Popen(in_ns(netns, "tshark", "-i", MASTER_IF, "-w", str(pcap), "-q"),
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        for line in shark.stderr:  # capture running before the first frame
            if "Capturing on" in line:
                break
        serve = start_serve(netns)
        try:
            res = run_master(netns, "cycles", str(CYCLES), "0.5")
        finally:
            report = stop_serve(serve)
    finally:
        shark.send_signal(signal.SIGINT)
        shark.communicate(timeout=30)

    described = describe_all(full)
    # config_init: every box, with the identity and name of its SII
    assert res["found"] == len(full.boxes)
    for s, (d, _img) in zip(res["slaves"], described, strict=True):
        assert (s["man"], s["id"], s["rev"], s["name"]) == (
            d.vendor_id, d.product_code, d.revision, d.name)
    # config_map: the image the docs state is the sum of the boxes' records
    per_box = sum(slot_sizes(sl.kind)[0] + slot_sizes(sl.kind)[1]
                  for b in full.boxes for sl in b.slots)
    assert res["image_bytes"] == per_box == 1552
    assert res["safeop"] == 4 and res["op"] == 8 and set(res["states"]) == {8}
    # every cycle's WKC is SOEM's expectation: 2 per slave with outputs, 1 with inputs
    with_out = sum(1 for b in full.boxes if b.out_bytes)
    assert res["expected_wkc"] == 2 * with_out + len(full.boxes)
    assert res["bad_wkc"] == 0, res["bad_wkc_values"]
    # stopped: every slave with outputs tripped its watchdog -> SAFEOP + error, 0x001B
    for s, box, slave in zip(res["after_stop"], full.boxes, report["slaves"], strict=True):
        if box.out_bytes:
            assert (s["state"], s["al_status"]) == (0x14, 0x001B)
            assert slave["trips"] == 1
            # within the stated time (+ one 1 ms cycle of the slave's clock)
            assert slave["watchdog_ms"] <= slave["last_trip_after_ms"] <= \
                slave["watchdog_ms"] + 1.0
        else:
            assert s["state"] == 8 and slave["trips"] == 0
    assert report["dropped_frames"] == 0

    # tshark, one pass over the capture (a field per column, a frame per line): every frame
    # is EtherCAT, none malformed or with expert info
    fields = ("frame.protocols", "_ws.malformed", "_ws.expert.message", "eth.src", "ecat.cnt")
    out = subprocess.run(["tshark", "-r", str(pcap), "-T", "fields", "-E", "aggregator=|",
                          *(a for f in fields for a in ("-e", f))],
                         capture_output=True, text=True, check=True)
    rows = [line.split("\t") for line in out.stdout.splitlines()]
    assert all(len(r) == len(fields) for r in rows)
    assert len(rows) >= 2 * CYCLES
    protos = {r[0] for r in rows}
    assert all(p.startswith("eth:ethertype:ecatf:ecat") for p in protos), sorted(protos)[:5]
    assert not [r for r in rows if r[1]], "malformed frames"
    # Expert info: only Ethernet's note on SOEM's own source MAC 01:01:01:01:01:01 (a group
    # address, SOEM's default), which the slaves hand back with bit 1 set as an ESC does.
    messages = {m for r in rows for m in r[2].split("|") if m}
    assert messages <= {SOEM_SOURCE_MAC_NOTE}, messages
    # log info tells requests from replies in this foreign capture as tshark does by the
    # source MAC's bit 1 (of its first octet, as tshark prints the address), and counts
    # the replies' working counters as tshark reads them
    s = summary(read_capture(pcap))
    counts = {"requests": [], "replies": []}
    for r in rows:
        counts["replies" if int(r[3][:2], 16) & 2 else "requests"].append(r[4])
    assert (s["requests"], s["replies"]) == (len(counts["requests"]), len(counts["replies"]))
    assert s["replies"] > 0
    assert s["reply_wkc"] == dict(Counter(w for line in counts["replies"]
                                          for w in line.split("|")))


def test_soem_force_command_reaches_the_full_stack(netns, full, cfg):
    serve = start_serve(netns, "--stack-box", "0")
    try:
        res = run_master(netns, "force", "0", "0", str(FORCE_N), "1500")
    finally:
        stop_serve(serve)
    # Bring-up first: a slave left behind (SII misread, SAFEOP refused) shows later only as
    # a short working counter on every cycle.
    assert (res["found"], res["image_bytes"], res["safeop"], res["op"]) == (16, 1552, 4, 8)
    assert set(res["states"]) == {8}
    assert res["bad_wkc"] == 0, res["bad_wkc_values"]
    # The same box model in this process, given the same output record, predicts the
    # pressure force the inputs carry once it has settled.
    box = make_box("stack", full.boxes[0], cfg)
    rec = bytearray(full.boxes[0].out_bytes)
    struct.pack_into("<BBi", rec, 0, 1, 1, round(FORCE_N / 0.01))
    predicted = []
    for k in range(400):
        box.apply(bytes(rec))
        box.advance(20)
        if k >= 300:
            predicted.append(struct.unpack_from("<h", box.inputs(), 6)[0] * 0.1)
    served = res["f_pressure"][-300:]
    mean = sum(predicted) / len(predicted)
    assert abs(sum(served) / len(served) - mean) < 0.01 * FORCE_N
    assert max(abs(f - mean) for f in served) < max(abs(f - mean) for f in predicted) + 3.0
