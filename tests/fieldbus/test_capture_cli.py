"""Captures made by ``--capture``, judged by Wireshark's own dissectors (tshark), and
captures made by Wireshark's ``dumpcap``, read back by the project.

The UDP test runs in a private network namespace (``ip netns``), so that the chain can take
EtherCAT's port 34980 (the default: no decode option for tshark) without meeting another
run on this machine, and so that ``dumpcap -i lo`` sees only this test's traffic.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from hil.cli import main
from hil.fieldbus.traffic import read_traffic, summary

ROOT = Path(__file__).resolve().parents[2]


def _tshark_env(tmp_path: Path) -> dict[str, str]:
    return dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path))


def _need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pytest.skip(f"{tool} not installed: apt-get install -y --no-install-recommends tshark "
                    "(.ci/run does this)")
    return path


def tshark_rows(path: Path, tmp_path: Path, *extra: str) -> list[list[str]]:
    """Per packet: protocols, EtherCAT command, working counter, malformed, expert info."""
    proc = subprocess.run(
        [_need("tshark"), "-n", "-r", str(path), *extra, "-T", "fields", "-E", "separator=\t",
         "-e", "frame.protocols", "-e", "ecat.cmd", "-e", "ecat.cnt", "-e", "_ws.malformed",
         "-e", "_ws.expert"],
        capture_output=True, text=True, timeout=120, env=_tshark_env(tmp_path), check=False)
    assert proc.returncode == 0, proc.stderr
    return [line.split("\t") for line in proc.stdout.splitlines() if line.strip()]


def _assert_clean_ecat(rows: list[list[str]], n: int, carrier: str) -> None:
    assert len(rows) == n
    for protocols, cmd, _cnt, malformed, expert in rows:
        assert protocols.endswith(f"{carrier}:ecatf:ecat"), protocols
        assert int(cmd, 0) == 12  # LRW
        assert not malformed and not expert


@pytest.mark.parametrize("suffix", [".pcapng", ".pcap"])
def test_capture_of_a_raw_ethernet_run_decodes_in_tshark(tmp_path, suffix, capsys):
    cap = tmp_path / f"bus{suffix}"
    assert main(["bus", "run", "--seconds", "0.02", "--topology", "hydra_full", "--capture",
                 str(cap), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["captured_frames"] == 2 * 2 * 20  # 2 frames per cycle, request and reply
    rows = tshark_rows(cap, tmp_path)
    _assert_clean_ecat(rows, 80, "eth:ethertype")
    # the replies' working counters are the plan's (43 and 3: docs/fieldbus.md)
    assert sorted({r[2] for r in rows}) == ["0", "3", "43"]
    s = summary(read_traffic(cap))
    assert (s["requests"], s["replies"], s["malformed"]) == (40, 40, 0)


def test_replay_of_a_capture_matches_and_sees_a_change(tmp_path, capsys):
    full = tmp_path / "full.pcapng"
    assert main(["bus", "run", "--seconds", "0.02", "--topology", "hydra_full", "--capture",
                 str(full)]) == 0
    capsys.readouterr()
    assert main(["replay", str(full)]) == 0  # topology, model, config from the comment
    assert "40 replies of hydra_full (echo model) match bit for bit" in capsys.readouterr().out
    cap = tmp_path / "bench.pcapng"
    assert main(["bus", "run", "--seconds", "0.03", "--capture", str(cap)]) == 0
    capsys.readouterr()
    assert main(["replay", str(cap)]) == 0
    assert "30 replies of bench_one_box (stack model) match bit for bit" in \
        capsys.readouterr().out
    assert main(["replay", str(cap), "--set", "mcu.kp_force=2.1"]) == 1
    assert ("first divergence at reply at t = 0.003000 s after the first frame (idx 3, lad 0): "
            "datagram 0 logical "
            "address 20 (box 0 inputs byte 10)") in capsys.readouterr().out


def test_capture_usage_errors_are_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:  # argparse: one line, exit 2
        main(["bus", "run", "--capture", str(tmp_path / "x.txt")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "use a file name ending .pcapng, .pcap" in err
    assert main(["bus", "run", "--udp-port", "5"]) == 2
    assert "--udp-port: only with --transport udp" in capsys.readouterr().err
    (tmp_path / "bad.pcapng").write_bytes(b"not a capture at all")
    assert main(["log", "info", str(tmp_path / "bad.pcapng")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a pcap or pcapng capture" in err


@pytest.mark.slow
def test_udp_port_taken_is_one_line(capsys):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        assert main(["bus", "run", "--transport", "udp", "--udp-port", str(port),
                     "--seconds", "0.01"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"cannot bind 127.0.0.1:{port}: address already in use" in err


# --- UDP on EtherCAT's port, in a private network namespace -------------------------------------
def _netns() -> str:
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("needs root and iproute2 (ip netns) for a private network namespace")
    name = f"eha-hil-test-{uuid.uuid4().hex[:8]}"
    proc = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True,
                          check=False)
    if proc.returncode != 0:
        pytest.skip(f"cannot create a network namespace: {proc.stderr.strip()}")
    subprocess.run(["ip", "netns", "exec", name, "ip", "link", "set", "lo", "up"], check=True)
    return name


@pytest.fixture
def netns():
    name = _netns()
    try:
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], check=False)


@pytest.mark.slow
def test_udp_capture_decodes_in_tshark_and_dumpcap_capture_reads_back(netns, tmp_path, capsys):
    """In the namespace: dumpcap captures loopback while ``bus run --transport udp`` (chain
    in another process on port 34980) writes its own capture. tshark decodes ours as
    EtherCAT over UDP without options, warning-free; the project reads dumpcap's pcapng
    (checksums left unfilled by the sending kernel: offload) and replays it bit for bit."""
    dumpcap = _need("dumpcap")
    ours, theirs = tmp_path / "ours.pcapng", tmp_path / "dumpcap.pcapng"
    ns = ["ip", "netns", "exec", netns]
    sniff = subprocess.Popen([*ns, dumpcap, "-q", "-i", "lo", "-f", "udp", "-w", str(theirs)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not theirs.exists() and sniff.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)  # dumpcap creates the file once it captures
        if sniff.poll() is not None or not theirs.exists():
            pytest.skip(f"dumpcap cannot capture here: {sniff.stderr.read().strip()}")
        time.sleep(0.3)
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        run = subprocess.run([*ns, sys.executable, "-m", "hil.cli", "bus", "run", "--transport",
                              "udp", "--topology", "hydra_full", "--seconds", "0.05",
                              "--capture", str(ours), "--json"],
                             capture_output=True, text=True, timeout=300, env=env, check=False)
        assert run.returncode == 0, run.stderr
        time.sleep(0.5)
    finally:
        sniff.terminate()
        sniff.wait(30)
    assert json.loads(run.stdout)["captured_frames"] == 200
    rows = tshark_rows(ours, tmp_path)
    _assert_clean_ecat(rows, 200, "eth:ethertype:ip:udp")

    got = summary(read_traffic(theirs))
    assert (got["requests"], got["replies"], got["malformed"]) == (100, 100, 0)
    assert got["carriers"] == {"udp": 200} and got["crc_trailers"] == 0
    assert got["udp_checksums"] == {"offloaded": 200}  # the loopback capture's checksums
    assert got["datagrams"] == {"LRW": 200} and got["reply_wkc"] == {"43": 50, "3": 50}
    assert main(["replay", str(theirs), "--topology", "hydra_full", "--model", "echo"]) == 0
    assert "100 replies of hydra_full (echo model) match bit for bit" in capsys.readouterr().out
    # tshark agrees that dumpcap's file is EtherCAT (its checksums are not validated)
    _assert_clean_ecat(tshark_rows(theirs, tmp_path), 200, "eth:ethertype:ip:udp")
