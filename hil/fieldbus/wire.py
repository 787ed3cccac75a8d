"""The fieldbus frame as the transports carry it: an EtherCAT PDU, optionally followed by a
CRC-32 trailer standing in for the Ethernet FCS.

The transports move bytes, not Ethernet frames. With the trailer (``crc_trailer=True``) the
frame check sequence a NIC would verify travels explicitly: ``pdu || crc32(pdu)`` (4 bytes
little endian, the Ethernet CRC-32, zlib's). Without it the frame is the bare PDU, which is
exactly EtherCAT's own UDP encapsulation (ETG.1000.4: the datagram payload starts with the
2-byte EtherCAT header and ends with the last datagram); integrity then comes from the
carrier (the UDP checksum). A receiver that finds a bad trailer or an undecodable PDU, or
extra bytes after the PDU when it expects none, discards the frame and counts it; nothing
of it is applied.

The trailer is what lets the fieldbus fault injection's bit flips be caught (the fault
acts above the transport, so a carrier checksum computed after the flip would not see it).
Whether a link carries it is the transport's default (``crc_trailer_by_default``: every
backend but ``udp``) unless the caller says otherwise; both ends must agree.
"""

from __future__ import annotations

import zlib

from protocols import ethercat as ec
from protocols.errors import CodecError

FCS_BYTES = 4


def seal(pdu: bytes, crc_trailer: bool = True) -> bytes:
    """The frame for an EtherCAT PDU: the PDU, plus its CRC-32 trailer if asked."""
    if not crc_trailer:
        return pdu
    return pdu + (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little")


def strip(frame: bytes, crc_trailer: bool = True) -> bytes:
    """The PDU of a frame (the trailer, if the frame has one, cut off; not checked)."""
    if crc_trailer and len(frame) > FCS_BYTES:
        return frame[:-FCS_BYTES]
    return frame


def open_frame(frame: bytes, crc_trailer: bool = True) -> list[ec.Datagram] | None:
    """Datagrams of a frame, or None if its trailer or its PDU is bad (or, without a
    trailer, if bytes follow the PDU: e.g. a trailer the receiver did not expect)."""
    if crc_trailer:
        if len(frame) <= FCS_BYTES:
            return None
        pdu, fcs = frame[:-FCS_BYTES], frame[-FCS_BYTES:]
        if (zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") != fcs:
            return None
    else:
        pdu = frame
    try:
        return ec.decode_pdu(pdu, allow_trailing=False)
    except CodecError:
        return None
