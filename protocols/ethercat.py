"""EtherCAT frames (IEC 61158 / ETG.1000.4 data-link layer) and their Ethernet/UDP carriers.

Layout, all little endian (ETG.1000.4; Wireshark's ``ecatf``/``ecat`` dissectors agree):

EtherCAT header (2 bytes): bits 0..10 length of all datagrams in bytes, bit 11 reserved (0),
bits 12..15 type (1 = EtherCAT commands / DLPDU).

Datagram: cmd (1) | idx (1) | address (4: ADP u16 + ADO u16, or a 32-bit logical address)
| length word (2: bits 0..10 data length, 11..13 reserved, 14 C circulating, 15 M more
datagrams follow) | IRQ (2) | data (length bytes) | working counter (2).

Carriers: Ethernet II with EtherType 0x88A4, padded to the 60-byte minimum (no FCS, as in
captures); or UDP/IPv4 with destination port 34980 (0x88A4), the payload starting with the
2-byte EtherCAT header.

Each layout is declared once as a field table; ``struct`` formats and the bit packing of
the length words are derived from those tables. Decoders raise only :class:`FrameError`
(layout/length/chain faults) and :class:`CrcError` (IPv4 header or UDP checksum).
"""

from __future__ import annotations

import enum
import ipaddress
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from protocols.errors import (
    CrcError,
    FrameError,
    RangeError,
    as_bytes,
    as_int,
    as_iterable,
    as_sequence,
)

ETHERTYPE_ETHERCAT = 0x88A4
ETHERTYPE_IPV4 = 0x0800
UDP_PORT_ETHERCAT = 34980  # 0x88A4
ETH_HEADER_LEN = 14
ETH_MIN_FRAME = 60  # without the 4-byte FCS
ETH_MAX_PAYLOAD = 1500
BROADCAST_MAC = b"\xff" * 6
#: Locally administered unicast MAC used as the master's source by default.
DEFAULT_MASTER_MAC = bytes.fromhex("020000000001")


class Command(enum.IntEnum):
    """Datagram command codes (ETG.1000.4 Table "EtherCAT command types")."""

    NOP = 0x00
    APRD = 0x01
    APWR = 0x02
    APRW = 0x03
    FPRD = 0x04
    FPWR = 0x05
    FPRW = 0x06
    BRD = 0x07
    BWR = 0x08
    BRW = 0x09
    LRD = 0x0A
    LWR = 0x0B
    LRW = 0x0C
    ARMW = 0x0D
    FRMW = 0x0E


LOGICAL_COMMANDS = frozenset({Command.LRD, Command.LWR, Command.LRW})


# --------------------------------------------------------------------------------------
# Field tables (the one declaration of each layout)
# --------------------------------------------------------------------------------------


class _Fields:
    """A byte layout declared as ``(name, struct code)`` pairs, little endian by default."""

    def __init__(self, fields: Sequence[tuple[str, str]], order: str = "<") -> None:
        self.names = tuple(n for n, _ in fields)
        self.struct = struct.Struct(order + "".join(c for _, c in fields))
        self.size = self.struct.size

    def pack(self, **values: int | bytes) -> bytes:
        try:
            return self.struct.pack(*(values[n] for n in self.names))
        except struct.error as exc:
            raise RangeError(f"field out of range: {exc}") from exc

    def unpack_from(self, buf: bytes, offset: int = 0) -> dict[str, int | bytes]:
        if len(buf) - offset < self.size:
            raise FrameError(f"need {self.size} bytes at offset {offset}, have {len(buf) - offset}")
        return dict(zip(self.names, self.struct.unpack_from(buf, offset), strict=True))


class _BitWord:
    """A 16/32-bit word declared as ``(name, msb, lsb)`` bit fields."""

    def __init__(self, fields: Sequence[tuple[str, int, int]], width: int) -> None:
        self.fields = tuple(fields)
        self.width = width

    def pack(self, **values: int) -> int:
        word = 0
        for name, msb, lsb in self.fields:
            v = as_int(values[name], name, 0, (1 << (msb - lsb + 1)) - 1)
            word |= v << lsb
        return word

    def unpack(self, word: int) -> dict[str, int]:
        return {n: (word >> lsb) & ((1 << (msb - lsb + 1)) - 1) for n, msb, lsb in self.fields}


