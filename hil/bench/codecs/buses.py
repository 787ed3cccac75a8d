"""Benchmark cases for the bus codecs: AD7195 over SPI, pressure ADC, EtherCAT.

``target_fps`` is the issue's target where it sets one; ``0.0`` means no target was set
(the figure is reported only). Batch cases decode a prepared stream; a 2**20-frame stream is
built once (longer runs tile it, cached) so that only decoding is timed.
"""

from __future__ import annotations

from functools import cache, lru_cache

import numpy as np

from hil.bench.codecs import CodecCase
from protocols import ad7195, ethercat, pressure_adc
from protocols.spi import exchange_bytes

_CODES = [(0x800000 + 12345 * k) & 0xFFFFFF for k in range(64)]


def _ad7195_pair() -> tuple[ad7195.AD7195Device, ad7195.AD7195Master]:
    dev, master = ad7195.AD7195Device(), ad7195.AD7195Master()
    master.start(dev.transfer)
    return dev, master


def run_ad7195_data_read(n: int) -> int:
    """Device conversion result -> SPI bytes (byte path) -> master force, ``n`` times."""
    dev, master = _ad7195_pair()
    transfer, set_code, read = dev.transfer, dev.set_code, master.read_force
    codes = _CODES
    for i in range(n):
        set_code(codes[i & 63])
        read(transfer)
    return n


def run_ad7195_bit_level(n: int) -> int:
    """The same data read, clocked bit by bit through the device's SPI state machine."""
    dev, master = _ad7195_pair()
    request = master.data_read_request()
    for i in range(n):
        dev.set_code(_CODES[i & 63])
        master.parse_data_read(exchange_bytes(dev, request))
    return n


_PRESSURES = [0.5e6 * k for k in range(8)]


def run_pressure_scan(n: int) -> int:
    """One 8-channel scan: pressures -> codes -> packed bytes -> codes -> readings."""
    for _ in range(n):
        raw = pressure_adc.pack_scan(pressure_adc.encode_scan(_PRESSURES))
        pressure_adc.decode_scan(pressure_adc.unpack_scan(raw))
    return n


_DGS = [
    ethercat.Datagram.logical(ethercat.Command.LRW, 0x00010000, bytes(32), idx=1, wkc=3),
    ethercat.Datagram(ethercat.Command.FPRD, idx=2, adp=0x1001, ado=0x0130, data=bytes(2)),
    ethercat.Datagram(ethercat.Command.BRD, idx=3, ado=0x0130, data=bytes(2), wkc=4),
]


def run_ethercat_frame(n: int) -> int:
    """Three datagrams (LRW 32 B, FPRD, BRD) -> Ethernet frame -> datagrams."""
    for _ in range(n):
        ethercat.decode_frame(ethercat.encode_frame(_DGS))
    return n


def run_ethercat_udp(n: int) -> int:
    """The same datagrams over UDP/IPv4 (both checksums computed and verified)."""
    for _ in range(n):
        ethercat.decode_udp_frame(ethercat.encode_udp_frame(_DGS))
    return n


_BASE = 1 << 20  # one prepared stream; longer runs tile it


@cache
def _base_words() -> np.ndarray:
    rng = np.random.default_rng(1)
    codes = rng.integers(0, 1 << 24, _BASE, dtype=np.uint32)
    status = rng.choice(np.array([0x00, 0x00, 0x00, 0x80, 0x40], dtype=np.uint32), _BASE)
    return (codes << np.uint32(8)) | status


@cache
def _base_pressure_codes() -> np.ndarray:
    return np.random.default_rng(2).integers(0, 4096, _BASE, dtype=np.uint16)


@lru_cache(maxsize=2)
def _tiled(which: str, n: int) -> np.ndarray:
    base = _base_words() if which == "ad7195" else _base_pressure_codes()
    return np.resize(base, n)


def _stream(which: str, n: int) -> np.ndarray:
    """``n`` prepared words: a view of the base stream, or a cached tiling of it."""
    base = _base_words() if which == "ad7195" else _base_pressure_codes()
    return base[:n] if n <= _BASE else _tiled(which, n)


def run_ad7195_batch(n: int) -> int:
    """Vectorised decode of ``n`` logged 32-bit data+status words."""
    ad7195.decode_data_words(_stream("ad7195", n))
    return n


def run_pressure_batch(n: int) -> int:
    """Vectorised decode of ``n`` logged 12-bit pressure codes."""
    pressure_adc.decode_codes(_stream("pressure", n))
    return n


CASES: list[CodecCase] = [
    CodecCase("AD7195 data read", "frame", run_ad7195_data_read, 100_000.0),
    CodecCase("AD7195 data read, bit-level SPI", "frame", run_ad7195_bit_level, 0.0),
    CodecCase("pressure ADC 8-ch scan", "frame", run_pressure_scan, 0.0),
    CodecCase("EtherCAT frame (3 datagrams, Ethernet)", "frame", run_ethercat_frame, 0.0),
    CodecCase("EtherCAT frame (3 datagrams, UDP)", "frame", run_ethercat_udp, 0.0),
    CodecCase("AD7195 batch decode", "batch", run_ad7195_batch, 1_000_000.0),
    CodecCase("pressure ADC batch decode", "batch", run_pressure_batch, 1_000_000.0),
]
