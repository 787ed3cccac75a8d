"""Reading captures: the UDP checksum as a sending host's capture leaves it (zero, or only
partly filled in by checksum offload) is accepted and reported; the CRC-32 trailer after a
PDU is recognised and checked. Files built with dpkt's writer and our codecs."""

from __future__ import annotations

import zlib

import dpkt

from hil.fieldbus.traffic import read_traffic, summary
from protocols import ethercat as ec

PDU = ec.encode_pdu([ec.Datagram.logical(ec.Command.LRW, 0, bytes(32), idx=7)])


def _udp(payload: bytes, checksum: int | None = None) -> bytes:
    """EtherCAT over UDP to 34980; ``checksum`` overwrites the computed one."""
    ip = bytearray(ec.encode_ipv4_udp(payload, "127.0.0.1", "127.0.0.1", 40000,
                                      ec.UDP_PORT_ETHERCAT))
    if checksum is not None:
        ip[26:28] = checksum.to_bytes(2, "big")
    return ec.encode_ethernet(bytes(ip), bytes(6), bytes(6), ec.ETHERTYPE_IPV4)


def test_udp_checksums_and_trailers(tmp_path):
    trailer = (zlib.crc32(PDU) & 0xFFFFFFFF).to_bytes(4, "little")
    packets = [_udp(PDU), _udp(PDU, 0), _udp(PDU, 0x1234), _udp(PDU + trailer),
               _udp(PDU + b"\0\0\0\0"), _udp(b"not ethercat at all")]
    path = tmp_path / "t.pcap"
    with open(path, "wb") as fh:
        w = dpkt.pcap.Writer(fh)
        for i, p in enumerate(packets):
            w.writepkt(p, ts=1.0 + i * 1e-3)
    t = read_traffic(path)
    s = summary(t)
    assert s["udp_checksums"] == {"good": 4, "none": 1, "offloaded": 1}
    assert [f.udp_checksum for f in t.frames] == ["good", "none", "offloaded", "good", "good",
                                                   "good"]
    assert [f.crc_trailer for f in t.frames] == [False, False, False, True, False, False]
    assert [f.error for f in t.frames][:4] == [None] * 4
    assert t.frames[4].error == "CRC-32 trailer wrong"
    assert t.frames[5].error is not None  # on port 34980, so counted as a malformed frame
    assert s["malformed"] == 2 and s["datagrams"] == {"LRW": 4}
    assert t.frames[0].ts_ns == 1_000_000_000
