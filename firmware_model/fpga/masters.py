"""The driver board's sensor masters at bit level: wires in, raw sensor words out.

Each tick :meth:`BitLevelMasters.read` talks to the sensor chips only through what their
links carry (the :class:`SensorWires` protocol, implemented by :class:`plant.sensors.
harness.SensorLines`) and fills the raw word array (``layout.R_*``) the compiled board tick takes,
in the same layout as the value-level :func:`plant.sensors.harness.digitise`:

* SSI (RMB30SI): one clocked frame per tick, starting at ``tick * tick_ns`` (integer ns),
  through :class:`protocols.ssi.SsiMaster`; a rejected frame (line low before the clock,
  not low after the LSB, bad parity) gives ``ssi_ok = 0`` and the previous count is held.
* ABI: a 4x quadrature counter over every A/B level the encoder showed since the previous
  tick (the FPGA samples at 50 MHz, far faster than the lines change), kept as a 16-bit
  register.
* BiSS-C (RESOLUTE): the SLO samples of one read cycle, decoded with
  :meth:`protocols.biss.BissCodec.decode_line`; a framing or CRC error, or the error bit
  (nE low), gives ``biss_ok = 0`` and the previous count is held.
* AD7195: when its DOUT/RDY pin is low (a conversion finished), one data read (comms byte
  0x58, 24-bit code + status) through :class:`protocols.ad7195.AD7195Master`:
  ``strain_new = 1``; a rejected read (stale, ERR, wrong channel, parity) gives
  ``strain_ok = 0`` and the previous code is held.
* The 8-channel ADC (pressures, temperatures): one scan as bytes
  (:func:`protocols.pressure_adc.unpack_scan`); each channel's code goes to the raw word of
  its row of :data:`layout.ANALOG_INPUTS`.
* Phase-current ADC: a 4-byte frame, :data:`CURRENT_FRAME` (assumed format, see there).
* Hall: three logic levels Ha, Hb, Hc -> code ``Ha << 2 | Hb << 1 | Hc``.

Raw words without an ok flag (ADC codes) keep their previous value when a frame is
malformed. Start-up: the board configures the AD7195 at power-on (:func:`boot_strain`,
reset, ID check, configuration and mode with DAT_STA and ENPAR); the sensor lines run that
sequence when they are built, i.e. before tick 0, because a mode write discards a pending
conversion. :meth:`BitLevelMasters.read` checks the configuration with non-destructive
register reads on first contact and boots the part only if it was not configured.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from protocols.abi import QuadratureCounter
from protocols.ad7195 import ID_PART_AD7195, REG_ID, REG_MODE, AD7195Master, Mode
from protocols.biss import BissCodec
from protocols.errors import CodecError, FrameError
from protocols.pressure_adc import unpack_scan
from protocols.ssi import SsiCodec, SsiFormat, SsiMaster, SsiSlave, SsiTiming

#: (raw word, ADC channel) of each analog input (``layout.ANALOG_INPUTS``).
_ANALOG = list(zip(B.ANALOG_RAW.tolist(), B.ANALOG_CHANNEL.tolist(), strict=True))
#: Phase-current ADC frame, assumed (the chip is not named): ia code then ib code, each a
#: little-endian uint16 holding a 12-bit offset-binary code with the top four bits zero.
CURRENT_FRAME = struct.Struct("<HH")
CURRENT_CODE_MAX = 0x0FFF
#: AD7195 channel the bridge is on (CH0 = AIN1(+) - AIN2(-)).
STRAIN_CHANNEL = 0
#: Mode register the board writes: continuous conversion, status appended to each data
#: read (DAT_STA) and the status parity bit (ENPAR) checked, so a flipped data bit is caught.
STRAIN_MODE = Mode(dat_sta=1, enpar=1)
#: Quadrature counter register width (bits).
ABI_BITS = 16


class SensorWires(Protocol):
    """What the sensor links carry in one tick (the chip side of every wire)."""

    #: SSI encoder output stage, clocked by the master.
    ssi: SsiSlave
    #: (A, B) levels the ABI lines took since the previous tick, in order.
    abi_levels: Sequence[tuple[int, int]]
    #: BiSS SLO levels sampled on successive MA rising edges for this tick's read cycle.
    biss_samples: Sequence[int]
    #: 8-channel ADC scan, one little-endian uint16 per channel.
    pressure_scan: bytes
    #: Phase-current ADC frame (:data:`CURRENT_FRAME`).
    current_frame: bytes
    #: Hall sensor levels (Ha, Hb, Hc).
    hall_levels: tuple[int, int, int]

    @property
    def strain_rdy_n(self) -> int:
        """AD7195 DOUT/RDY pin level: 0 = a conversion result is waiting."""
        ...

    def strain_transfer(self, data: bytes) -> bytes:
        """Full-duplex SPI bytes with the AD7195: DIN bytes in, DOUT bytes out."""
        ...


def strain_master(cal: FirmwareCalibration) -> AD7195Master:
    """The board's AD7195 reader: status appended and checked, parity checked."""
    return AD7195Master(full_scale_n=calibration(cal).strain_full_scale_n,
                        status_appended=True, channel=STRAIN_CHANNEL, check_parity=True)


