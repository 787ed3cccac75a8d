"""``bus run --transport can --can-log``: the CAN traffic of a run in python-can's file
formats, read back by python-can's own ``can.LogReader`` (not our code) segment by segment,
then summarised (``log info``) and replayed (``replay``) by the project."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import uuid
import zlib
from pathlib import Path

import can
import pytest

from hil.cli import main
from hil.fieldbus.traffic import read_traffic
from hil.transports.canbus import segment

ROOT = Path(__file__).resolve().parents[2]
CYCLES = 10


def _expected_segments(capture: Path) -> dict[int, list[bytes]]:
    """The data field of every CAN segment the run must have sent, per CAN ID, built from
    the run's capture (each PDU + its CRC-32 trailer, cut as the can transport cuts)."""
    out: dict[int, list[bytes]] = {0x100: [], 0x101: []}
    messages = {0x100: 0, 0x101: 0}  # the message sequence number counts per sender
    for f in read_traffic(capture).frames:
        can_id = 0x100 if f.direction == "tx" else 0x101
        frame = f.pdu + (zlib.crc32(f.pdu) & 0xFFFFFFFF).to_bytes(4, "little")
        out[can_id] += segment(frame, messages[can_id] % 32, fd=True)
        messages[can_id] += 1
    return out


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_can_log_reads_back_every_segment(tmp_path, suffix, capsys):
    log, cap = tmp_path / f"run{suffix}", tmp_path / "run.pcap"
    assert main(["bus", "run", "--transport", "can", "--topology", "hydra_full", "--seconds",
                 str(CYCLES / 1000), "--can-log", str(log), "--capture", str(cap),
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    expected = _expected_segments(cap)
    n = sum(len(v) for v in expected.values())
    assert out["can_messages"] == n
    # per cycle and direction a 1392-byte and a 160-byte window: 23 + 3 CAN-FD segments
    assert n == 2 * CYCLES * (23 + 3)
    messages = list(can.LogReader(str(log)))
    assert len(messages) == n
    for can_id, segments in expected.items():
        got = [m for m in messages if m.arbitration_id == can_id]
        assert [bytes(m.data) for m in got] == segments
        assert all(m.is_fd and m.bitrate_switch and not m.is_extended_id for m in got)

    assert main(["log", "info", str(log), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["requests"], info["replies"], info["malformed"]) == (20, 20, 0)
    assert info["crc_trailers"] == 40 and info["can_reassembly_errors"] == {}
    assert main(["replay", str(log), "--topology", "hydra_full"]) == 0
    assert "20 replies of hydra_full (echo model) match bit for bit" in capsys.readouterr().out


def test_can_log_usage_errors_are_one_line(tmp_path, capsys):
    assert main(["bus", "run", "--can-log", str(tmp_path / "x.blf")]) == 2
    assert "CAN logs need the can transport" in capsys.readouterr().err
    assert main(["bus", "run", "--can-channel", "x"]) == 2
    assert "--can-channel: only with --transport can" in capsys.readouterr().err
    (tmp_path / "bad.blf").write_bytes(b"\x00" * 200)
    assert main(["log", "info", str(tmp_path / "bad.blf")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a readable CAN log" in err


def test_socketcan_in_a_private_namespace(tmp_path):
    """``--can-interface socketcan``: a vcan device made in a namespace of this test."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("needs root and iproute2 for a network namespace with a vcan device")
    ns = f"eha-hil-test-{uuid.uuid4().hex[:8]}"
    if subprocess.run(["ip", "netns", "add", ns], capture_output=True, check=False).returncode:
        pytest.skip("cannot create a network namespace")
    try:
        made = subprocess.run(["ip", "netns", "exec", ns, "sh", "-c",
                               "ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 up"],
                              capture_output=True, text=True, check=False)
        if made.returncode:
            pytest.skip(f"no vcan device possible here (kernel module vcan?): "
                        f"{made.stderr.strip()}")
        log = tmp_path / "vcan.asc"
        run = subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-m", "hil.cli", "bus",
                              "run", "--transport", "can", "--can-interface", "socketcan",
                              "--can-channel", "vcan0", "--seconds", "0.02", "--can-log",
                              str(log)], capture_output=True, text=True, timeout=300,
                             env=dict(os.environ, PYTHONPATH=str(ROOT)), check=False)
        if "Address family not supported" in run.stderr:
            pytest.skip("the kernel has no SocketCAN (AF_CAN) support")
        assert run.returncode == 0, run.stderr
        t = read_traffic(log)
        assert sum(f.direction == "tx" for f in t.frames) == 20
        assert sum(f.direction == "rx" for f in t.frames) == 20
    finally:
        subprocess.run(["ip", "netns", "del", ns], check=False)


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_a_channel_name_ending_in_a_large_number_is_logged(tmp_path, suffix):
    """The virtual bus's private channel names are random: one ending in digits that do not
    fit BLF's 16-bit channel number must still be logged (the file is one cable)."""
    from hil.transports.canlog import CanLogRecorder, read_can_log

    channel = f"eha-hil-test-{uuid.uuid4().hex[:4]}99999"
    path = tmp_path / f"one{suffix}"
    with can.Bus(interface="virtual", channel=channel, fd=True) as bus:
        rec = CanLogRecorder(path, "virtual", channel)
        bus.send(can.Message(arbitration_id=0x123, data=bytes(range(12)), is_fd=True,
                             is_extended_id=False))
        rec.close()
    msgs = read_can_log(path)
    assert [(m.arbitration_id, bytes(m.data)) for m in msgs] == [(0x123, bytes(range(12)))]


def test_can_log_carries_its_topology_and_replay_refuses_without(tmp_path, capsys):
    log = tmp_path / "run.asc"
    assert main(["bus", "run", "--transport", "can", "--topology", "hydra_full", "--seconds",
                 str(CYCLES / 1000), "--can-log", str(log)]) == 0
    capsys.readouterr()
    side = Path(str(log) + ".eha-hil.json")
    assert json.loads(side.read_text())["topology"] == "hydra_full"
    # the sidecar gives the topology: no --topology needed, times from the log's start
    assert main(["replay", str(log)]) == 0
    assert "20 replies of hydra_full (echo model) match bit for bit" in capsys.readouterr().out
    assert main(["log", "info", str(log)]) == 0
    time_line = next(ln for ln in capsys.readouterr().out.splitlines()
                     if ln.startswith("time:"))
    first, last = (float(x) for x in time_line.split()[1:4:2])
    assert first == 0 and 0 < last < 60, time_line  # not epoch seconds
    # without it: one line asking for --topology, not a replay against a default topology
    side.unlink()
    assert main(["replay", str(log)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "give --topology" in err and "names no topology" in err
    assert main(["replay", str(log), "--topology", "hydra_full"]) == 0