#: EtherCAT frame header word.
ECAT_HEADER_WORD = _BitWord((("length", 10, 0), ("reserved", 11, 11), ("type", 15, 12)), 16)
ECAT_HEADER = _Fields((("word", "H"),))
ECAT_TYPE_COMMANDS = 1

#: Datagram header (10 bytes) and trailer (working counter).
DATAGRAM_HEADER = _Fields(
    (("cmd", "B"), ("idx", "B"), ("adp", "H"), ("ado", "H"), ("len_word", "H"), ("irq", "H"))
)
DATAGRAM_LEN_WORD = _BitWord(
    (("length", 10, 0), ("reserved", 13, 11), ("circulating", 14, 14), ("more", 15, 15)), 16
)
DATAGRAM_TRAILER = _Fields((("wkc", "H"),))
DATAGRAM_OVERHEAD = DATAGRAM_HEADER.size + DATAGRAM_TRAILER.size  # 12 bytes
#: Largest data of the one datagram of a frame: the Ethernet payload less the 2-byte
#: EtherCAT header and the datagram's header and working counter (1486 bytes).
MAX_DATAGRAM_DATA = ETH_MAX_PAYLOAD - 2 - DATAGRAM_OVERHEAD
MAX_PDU_LENGTH = (1 << 11) - 1

ETHERNET_HEADER = _Fields((("dst", "6s"), ("src", "6s"), ("ethertype", "H")), order=">")
IPV4_HEADER = _Fields(
    (
        ("ver_ihl", "B"),
        ("tos", "B"),
        ("total_length", "H"),
        ("ident", "H"),
        ("flags_frag", "H"),
        ("ttl", "B"),
        ("proto", "B"),
        ("checksum", "H"),
        ("src", "4s"),
        ("dst", "4s"),
    ),
    order=">",
)
UDP_HEADER = _Fields(
    (("src_port", "H"), ("dst_port", "H"), ("length", "H"), ("checksum", "H")), order=">"
)
IPPROTO_UDP = 17


# --------------------------------------------------------------------------------------
# Datagrams and the EtherCAT PDU
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Datagram:
    """One EtherCAT datagram.

    ``adp``/``ado``: position/station address and register offset (the two 16-bit halves of
    the address field); for logical commands use :meth:`logical` / :attr:`lad`.
    ``wkc``: working counter as carried in the frame. ``irq``: the IRQ word.
    """

    cmd: int
    idx: int = 0
    adp: int = 0
    ado: int = 0
    data: bytes = b""
    wkc: int = 0
    irq: int = 0
    circulating: bool = False

    @classmethod
    def logical(
        cls, cmd: int, lad: int, data: bytes, idx: int = 0, wkc: int = 0, irq: int = 0
    ) -> Datagram:
        """A logical-addressed datagram (LRD/LWR/LRW) at 32-bit address ``lad``."""
        lad = as_int(lad, "logical address", 0, 0xFFFFFFFF)
        return cls(as_int(cmd, "command"), idx, lad & 0xFFFF, lad >> 16,
                   as_bytes(data, "datagram data", RangeError), wkc, irq)

    @property
    def lad(self) -> int:
        """The address field read as a 32-bit logical address."""
        return self.adp | (self.ado << 16)

    @property
    def size(self) -> int:
        """Bytes this datagram occupies in a frame."""
        return DATAGRAM_OVERHEAD + len(self.data)


