"""The sensor harness: every sensor part of one actuator wired to the driver board's inputs.

Two views of the same parts (:mod:`plant.sensors`), which give the FPGA identical raw words:

* value level, compiled: :func:`digitise` fills the raw words the board's masters would
  decode (``firmware_model.fpga.layout.R_*``) straight from the plant outputs;
* line level: :class:`SensorLines` puts the bits, levels and bytes on the wires each tick
  (implements :class:`firmware_model.fpga.masters.SensorWires`, read by
  :class:`~firmware_model.fpga.masters.BitLevelMasters`): ``ssi`` (an SSI slave presented
  with the frame of the current count), ``abi_levels`` (every A/B state between the previous
  and the new quadrature count: the FPGA samples A/B at 50 MHz, far faster than the encoder
  moves), ``biss_samples`` (one BiSS-C read cycle), ``strain_rdy_n`` and ``strain_transfer``
  (the AD7195 on SPI), ``pressure_scan`` (the 8-channel ADC), ``current_frame``,
  ``hall_levels``.

Fault knobs of the line level (attributes, applied on the next :meth:`SensorLines.update` or
read; the one-shot ones reset themselves): ``ssi_stuck``, ``ssi_flip_mask`` (motor encoder),
``biss_flip_mask``, ``biss_error_frames``, :meth:`SensorLines.corrupt_biss_crc` (piston
encoder), ``strain_flip_mask`` (AD7195); each part's module says what they do.
"""

from __future__ import annotations

import importlib
import pkgutil

import numpy as np
from numba import njit

from firmware_model.fpga import layout as B
from firmware_model.fpga.masters import boot_strain, pack_currents, ssi_format
from plant import layout as L
from plant.config import Config
from plant.sensors.chips import K_MOTOR_DEAD, K_PISTON_DEAD, analog_code, chip_params
from plant.sensors.current_sense import current_code, current_frame
from plant.sensors.hall_sensor import hall_code, hall_levels
from plant.sensors.motor_encoder import MotorEncoderLines, abi_count, ssi_count
from plant.sensors.piston_encoder import PistonEncoderLine, biss_count
from plant.sensors.strain_gauge import (
    StrainAdcLine,
    strain_clamped,
    strain_code,
    strain_conversions,
)
from protocols.pressure_adc import DEFAULT as ADC
from protocols.pressure_adc import pack_scan
from protocols.ssi import SsiCodec, SsiFormat, SsiTiming


def _analog_rows() -> np.ndarray:
    """The plant output each analog input reads (``ANALOG_INPUTS`` order), from the
    ``ANALOG_SOURCES`` of the part modules in :mod:`plant.sensors`."""
    import plant.sensors

    sources: dict[str, int] = {}
    for info in pkgutil.iter_modules(plant.sensors.__path__):
        if info.name == "lanes":  # this harness's lane-wise twin (it imports this), no part
            continue
        part = importlib.import_module(f"plant.sensors.{info.name}")
        for name, row in getattr(part, "ANALOG_SOURCES", {}).items():
            if name in sources:
                raise ImportError(f"analog input {name!r} has two parts ({info.name})")
            sources[name] = row
    names = [a.name for a in B.ANALOG_INPUTS]
    if sorted(sources) != sorted(names):
        raise ImportError(f"analog inputs without a part or parts without an input: "
                          f"{sorted(set(names) ^ set(sources))}")
    return np.array([sources[n] for n in names], dtype=np.int64)


#: The plant output each analog input measures (``ANALOG_INPUTS`` order); a constant of
#: the compiled code.
ANALOG_ROWS = _analog_rows()


@njit(cache=True, _nrt=False)  # no reference counts on the rows (firmware_model.lvds.link)
def digitise(y, k, tick, raw):
    """Fill the raw sensor words (``firmware_model.fpga.layout.R_*``) from plant outputs
    ``y`` at ``tick``. Every link delivers a valid frame unless an encoder is marked dead
    (``K_MOTOR_DEAD``/``K_PISTON_DEAD``, fault injection): its master then sees no valid
    frame (OK = 0) and its counts hold."""
    theta = y[L.Y_THETA_M]
    if k[K_MOTOR_DEAD] > 0.5:
        raw[B.R_SSI_OK] = 0
    else:
        raw[B.R_SSI] = ssi_count(theta, k)
        raw[B.R_SSI_OK] = 1
        raw[B.R_ABI] = abi_count(theta, k) & 0xFFFF
    if k[K_PISTON_DEAD] > 0.5:
        raw[B.R_BISS_OK] = 0
    else:
        raw[B.R_BISS] = biss_count(y[L.Y_X_PISTON], k)
        raw[B.R_BISS_OK] = 1
    new = strain_conversions(tick, k) != strain_conversions(tick - 1, k)
    raw[B.R_STRAIN_NEW] = 1 if new else 0
    if new:
        f = y[L.Y_F_STRAIN]
        if strain_clamped(f, k):
            raw[B.R_STRAIN_OK] = 0  # ERR set: the read is rejected, the last code held
        else:
            raw[B.R_STRAIN] = strain_code(f, k)
            raw[B.R_STRAIN_OK] = 1
    for j in range(ANALOG_ROWS.size):
        raw[B.ANALOG_RAW[j]] = analog_code(y[ANALOG_ROWS[j]], k, j)
    raw[B.R_IA] = current_code(y[L.Y_IA], k)
    raw[B.R_IB] = current_code(y[L.Y_IB], k)
    raw[B.R_HALL] = hall_code(theta, k)


