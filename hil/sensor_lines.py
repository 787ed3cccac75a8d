"""The sensor chips at bit level: plant outputs -> the bits, levels and bytes on their wires.

Each tick :meth:`SensorLines.update` quantises the plant outputs with the *same* compiled
functions as the value level (:mod:`hil.sensor_chips`: ``ssi_count``, ``abi_count``, ...),
then hands the codes to the chips' line models from :mod:`protocols`, where the board's
masters (:class:`firmware_model.fpga.masters.BitLevelMasters`) pick them up:

* ``ssi``: an :class:`protocols.ssi.SsiSlave` presented with the frame of the current
  count; the master clocks it out (times in integer ns).
* ``abi_levels``: every (A, B) state between the previous and the new quadrature count, in
  order. The FPGA samples A/B at its 50 MHz clock, far faster than the encoder moves (at
  most ~7 counts per 50 us tick), so it sees each intermediate state.
* ``biss_samples``: SLO levels of one BiSS-C read cycle (ready, Ack, frame, timeout).
* ``strain``: an :class:`protocols.ad7195.AD7195Device` given a conversion result when a
  conversion completes (:func:`hil.sensor_chips.strain_conversions`); the master reads it
  through :meth:`SensorLines.strain_transfer` when ``strain_rdy_n`` (DOUT/RDY) is low. A
  force beyond the bridge range gives the clamped code with the ERR bit set, as the part.
* ``pressure_scan``: one 8-channel ADC scan (:func:`protocols.pressure_adc.pack_scan`):
  channels 0..4 the pressures in register order, 5 the oil temperature, 6..7 zero.
* ``current_frame``: ia and ib codes, 4 bytes little-endian
  (:data:`firmware_model.fpga.masters.CURRENT_FRAME`, an assumed format).
* ``hall_levels``: (Ha, Hb, Hc) logic levels.

Fault knobs (attributes, applied on the next :meth:`update` or read; "one-shot" ones reset
themselves after use):

* ``ssi_stuck``: None, 0 or 1 -- the SSI data line held low/high (persistent);
* ``ssi_flip_mask``: XOR into the next SSI frame word (one-shot; only a format with parity
  lets the master detect it, the default RMB30 format has none);
* ``biss_flip_mask``: XOR into the next BiSS frame word Start..CRC, bit 0 = the last CRC
  bit (one-shot); :meth:`corrupt_biss_crc` flips one CRC bit;
* ``biss_error_frames``: the next n BiSS frames carry the error bit (nE low);
* ``strain_flip_mask``: XOR into the 32-bit code+status word on DOUT of the next AD7195
  data read (one-shot): 0x40 ERR, 0x80 /RDY (stale), 0x100 a data bit (parity error).
"""

from __future__ import annotations

import numpy as np

from firmware_model.fpga.masters import (
    PRESSURE_CHANNELS,
    TEMPERATURE_CHANNEL,
    boot_strain,
    pack_currents,
    ssi_format,
)
from hil.sensor_chips import (
    PRESSURE_ROWS,
    abi_count,
    biss_count,
    chip_params,
    current_code,
    hall_code,
    pressure_code,
    ssi_count,
    strain_clamped,
    strain_code,
    strain_conversions,
    temperature_code,
)
from plant import layout as L
from plant.config import Config
from protocols.abi import ab_from_count
from protocols.ad7195 import CMD_READ_DATA, AD7195Device
from protocols.biss import BissCodec
from protocols.errors import RangeError
from protocols.pressure_adc import DEFAULT as ADC
from protocols.pressure_adc import pack_scan
from protocols.ssi import SsiCodec, SsiFormat, SsiSlave, SsiTiming

#: BiSS read cycle shape: SLO high before the cycle, Ack zeros, timeout zeros (MA periods).
BISS_READY_BITS = 1
BISS_ACK_BITS = 1
BISS_TIMEOUT_BITS = 1
#: Bytes of an AD7195 data read with DAT_STA: comms byte + 3 code bytes + status.
_STRAIN_READ_LEN = 5


class FaultySsiSlave(SsiSlave):
    """An :class:`SsiSlave` whose data line can be held low or high (``stuck``)."""

    def __init__(self, frame_bits: int, monoflop_ns: int = 20_000) -> None:
        super().__init__(frame_bits, monoflop_ns)
        #: None: healthy; 0 or 1: the data line reads this level whatever the encoder does.
        self.stuck: int | None = None

    def data_at(self, t_ns: int) -> int:
        """Data line level at ``t_ns`` (the stuck level if a fault is set)."""
        level = super().data_at(t_ns)
        return level if self.stuck is None else self.stuck

    def step(self, t_ns: int, clock: int) -> int:
        """Apply a clock level; the encoder shifts on as usual, the line may be stuck."""
        level = super().step(t_ns, clock)
        return level if self.stuck is None else self.stuck