def encode_datagrams(datagrams: Sequence[Datagram]) -> bytes:
    """The datagram area of a frame; M bits are set on all but the last datagram."""
    datagrams = as_sequence(datagrams, "datagrams", RangeError)
    out = bytearray()
    last = len(datagrams) - 1
    for i, d in enumerate(datagrams):
        if not isinstance(d, Datagram):
            raise RangeError(f"datagrams[{i}]: {type(d).__name__} is not a Datagram")
        cmd = as_int(d.cmd, f"datagrams[{i}].cmd")
        if cmd not in Command._value2member_map_:
            raise RangeError(f"unknown command {d.cmd!r}")
        data = as_bytes(d.data, f"datagrams[{i}].data", RangeError)
        n = len(data)
        len_word = DATAGRAM_LEN_WORD.pack(
            length=n, reserved=0, circulating=int(d.circulating), more=int(i < last)
        )
        out += DATAGRAM_HEADER.pack(
            cmd=cmd, idx=d.idx, adp=d.adp, ado=d.ado, len_word=len_word, irq=d.irq
        )
        out += data
        out += DATAGRAM_TRAILER.pack(wkc=d.wkc)
    return bytes(out)


def encode_pdu(datagrams: Sequence[Datagram]) -> bytes:
    """EtherCAT header + datagrams (what follows the Ethernet header or fills a UDP payload).

    Raises :class:`RangeError` for no datagrams, a field out of range or more than 2047
    bytes of datagrams.
    """
    if not as_sequence(datagrams, "datagrams", RangeError):
        raise RangeError("an EtherCAT frame carries at least one datagram")
    body = encode_datagrams(datagrams)
    if len(body) > MAX_PDU_LENGTH:
        raise RangeError(f"{len(body)} bytes of datagrams exceed the 11-bit length field")
    word = ECAT_HEADER_WORD.pack(length=len(body), reserved=0, type=ECAT_TYPE_COMMANDS)
    return ECAT_HEADER.pack(word=word) + body


def decode_pdu(buf: bytes, allow_trailing: bool = True) -> list[Datagram]:
    """Parse an EtherCAT header + datagrams.

    ``allow_trailing``: bytes after the header's length are accepted (Ethernet padding).
    Raises :class:`FrameError` if the type is not 1, a reserved bit is set, the length is
    zero or longer than the buffer, a datagram overruns the length, an M bit is set on the
    datagram that ends the frame, or the M chain ends before the frame's length, and for
    a ``buf`` that is not bytes-like.
    """
    buf = as_bytes(buf, "EtherCAT PDU")
    hdr = ECAT_HEADER_WORD.unpack(int(ECAT_HEADER.unpack_from(buf)["word"]))
    if hdr["type"] != ECAT_TYPE_COMMANDS:
        raise FrameError(f"EtherCAT type {hdr['type']} is not 1 (commands)")
    if hdr["reserved"]:
        raise FrameError("reserved bit 11 of the EtherCAT header is set")
    length = hdr["length"]
    end = ECAT_HEADER.size + length
    if length == 0:
        raise FrameError("EtherCAT length 0: no datagram")
    if end > len(buf):
        raise FrameError(f"EtherCAT length {length} exceeds the {len(buf) - 2} bytes present")
    if not allow_trailing and end != len(buf):
        raise FrameError(f"{len(buf) - end} bytes after the EtherCAT length")
    out: list[Datagram] = []
    pos = ECAT_HEADER.size
    while True:
        if pos + DATAGRAM_HEADER.size > end:
            raise FrameError("datagram header runs past the EtherCAT length")
        h = DATAGRAM_HEADER.unpack_from(buf, pos)
        lw = DATAGRAM_LEN_WORD.unpack(int(h["len_word"]))
        if h["cmd"] not in Command._value2member_map_:
            raise FrameError(f"unknown command {h['cmd']:#04x}")
        if lw["reserved"]:
            raise FrameError("reserved bits 11..13 of a datagram length word set")
        data_start = pos + DATAGRAM_HEADER.size
        nxt = data_start + lw["length"] + DATAGRAM_TRAILER.size
        if nxt > end:
            raise FrameError("datagram runs past the EtherCAT length")
        wkc = int(DATAGRAM_TRAILER.unpack_from(buf, nxt - DATAGRAM_TRAILER.size)["wkc"])
        out.append(
            Datagram(
                cmd=int(h["cmd"]),
                idx=int(h["idx"]),
                adp=int(h["adp"]),
                ado=int(h["ado"]),
                data=buf[data_start : nxt - DATAGRAM_TRAILER.size],
                wkc=wkc,
                irq=int(h["irq"]),
                circulating=bool(lw["circulating"]),
            )
        )
        pos = nxt
        if lw["more"]:
            if pos == end:
                raise FrameError("M bit set on the datagram that ends the frame")
        else:
            if pos != end:
                raise FrameError("M chain ends before the EtherCAT length")
            return out