class SensorLines:
    """The motor encoder, piston encoder, strain ADC, board ADCs and hall sensors, as the
    wires the FPGA's masters read (see the module docstring).

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
        timing = ssi_timing or SsiTiming()
        self.motor_encoder = MotorEncoderLines(SsiCodec(ssi_fmt or ssi_format(cfg)),
                                               timing.monoflop_ns)
        self.piston_encoder = PistonEncoderLine(s["biss_bits"])
        self.strain_adc = StrainAdcLine(s["strain_full_scale_n"])
        boot_strain(cfg, self.strain_adc.device.transfer)
        self.pressure_scan = bytes(2 * ADC.channels)
        self.current_frame = pack_currents(0, 0)
        self.hall_levels: tuple[int, int, int] = (0, 0, 0)
        self._scan = [0] * ADC.channels
        self._analog = list(enumerate(zip(B.ANALOG_CHANNEL.tolist(), ANALOG_ROWS.tolist(),
                                          strict=True)))

    # --- the wires -------------------------------------------------------------------------
    @property
    def ssi(self):  # noqa: ANN201
        return self.motor_encoder.ssi

    @property
    def abi_levels(self) -> list[tuple[int, int]]:
        return self.motor_encoder.abi_levels

    @property
    def biss_samples(self) -> tuple[int, ...]:
        return self.piston_encoder.samples

    @property
    def strain_rdy_n(self) -> int:
        """AD7195 DOUT/RDY level: 0 while an unread conversion result waits."""
        return self.strain_adc.rdy_n

    def strain_transfer(self, data: bytes) -> bytes:
        """SPI bytes with the AD7195 (DIN in, DOUT out)."""
        return self.strain_adc.transfer(data)

    # --- fault knobs ------------------------------------------------------------------------
    @property
    def ssi_stuck(self) -> int | None:
        """None (healthy) or the level 0/1 the SSI data line is held at."""
        return self.motor_encoder.ssi.stuck

    @ssi_stuck.setter
    def ssi_stuck(self, level: int | None) -> None:
        if level not in (None, 0, 1):
            raise ValueError(f"ssi_stuck must be None, 0 or 1, got {level!r}")
        self.motor_encoder.ssi.stuck = level

    @property
    def ssi_flip_mask(self) -> int:
        return self.motor_encoder.ssi_flip_mask

    @ssi_flip_mask.setter
    def ssi_flip_mask(self, mask: int) -> None:
        self.motor_encoder.ssi_flip_mask = mask

    @property
    def biss_flip_mask(self) -> int:
        return self.piston_encoder.flip_mask

    @biss_flip_mask.setter
    def biss_flip_mask(self, mask: int) -> None:
        self.piston_encoder.flip_mask = mask

    @property
    def biss_error_frames(self) -> int:
        return self.piston_encoder.error_frames

    @biss_error_frames.setter
    def biss_error_frames(self, n: int) -> None:
        self.piston_encoder.error_frames = n

    def corrupt_biss_crc(self) -> None:
        """Flip the last CRC bit of the next BiSS frame."""
        self.piston_encoder.corrupt_crc()

    @property
    def strain_flip_mask(self) -> int:
        return self.strain_adc.flip_mask

    @strain_flip_mask.setter
    def strain_flip_mask(self, mask: int) -> None:
        self.strain_adc.flip_mask = mask

    # --- one tick ---------------------------------------------------------------------------
    def _adc_scan(self, y: np.ndarray) -> bytes:
        """The packed 8-channel scan of the plant outputs ``y``; empty channels read 0."""
        scan, k = self._scan, self.k
        for j, (ch, row) in self._analog:
            scan[ch] = analog_code(float(y[row]), k, j)
        return pack_scan(scan)

    def update(self, y: np.ndarray, tick: int) -> None:
        """Put the plant outputs ``y`` (``plant.layout.Y_*``) of ``tick`` on the wires."""
        k = self.k
        theta = float(y[L.Y_THETA_M])
        self.motor_encoder.update(theta, k)
        self.piston_encoder.update(float(y[L.Y_X_PISTON]), k)
        self.strain_adc.update(float(y[L.Y_F_STRAIN]), tick, k)
        self.pressure_scan = self._adc_scan(y)
        self.current_frame = current_frame(float(y[L.Y_IA]), float(y[L.Y_IB]), k)
        self.hall_levels = hall_levels(hall_code(theta, k))


__all__ = ["ANALOG_ROWS", "SensorLines", "digitise"]
