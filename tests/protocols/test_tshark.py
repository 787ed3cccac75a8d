"""Cross-check with an independent decoder: Wireshark's EtherCAT dissector via ``tshark``.

A capture is written with protocols.pcap + protocols.ethercat (raw Ethernet, EtherType
0x88A4, and UDP port 34980) and read back by tshark; every datagram's command, index,
addresses (ADP/ADO, or the logical address for LRD/LWR/LRW), length and working counter
must be what was written, and the IPv4/UDP checksums must verify.

Field names checked against ``tshark -G fields`` (Wireshark 4.0): per-datagram
``ecat.cmd``, ``ecat.idx``, ``ecat.adp``, ``ecat.ado`` (physical commands only),
``ecat.lad`` (logical commands only), ``ecat.subframe.length`` (the datagram length; there
is no ``ecat.len``), ``ecat.subframe.more``, ``ecat.cnt``, and the indexed copies
``ecat.subN.cmd`` / ``.idx`` / ``.adp`` / ``.ado`` / ``.lad`` / ``.cnt``; frame header
``ecatf.length`` and ``ecatf.type``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from protocols import ethercat as ec
from protocols.ethercat import Command, Datagram
from protocols.pcap import PcapRecord, write_pcap

N_SUB = 4
FIELDS = [
    "frame.number",
    "ecatf.length",
    "ecatf.type",
    "ecat.cmd",
    "ecat.idx",
    "ecat.adp",
    "ecat.ado",
    "ecat.lad",
    "ecat.subframe.length",
    "ecat.subframe.more",
    "ecat.cnt",
    "udp.dstport",
    "ip.checksum.status",
    "udp.checksum.status",
    "_ws.malformed",
] + [
    f"ecat.sub{n}.{f}"
    for n in range(1, N_SUB + 1)
    for f in ("cmd", "idx", "adp", "ado", "lad", "cnt")
]

FRAMES: list[tuple[str, list[Datagram]]] = [
    ("eth", [Datagram(Command.BRD, idx=0x12, ado=0x0130, data=b"\x00\x00", wkc=3)]),
    (
        "eth",
        [
            Datagram(Command.APRD, idx=1, adp=0xFFFF, ado=0x0010, data=b"\x00\x00", wkc=1),
            Datagram.logical(Command.LRW, 0x00010000, bytes(range(8)), idx=2, wkc=3),
            Datagram(Command.FPWR, idx=3, adp=0x1001, ado=0x0120, data=b"\x02\x00", wkc=1),
        ],
    ),
    (
        "eth",
        [
            Datagram.logical(Command.LRD, 0x12345678, bytes(6), idx=0x40, wkc=2),
            Datagram.logical(Command.LWR, 0x00020000, b"\xaa" * 4, idx=0x41, wkc=1),
            Datagram(Command.APWR, idx=0x42, adp=0xFFFE, ado=0x0010, data=b"\x01\x10", wkc=1),
            Datagram(Command.FPRD, idx=0x43, adp=0x03E9, ado=0x0130, data=bytes(2), wkc=0),
        ],
    ),
    ("udp", [Datagram(Command.FPRD, idx=7, adp=0x1001, ado=0x0130, data=b"\x00\x00", wkc=1)]),
    (
        "udp",
        [
            Datagram.logical(Command.LRW, 0x00001000, bytes(range(16)), idx=9, wkc=6),
            Datagram(Command.BRD, idx=10, ado=0x0000, data=bytes(4), wkc=2),
            Datagram(Command.APWR, idx=11, adp=0x0000, ado=0x0120, data=b"\x08\x00", wkc=1),
        ],
    ),
]


def _tshark() -> str:
    path = shutil.which("tshark")
    if path is None:
        pytest.skip(
            "tshark not installed: apt-get install -y --no-install-recommends tshark "
            "(.ci/run does this)"
        )
    return path


def _ints(cell: str) -> list[int]:
    return [int(v, 0) for v in cell.split(";") if v != ""]


def _run_tshark(tshark: str, capture: Path, home: Path) -> list[dict[str, str]]:
    cmd = [
        tshark,
        "-n",
        "-r",
        str(capture),
        "-T",
        "fields",
        "-E",
        "separator=\t",
        "-E",
        "aggregator=;",
        "-o",
        "ip.check_checksum:TRUE",
        "-o",
        "udp.check_checksum:TRUE",
    ]
    for f in FIELDS:
        cmd += ["-e", f]
    env = dict(os.environ, HOME=str(home), XDG_CONFIG_HOME=str(home))
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, check=False)
    # tshark warns on stderr when run as root; only the exit status and stdout matter.
    assert proc.returncode == 0, proc.stderr
    rows = [line.split("\t") for line in proc.stdout.splitlines() if line.strip()]
    return [dict(zip(FIELDS, r + [""] * (len(FIELDS) - len(r)), strict=True)) for r in rows]


def test_tshark_decodes_our_capture(tmp_path: Path) -> None:
    tshark = _tshark()
    records = []
    for i, (kind, dgs) in enumerate(FRAMES):
        frame = ec.encode_frame(dgs) if kind == "eth" else ec.encode_udp_frame(dgs, ident=i)
        records.append(PcapRecord(1_700_000_000_000_000_000 + i * 50_000, frame))
    capture = tmp_path / "ecat.pcap"
    write_pcap(capture, records)

    rows = _run_tshark(tshark, capture, tmp_path)
    assert len(rows) == len(FRAMES)
    for row, (kind, dgs) in zip(rows, FRAMES, strict=True):
        assert row["_ws.malformed"] == "", row
        physical = [d for d in dgs if d.cmd not in ec.LOGICAL_COMMANDS]
        logical = [d for d in dgs if d.cmd in ec.LOGICAL_COMMANDS]
        assert _ints(row["ecatf.length"]) == [sum(d.size for d in dgs)]
        assert _ints(row["ecatf.type"]) == [1]
        assert _ints(row["ecat.cmd"]) == [d.cmd for d in dgs]
        assert _ints(row["ecat.idx"]) == [d.idx for d in dgs]
        assert _ints(row["ecat.subframe.length"]) == [len(d.data) for d in dgs]
        assert _ints(row["ecat.subframe.more"]) == [1] * (len(dgs) - 1) + [0]
        assert _ints(row["ecat.cnt"]) == [d.wkc for d in dgs]
        assert _ints(row["ecat.adp"]) == [d.adp for d in physical]
        assert _ints(row["ecat.ado"]) == [d.ado for d in physical]
        assert _ints(row["ecat.lad"]) == [d.lad for d in logical]
        for n, d in enumerate(dgs, start=1):
            assert _ints(row[f"ecat.sub{n}.cmd"]) == [d.cmd]
            assert _ints(row[f"ecat.sub{n}.idx"]) == [d.idx]
            assert _ints(row[f"ecat.sub{n}.cnt"]) == [d.wkc]
            if d.cmd in ec.LOGICAL_COMMANDS:
                assert _ints(row[f"ecat.sub{n}.lad"]) == [d.lad]
            else:
                assert _ints(row[f"ecat.sub{n}.adp"]) == [d.adp]
                assert _ints(row[f"ecat.sub{n}.ado"]) == [d.ado]
        if kind == "udp":
            assert _ints(row["udp.dstport"]) == [34980]
            # Wireshark checksum status: 1 = good (0 = bad, 2 = unverified).
            assert _ints(row["ip.checksum.status"]) == [1]
            assert _ints(row["udp.checksum.status"]) == [1]
        else:
            assert row["udp.dstport"] == ""