# --------------------------------------------------------------------------------------
# Ethernet II
# --------------------------------------------------------------------------------------


def mac(value: str | bytes) -> bytes:
    """A MAC address as 6 bytes, from bytes or ``"aa:bb:cc:dd:ee:ff"``."""
    if isinstance(value, str):
        try:
            raw = bytes.fromhex(value.replace(":", "").replace("-", ""))
        except ValueError as exc:
            raise RangeError(f"bad MAC {value!r}") from exc
    else:
        raw = as_bytes(value, "MAC address", RangeError)
    if len(raw) != 6:
        raise RangeError(f"a MAC address has 6 bytes, got {len(raw)}")
    return raw


@dataclass(frozen=True)
class EthernetFrame:
    """An Ethernet II frame without FCS; ``payload`` includes any padding."""

    dst: bytes
    src: bytes
    ethertype: int
    payload: bytes


def encode_ethernet(payload: bytes, dst: str | bytes, src: str | bytes, ethertype: int) -> bytes:
    """Ethernet II frame, zero-padded to the 60-byte minimum (FCS not included)."""
    payload = as_bytes(payload, "Ethernet payload", RangeError)
    if len(payload) > ETH_MAX_PAYLOAD:
        raise RangeError(f"payload of {len(payload)} bytes exceeds the 1500-byte MTU")
    frame = ETHERNET_HEADER.pack(dst=mac(dst), src=mac(src), ethertype=ethertype) + payload
    if len(frame) < ETH_MIN_FRAME:
        frame += bytes(ETH_MIN_FRAME - len(frame))
    return frame


def decode_ethernet(frame: bytes) -> EthernetFrame:
    """Split an Ethernet II frame; :class:`FrameError` if shorter than the 14-byte header."""
    frame = as_bytes(frame, "Ethernet frame")
    h = ETHERNET_HEADER.unpack_from(frame)
    ethertype = int(h["ethertype"])
    if ethertype < 0x0600:
        raise FrameError(f"length/type {ethertype:#06x} is an 802.3 length, not an EtherType")
    return EthernetFrame(bytes(h["dst"]), bytes(h["src"]), ethertype, frame[ETH_HEADER_LEN:])


def encode_frame(
    datagrams: Sequence[Datagram],
    dst: str | bytes = BROADCAST_MAC,
    src: str | bytes = DEFAULT_MASTER_MAC,
) -> bytes:
    """EtherCAT datagrams in an Ethernet II frame (EtherType 0x88A4)."""
    return encode_ethernet(encode_pdu(datagrams), dst, src, ETHERTYPE_ETHERCAT)


def decode_frame(frame: bytes) -> list[Datagram]:
    """Datagrams of an EtherCAT-over-Ethernet frame; :class:`FrameError` on any fault."""
    eth = decode_ethernet(frame)
    if eth.ethertype != ETHERTYPE_ETHERCAT:
        raise FrameError(f"EtherType {eth.ethertype:#06x} is not EtherCAT (0x88a4)")
    return decode_pdu(eth.payload, allow_trailing=True)


# --------------------------------------------------------------------------------------
# IPv4 / UDP
# --------------------------------------------------------------------------------------


def ones_complement_sum(data: bytes) -> int:
    """16-bit one's-complement sum of ``data`` (odd length padded with a zero byte)."""
    data = as_bytes(data, "checksum data", RangeError)
    if len(data) % 2:
        data = data + b"\x00"
    total = sum(struct.unpack(f">{len(data) // 2}H", data))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return total


def internet_checksum(data: bytes) -> int:
    """RFC 1071 Internet checksum: one's complement of the one's-complement sum."""
    return (~ones_complement_sum(data)) & 0xFFFF


