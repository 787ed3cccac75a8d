"""The pcap tap: 20 cycles of the full robot, decoded by Wireshark's EtherCAT dissector."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from hil.fieldbus.capture import PcapTap
from hil.fieldbus.system import BusSystem
from protocols import ethercat as ec
from protocols.pcap import read_pcap

from .conftest import full_robot_pc

CYCLES = 20


@pytest.fixture(scope="module")
def capture(cfg, full, tmp_path_factory):
    tap = PcapTap(tick_ns=cfg.get("sim.tick_ns"))
    with BusSystem(full, cfg, "inproc", model="echo", tap=tap) as bs:
        rec = bs.run(CYCLES, full_robot_pc)
        plan = bs.master.plan
    path = tmp_path_factory.mktemp("cap") / "bus.pcap"
    tap.write(path)
    return path, plan, rec


def test_pcap_records(capture):
    path, plan, _ = capture
    cap = read_pcap(path)
    n = len(plan.frames)
    assert len(cap.records) == 2 * n * CYCLES
    for i, r in enumerate(cap.records):
        cycle = i // (2 * n)
        assert r.ts_ns == cycle * 20 * 50_000  # simulated time: tick * 50 us
        (d,) = ec.decode_frame(r.data)
        _, length, wkc = next(f for f in plan.frames if f[0] == d.lad)
        assert d.cmd == ec.Command.LRW and d.idx == cycle & 0xFF and len(d.data) == length
        tx = (i % (2 * n)) < n  # the master sends all frames, then reads the replies
        assert d.wkc == (0 if tx else wkc)


def test_tshark_reads_working_counters(capture, tmp_path):
    tshark = shutil.which("tshark")
    if tshark is None:
        pytest.skip("tshark not installed: apt-get install -y --no-install-recommends tshark "
                    "(.ci/run does this)")
    path, plan, rec = capture
    env = dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path))
    proc = subprocess.run([tshark, "-n", "-r", str(path), "-T", "fields", "-E",
                           "separator=\t", "-e", "ecat.cmd", "-e", "ecat.idx", "-e",
                           "ecat.lad", "-e", "ecat.cnt", "-e", "_ws.malformed"],
                          capture_output=True, text=True, timeout=120, env=env, check=False)
    assert proc.returncode == 0, proc.stderr
    rows = [line.split("\t") for line in proc.stdout.splitlines() if line.strip()]
    n = len(plan.frames)
    assert len(rows) == 2 * n * CYCLES
    expected = {lad: wkc for lad, _, wkc in plan.frames}
    replies = 0
    for i, (cmd, idx, lad, cnt, *malformed) in enumerate(rows):
        assert int(cmd, 0) == ec.Command.LRW
        assert int(idx, 0) == (i // (2 * n)) & 0xFF
        assert not any(malformed)
        if (i % (2 * n)) >= n:  # a reply
            assert int(cnt, 0) == expected[int(lad, 0)]
            replies += 1
        else:
            assert int(cnt, 0) == 0
    assert replies == rec.master["frames_ok"] == n * CYCLES


def test_bench_smoke():
    from hil.bench.bus import bench_bus, format_table

    res = bench_bus(("inproc",), cycles=20, stack_cycles=20)
    assert set(res) == {"inproc", "stack_rtf"} and all(v > 0 for v in res.values())
    assert "hydra_full" in format_table(res)