class SensorLines:
    """The motor encoders, piston encoder, strain ADC, board ADCs and hall sensors, as the
    wires the FPGA's masters read (implements
    :class:`firmware_model.fpga.masters.SensorWires`).

    ``ssi_fmt``/``ssi_timing`` override the SSI frame format and the encoder's monoflop
    (the masters must use the same format). The AD7195 is configured with the board's
    power-on sequence here, i.e. before tick 0, because that sequence's mode write would
    discard a conversion finishing at tick 0.
    """

    def __init__(self, cfg: Config, ssi_fmt: SsiFormat | None = None,
                 ssi_timing: SsiTiming | None = None) -> None:
        self.config = cfg
        self.k = chip_params(cfg)
        s = cfg.section("sensors")
        self.ssi_codec = SsiCodec(ssi_fmt or ssi_format(cfg))
        timing = ssi_timing or SsiTiming()
        self.ssi = FaultySsiSlave(self.ssi_codec.frame_bits, timing.monoflop_ns)
        self.biss_codec = BissCodec(s["biss_bits"])
        self.strain = AD7195Device(full_scale_n=s["strain_full_scale_n"])
        boot_strain(cfg, self.strain.transfer)
        # The quadrature count the A/B lines show; the FPGA's counter was zeroed with the
        # encoder at count 0 (theta_m = 0), as the value level counts from there.
        self._abi = 0
        self.abi_levels: list[tuple[int, int]] = []
        self.biss_samples: tuple[int, ...] = ()
        self.pressure_scan = bytes(2 * ADC.channels)
        self.current_frame = pack_currents(0, 0)
        self.hall_levels: tuple[int, int, int] = (0, 0, 0)
        self._scan = [0] * ADC.channels
        # Fault knobs (see the module docstring).
        self.ssi_flip_mask = 0
        self.biss_flip_mask = 0
        self.biss_error_frames = 0
        self.strain_flip_mask = 0

    # --- fault knobs ----------------------------------------------------------------------
    @property
    def ssi_stuck(self) -> int | None:
        """None (healthy) or the level 0/1 the SSI data line is held at."""
        return self.ssi.stuck

    @ssi_stuck.setter
    def ssi_stuck(self, level: int | None) -> None:
        if level not in (None, 0, 1):
            raise ValueError(f"ssi_stuck must be None, 0 or 1, got {level!r}")
        self.ssi.stuck = level

    def corrupt_biss_crc(self) -> None:
        """Flip the last CRC bit of the next BiSS frame."""
        self.biss_flip_mask ^= 1

    # --- the wires -------------------------------------------------------------------------
    @property
    def strain_rdy_n(self) -> int:
        """AD7195 DOUT/RDY level: 0 while an unread conversion result waits."""
        return 0 if self.strain.ready else 1

    def strain_transfer(self, data: bytes) -> bytes:
        """SPI bytes with the AD7195 (DIN in, DOUT out); applies ``strain_flip_mask`` to the
        code+status bytes of a data read."""
        out = self.strain.transfer(data)
        mask = self.strain_flip_mask
        if mask and len(data) == _STRAIN_READ_LEN and data[0] == CMD_READ_DATA:
            self.strain_flip_mask = 0
            word = int.from_bytes(out[1:], "big") ^ (mask & 0xFFFFFFFF)
            out = out[:1] + word.to_bytes(4, "big")
        return out

    def update(self, y: np.ndarray, tick: int) -> None:
        """Put the plant outputs ``y`` (``plant.layout.Y_*``) of ``tick`` on the wires."""
        k = self.k
        theta = float(y[L.Y_THETA_M])

        # SSI: the frame the encoder latches on the master's first falling edge.
        word = self.ssi_codec.encode(ssi_count(theta, k))
        if self.ssi_flip_mask:
            word ^= self.ssi_flip_mask
            self.ssi_flip_mask = 0
        self.ssi.present(word)

        # ABI: walk the quadrature states one count at a time so no edge is skipped.
        c = abi_count(theta, k)
        prev = self._abi
        if c > prev:
            self.abi_levels = [ab_from_count(n) for n in range(prev + 1, c + 1)]
        elif c < prev:
            self.abi_levels = [ab_from_count(n) for n in range(prev - 1, c - 1, -1)]
        else:
            self.abi_levels = []
        self._abi = c

        # BiSS: one read cycle's SLO samples.
        error = self.biss_error_frames > 0
        if error:
            self.biss_error_frames -= 1
        line = self.biss_codec.encode_line(
            biss_count(float(y[L.Y_X_PISTON]), k), error=error,
            ready_bits=BISS_READY_BITS, ack_bits=BISS_ACK_BITS, timeout_bits=BISS_TIMEOUT_BITS)
        if self.biss_flip_mask:
            line = self._flip_biss(line, self.biss_flip_mask)
            self.biss_flip_mask = 0
        self.biss_samples = line

        # AD7195: a conversion that completed during this tick replaces the data register.
        if strain_conversions(tick, k) != strain_conversions(tick - 1, k):
            f = float(y[L.Y_F_STRAIN])
            self.strain.set_code(strain_code(f, k), err=strain_clamped(f, k))

        # Board ADC scan and current ADC frame.
        scan = self._scan
        for ch, row in zip(PRESSURE_CHANNELS, PRESSURE_ROWS, strict=True):
            scan[ch] = pressure_code(float(y[row]), k)
        scan[TEMPERATURE_CHANNEL] = temperature_code(float(y[L.Y_TEMP]), k)
        self.pressure_scan = pack_scan(scan)
        self.current_frame = pack_currents(current_code(float(y[L.Y_IA]), k),
                                           current_code(float(y[L.Y_IB]), k))

        h = hall_code(theta, k)
        self.hall_levels = ((h >> 2) & 1, (h >> 1) & 1, h & 1)

    def _flip_biss(self, line: tuple[int, ...], mask: int) -> tuple[int, ...]:
        n = self.biss_codec.frame_bits
        if mask >> n:
            raise RangeError(f"BiSS flip mask {mask:#x} wider than the {n}-bit frame")
        start = BISS_READY_BITS + BISS_ACK_BITS  # index of the Start bit
        out = list(line)
        for i in range(n):
            if (mask >> i) & 1:
                out[start + n - 1 - i] ^= 1
        return tuple(out)


__all__ = ["BISS_ACK_BITS", "BISS_READY_BITS", "BISS_TIMEOUT_BITS", "FaultySsiSlave",
           "SensorLines"]