def ip4(value: str | bytes) -> bytes:
    """An IPv4 address as 4 bytes, from bytes or dotted quad."""
    if isinstance(value, str):
        try:
            return ipaddress.IPv4Address(value).packed
        except ValueError as exc:
            raise RangeError(f"bad IPv4 address {value!r}") from exc
    raw = as_bytes(value, "IPv4 address", RangeError)
    if len(raw) != 4:
        raise RangeError(f"an IPv4 address has 4 bytes, got {len(raw)}")
    return raw


def _udp_checksum(src: bytes, dst: bytes, udp: bytes) -> int:
    pseudo = src + dst + struct.pack(">BBH", 0, IPPROTO_UDP, len(udp))
    c = internet_checksum(pseudo + udp)
    return c or 0xFFFF  # 0 would mean "no checksum" (RFC 768)


@dataclass(frozen=True)
class UdpDatagram:
    """A decoded UDP/IPv4 packet."""

    src_ip: bytes
    dst_ip: bytes
    src_port: int
    dst_port: int
    payload: bytes
    ttl: int = 64
    ident: int = 0


def encode_ipv4_udp(
    payload: bytes,
    src_ip: str | bytes,
    dst_ip: str | bytes,
    src_port: int = UDP_PORT_ETHERCAT,
    dst_port: int = UDP_PORT_ETHERCAT,
    ttl: int = 64,
    ident: int = 0,
) -> bytes:
    """IPv4 (20-byte header, DF set, correct header checksum) + UDP (with checksum)."""
    src, dst = ip4(src_ip), ip4(dst_ip)
    payload = as_bytes(payload, "UDP payload", RangeError)
    udp_len = UDP_HEADER.size + len(payload)
    total = IPV4_HEADER.size + udp_len
    if total > 0xFFFF:
        raise RangeError("IPv4 packet longer than 65535 bytes")
    udp0 = UDP_HEADER.pack(src_port=src_port, dst_port=dst_port, length=udp_len, checksum=0)
    udp = udp0 + payload
    csum = _udp_checksum(src, dst, udp)
    udp = UDP_HEADER.pack(src_port=src_port, dst_port=dst_port, length=udp_len, checksum=csum)
    ip_fields = dict(
        ver_ihl=0x45,
        tos=0,
        total_length=total,
        ident=ident,
        flags_frag=0x4000,
        ttl=ttl,
        proto=IPPROTO_UDP,
        src=src,
        dst=dst,
    )
    hdr0 = IPV4_HEADER.pack(checksum=0, **ip_fields)
    hdr = IPV4_HEADER.pack(checksum=internet_checksum(hdr0), **ip_fields)
    return hdr + udp + payload


def decode_ipv4_udp(packet: bytes, allow_trailing: bool = True,
                    check_udp_checksum: bool = True) -> UdpDatagram:
    """Parse IPv4 + UDP.

    Raises :class:`CrcError` if the IPv4 header checksum or a non-zero UDP checksum is
    wrong; :class:`FrameError` for anything else malformed (not IPv4, not UDP, fragments,
    lengths inconsistent with the buffer). ``allow_trailing`` accepts Ethernet padding
    after the IP total length. ``check_udp_checksum=False`` skips the UDP checksum, as
    Wireshark does by default: a capture taken on the sending host (loopback included)
    holds datagrams whose checksum the kernel left to the NIC ("checksum offload"), so
    their field is only partly computed and would fail.
    """
    packet = as_bytes(packet, "IPv4 packet")
    h = IPV4_HEADER.unpack_from(packet)
    ver_ihl = int(h["ver_ihl"])
    ihl = (ver_ihl & 0x0F) * 4
    if ver_ihl >> 4 != 4 or ihl < IPV4_HEADER.size:
        raise FrameError(f"not an IPv4 header (version/IHL byte {ver_ihl:#04x})")
    total = int(h["total_length"])
    if total < ihl + UDP_HEADER.size or total > len(packet):
        raise FrameError(f"IPv4 total length {total} inconsistent with {len(packet)} bytes")
    if not allow_trailing and total != len(packet):
        raise FrameError("bytes after the IPv4 total length")
    if ones_complement_sum(packet[:ihl]) != 0xFFFF:
        raise CrcError("IPv4 header checksum wrong")
    if int(h["proto"]) != IPPROTO_UDP:
        raise FrameError(f"IP protocol {h['proto']} is not UDP")
    if int(h["flags_frag"]) & 0x3FFF:
        raise FrameError("IPv4 fragments are not supported")
    u = UDP_HEADER.unpack_from(packet, ihl)
    udp_len = int(u["length"])
    if udp_len != total - ihl:
        raise FrameError(f"UDP length {udp_len} does not match IPv4 payload {total - ihl}")
    udp = packet[ihl:total]
    src, dst = bytes(h["src"]), bytes(h["dst"])
    if check_udp_checksum and int(u["checksum"]) != 0:
        pseudo = src + dst + struct.pack(">BBH", 0, IPPROTO_UDP, udp_len)
        if ones_complement_sum(pseudo + udp) != 0xFFFF:
            raise CrcError("UDP checksum wrong")
    return UdpDatagram(
        src,
        dst,
        int(u["src_port"]),
        int(u["dst_port"]),
        udp[UDP_HEADER.size :],
        int(h["ttl"]),
        int(h["ident"]),
    )


