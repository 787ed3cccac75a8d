"""The fieldbus frame as the transports carry it: an EtherCAT PDU plus the Ethernet FCS.

The transports move bytes, not Ethernet frames, so the frame check sequence a NIC would
verify travels explicitly: ``pdu || crc32(pdu)`` (4 bytes little endian, the Ethernet
CRC-32, zlib's). A receiver that finds a bad FCS or an undecodable PDU discards the frame
and counts it; nothing of it is applied. EtherCAT decoders ignore the trailing 4 bytes
(like Ethernet padding), so a UDP capture still dissects as EtherCAT.
"""

from __future__ import annotations

import zlib

from protocols import ethercat as ec
from protocols.errors import CodecError

FCS_BYTES = 4


def seal(pdu: bytes) -> bytes:
    """Append the FCS to an EtherCAT PDU."""
    return pdu + (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little")


def open_frame(frame: bytes) -> list[ec.Datagram] | None:
    """Datagrams of a sealed frame, or None if its FCS or its PDU is bad."""
    if len(frame) <= FCS_BYTES:
        return None
    pdu, fcs = frame[:-FCS_BYTES], frame[-FCS_BYTES:]
    if (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") != fcs:
        return None
    try:
        return ec.decode_pdu(pdu, allow_trailing=False)
    except CodecError:
        return None