def boot_strain(cal: FirmwareCalibration, transfer: Callable[[bytes], bytes]) -> int:
    """The board's AD7195 power-on sequence over ``transfer``: reset, ID check (FrameError
    if not an AD7195), configuration (channel CH0) and mode (:data:`STRAIN_MODE`).
    Returns the ID byte. A pending conversion result is discarded by the mode write."""
    return strain_master(cal).start(transfer, mode=STRAIN_MODE)


def ssi_format(cal: FirmwareCalibration) -> SsiFormat:
    """SSI frame format of the configured encoder (natural binary, no status, no parity)."""
    return SsiFormat(position_bits=calibration(cal).ssi_bits)


class BitLevelMasters:
    """The FPGA's sensor masters, reading the wires of :class:`SensorWires` each tick.

    ``ssi_fmt``/``ssi_timing`` override the SSI frame format and clock (the sensor lines
    must use the same format). Counters of rejected reads are kept for inspection
    (``ssi_errors``, ``biss_errors``, ``strain_errors``, ``adc_errors``); the board keeps
    its own from the ok flags.
    """

    def __init__(self, cal: FirmwareCalibration, ssi_fmt: SsiFormat | None = None,
                 ssi_timing: SsiTiming | None = None) -> None:
        cal = calibration(cal)
        self.calibration = cal
        self.tick_ns: int = cal.tick_ns
        self._ssi_codec = SsiCodec(ssi_fmt or ssi_format(cal))
        self._ssi_master = SsiMaster(self._ssi_codec.frame_bits, ssi_timing)
        timing = self._ssi_master.timing
        # One frame (frame_bits + 1 clock periods) plus the monoflop must fit in a tick, or
        # every read after the first would find the encoder busy.
        frame_ns = (self._ssi_codec.frame_bits + 1) * 2 * timing.half_period_ns
        if frame_ns + timing.monoflop_ns > self.tick_ns:
            raise ValueError(f"SSI frame {frame_ns} ns + monoflop {timing.monoflop_ns} ns "
                             f"exceed the {self.tick_ns} ns tick")
        self._biss = BissCodec(cal.biss_bits)
        self._strain = strain_master(cal)
        self._strain_wires: object | None = None
        self._abi = QuadratureCounter(0, 0, 0)
        self._abi_mask = (1 << ABI_BITS) - 1
        self._ssi_count = 0
        self._biss_count = 0
        self._strain_code = 0
        self._strain_ok = 0
        self._adc = [0] * 8
        self._currents = (0, 0)
        self.ssi_errors = 0
        self.biss_errors = 0
        self.strain_errors = 0
        self.adc_errors = 0

    @property
    def abi_illegal(self) -> int:
        """Quadrature transitions in which A and B both changed (not counted)."""
        return self._abi.illegal

    def start(self, wires: SensorWires) -> None:
        """Make sure the AD7195 behind ``wires`` is configured as the board needs.

        Reads the ID and mode registers (reads leave a pending result alone); only if the
        mode is not :data:`STRAIN_MODE` does it run :func:`boot_strain`, which discards a
        pending conversion.
        """
        transfer = wires.strain_transfer
        m = self._strain
        if (m.read_register(transfer, REG_ID) & 0x0F) != ID_PART_AD7195 or (
                m.read_register(transfer, REG_MODE) != STRAIN_MODE.encode()):
            boot_strain(self.calibration, transfer)
        self._strain_wires = wires

    def read(self, wires: SensorWires, tick: int, raw: np.ndarray) -> None:
        """Read every sensor link for ``tick`` and fill ``raw`` (int64, ``layout.R_*``)."""
        if self._strain_wires is not wires:
            self.start(wires)

        # SSI: the clock train starts at the tick's first instant; the previous frame's
        # monoflop (20 us) has long expired 50 us later.
        try:
            word, _ = self._ssi_master.read(wires.ssi, tick * self.tick_ns)
            self._ssi_count = self._ssi_codec.decode(word).position
            ssi_ok = 1
        except CodecError:
            ssi_ok = 0
            self.ssi_errors += 1
        raw[B.R_SSI] = self._ssi_count
        raw[B.R_SSI_OK] = ssi_ok

        # ABI: every level change since the last tick; the counter register is 16 bits.
        q = self._abi
        for a, b in wires.abi_levels:
            q.update(a, b)
        q.count &= self._abi_mask
        raw[B.R_ABI] = q.count

        # BiSS: an error bit means the position may be invalid, so it is not taken.
        try:
            r = self._biss.decode_line(wires.biss_samples)
            biss_ok = 0 if r.error else 1
            if biss_ok:
                self._biss_count = r.position
        except CodecError:
            biss_ok = 0
        if not biss_ok:
            self.biss_errors += 1
        raw[B.R_BISS] = self._biss_count
        raw[B.R_BISS_OK] = biss_ok

        # AD7195: read only when DOUT/RDY says a conversion finished.
        if wires.strain_rdy_n == 0:
            raw[B.R_STRAIN_NEW] = 1
            try:
                self._strain_code = self._strain.read_force(wires.strain_transfer).code
                self._strain_ok = 1
            except CodecError:
                self._strain_ok = 0
                self.strain_errors += 1
        else:
            raw[B.R_STRAIN_NEW] = 0
        raw[B.R_STRAIN] = self._strain_code
        raw[B.R_STRAIN_OK] = self._strain_ok

        # The 8-channel ADC's scan.
        try:
            self._adc = unpack_scan(wires.pressure_scan)
        except CodecError:
            self.adc_errors += 1
        adc = self._adc
        for r, ch in _ANALOG:
            raw[r] = adc[ch]

        # Phase currents.
        try:
            self._currents = _unpack_currents(wires.current_frame)
        except CodecError:
            self.adc_errors += 1
        raw[B.R_IA], raw[B.R_IB] = self._currents

        ha, hb, hc = wires.hall_levels
        raw[B.R_HALL] = (ha & 1) << 2 | (hb & 1) << 1 | (hc & 1)


def _unpack_currents(frame: bytes) -> tuple[int, int]:
    """(ia, ib) codes of a :data:`CURRENT_FRAME`; FrameError on length or high bits."""
    if len(frame) != CURRENT_FRAME.size:
        raise FrameError(f"current frame needs {CURRENT_FRAME.size} bytes, got {len(frame)}")
    ia, ib = CURRENT_FRAME.unpack(frame)
    if ia > CURRENT_CODE_MAX or ib > CURRENT_CODE_MAX:
        raise FrameError("current code above 12 bits")
    return ia, ib


def pack_currents(ia_code: int, ib_code: int) -> bytes:
    """The :data:`CURRENT_FRAME` for two 12-bit codes (chip side)."""
    return CURRENT_FRAME.pack(ia_code, ib_code)


__all__ = [
    "ABI_BITS",
    "CURRENT_FRAME",
    "STRAIN_CHANNEL",
    "STRAIN_MODE",
    "BitLevelMasters",
    "SensorWires",
    "boot_strain",
    "pack_currents",
    "ssi_format",
    "strain_master",
]