def encode_udp_frame(
    datagrams: Sequence[Datagram],
    src_ip: str | bytes = "192.168.1.1",
    dst_ip: str | bytes = "192.168.1.255",
    dst: str | bytes = BROADCAST_MAC,
    src: str | bytes = DEFAULT_MASTER_MAC,
    src_port: int = UDP_PORT_ETHERCAT,
    ident: int = 0,
) -> bytes:
    """EtherCAT datagrams in UDP/IPv4 (destination port 34980) in an Ethernet II frame."""
    packet = encode_ipv4_udp(
        encode_pdu(datagrams), src_ip, dst_ip, src_port, UDP_PORT_ETHERCAT, ident=ident
    )
    return encode_ethernet(packet, dst, src, ETHERTYPE_IPV4)


def decode_udp_frame(frame: bytes) -> list[Datagram]:
    """Datagrams of an EtherCAT-over-UDP Ethernet frame (destination port must be 34980)."""
    eth = decode_ethernet(frame)
    if eth.ethertype != ETHERTYPE_IPV4:
        raise FrameError(f"EtherType {eth.ethertype:#06x} is not IPv4")
    udp = decode_ipv4_udp(eth.payload, allow_trailing=True)
    if udp.dst_port != UDP_PORT_ETHERCAT:
        raise FrameError(f"UDP port {udp.dst_port} is not EtherCAT (34980)")
    return decode_pdu(udp.payload, allow_trailing=False)


def decode_any(frame: bytes) -> list[Datagram]:
    """Datagrams of a frame carrying EtherCAT either directly or over UDP."""
    eth = decode_ethernet(frame)
    if eth.ethertype == ETHERTYPE_ETHERCAT:
        return decode_pdu(eth.payload, allow_trailing=True)
    return decode_udp_frame(frame)


def expected_wkc(cmd: int, slaves_addressed: int) -> int:
    """Working counter a master expects when every addressed slave succeeds.

    Reads and writes add 1 per slave; read-write commands 3 (1 for the read, 2 for the
    write). NOP: 0. ARMW/FRMW mix rules per slave and raise :class:`RangeError` here.
    """
    cmd = as_int(cmd, "command")
    slaves_addressed = as_int(slaves_addressed, "slaves_addressed", 0)
    if cmd not in Command._value2member_map_ or cmd in (Command.ARMW, Command.FRMW):
        raise RangeError(f"no simple working-counter rule for command {cmd!r}")
    if cmd == Command.NOP:
        return 0
    per = 3 if cmd in (Command.APRW, Command.FPRW, Command.BRW, Command.LRW) else 1
    return per * slaves_addressed


def iter_datagrams(frames: Iterable[bytes]) -> Iterable[tuple[int, Datagram]]:
    """``(frame index, datagram)`` for every datagram of every frame (EtherCAT or UDP)."""
    for i, f in enumerate(as_iterable(frames, "frames")):
        for d in decode_any(f):
            yield i, d
