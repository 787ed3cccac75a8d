"""Direction of frames in captures other tools made: from the frames themselves, not from
the project's own MAC. Captures are written by Wireshark's ``text2pcap`` from hex dumps
and counted with ``tshark`` (skipped without them); the pysoem test checks the same on a
real SOEM capture."""

from __future__ import annotations

import random
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

from hil.fieldbus.traffic import read_capture, summary
from protocols import ethercat as ec

SOEM_MAC = bytes.fromhex("010101010101")  # SOEM's default source MAC
RETURNED = bytes.fromhex("030101010101")  # ... as the slaves hand it back (bit 1 set)

pytestmark = pytest.mark.skipif(
    shutil.which("text2pcap") is None or shutil.which("tshark") is None,
    reason="needs Wireshark's text2pcap and tshark (make system-deps)")


def _cycle(rng: random.Random, n: int) -> tuple[list[ec.Datagram], list[ec.Datagram]]:
    """A request (working counter 0) and the reply the slaves make of it: process data
    changed, working counters counted, auto-increment addresses incremented."""
    data = bytes(rng.randrange(256) for _ in range(8))
    req = [ec.Datagram(ec.Command.LRW, idx=n & 0xFF, adp=0, ado=0x1000, data=data),
           ec.Datagram(ec.Command.APRD, idx=(n + 1) & 0xFF, adp=0, ado=0x0130,
                       data=bytes(2))]
    rep = [ec.Datagram(ec.Command.LRW, idx=n & 0xFF, adp=0, ado=0x1000,
                       data=bytes(rng.randrange(256) for _ in range(8)),
                       wkc=3 * rng.randrange(1, 4)),
           ec.Datagram(ec.Command.APRD, idx=(n + 1) & 0xFF, adp=4, ado=0x0130,
                       data=b"\x08\x00", wkc=1)]
    return req, rep


def _write(path: Path, frames: list[bytes]) -> None:
    """A pcap of ``frames`` by text2pcap (one hex dump per frame, 1 ms apart)."""
    dump = path.with_suffix(".txt")
    with open(dump, "w") as f:
        for k, fr in enumerate(frames):
            f.write(f"00:00:{k / 1000:09.6f}\n")
            for off in range(0, len(fr), 16):
                f.write(f"{off:06x} " + " ".join(f"{b:02x}" for b in fr[off:off + 16]) + "\n")
    subprocess.run(["text2pcap", "-q", "-t", "%H:%M:%S.", str(dump), str(path)], check=True,
                   capture_output=True)


def _tshark(path: Path, filt: str) -> list[str]:
    out = subprocess.run(["tshark", "-r", str(path), "-Y", filt, "-T", "fields", "-e",
                          "ecat.cnt"], capture_output=True, text=True, check=True)
    return out.stdout.split()


def _capture(tmp_path: Path, reply_mac: bytes, lost: set[int]) -> tuple[Path, int, int]:
    rng = random.Random(7)
    frames, n_req, n_rep = [], 0, 0
    for n in range(200):
        req, rep = _cycle(rng, n)
        frames.append(ec.encode_frame(req, src=SOEM_MAC))
        n_req += 1
        if n not in lost:
            frames.append(ec.encode_frame(rep, src=reply_mac))
            n_rep += 1
    path = tmp_path / "foreign.pcap"
    _write(path, frames)
    return path, n_req, n_rep


def test_replies_known_by_the_mac_bit_an_esc_sets(tmp_path: Path) -> None:
    path, n_req, n_rep = _capture(tmp_path, RETURNED, lost={5, 80})
    s = summary(read_capture(path))
    # tshark's reading of the same file: frames with bit 1 of the source MAC are replies
    req_wkc = _tshark(path, "ecat && !(eth.src[0] & 2)")
    rep_wkc = _tshark(path, "ecat && (eth.src[0] & 2)")
    assert (s["requests"], s["replies"], s["direction_unknown"]) == (n_req, n_rep, 0)
    assert len(req_wkc) == n_req and len(rep_wkc) == n_rep
    assert s["reply_wkc"] == dict(Counter(w for line in rep_wkc for w in line.split(",")))


def test_replies_paired_with_their_requests_when_the_mac_does_not_tell(tmp_path: Path
                                                                       ) -> None:
    # a capture where the replies keep the master's MAC: paired by their datagrams
    path, n_req, n_rep = _capture(tmp_path, SOEM_MAC, lost={5, 80})
    t = read_capture(path)
    s = summary(t)
    assert s["requests"] + s["replies"] + s["direction_unknown"] == n_req + n_rep
    # a lost reply leaves its request alone (unknown), never a request called a reply
    assert (s["requests"], s["replies"], s["direction_unknown"]) == (n_rep, n_rep, 2)
    # every frame called a reply carries what tshark reads as non-zero working counters
    numbers = subprocess.run(["tshark", "-r", str(path), "-T", "fields", "-e",
                              "frame.number", "-e", "ecat.cnt"], capture_output=True,
                             text=True, check=True).stdout.splitlines()
    wkc = {int(line.split()[0]): line.split()[1] for line in numbers}
    for k, f in enumerate(t.frames, 1):
        zero = set(wkc[k].split(",")) == {"0"}
        assert zero == (f.direction != "rx"), k
