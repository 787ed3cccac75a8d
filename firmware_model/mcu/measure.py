"""What the MCU program reads from a driver board's upstream memory, in SI units, float32.

The MCU sees the driver board's upstream memory as plain variables (thesis 6.3.1: a
dual-port RAM in the MCU board's FPGA); this module turns those 16-bit words into physical
values with the scale factors of ``docs/fpga.md``. Everything is ``numpy.float32``.
"""

from __future__ import annotations

import math

import numpy as np

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from protocols import pressure_adc as padc
from protocols.ad7195 import MIDSCALE
from protocols.biss import LINEAR_COUNT_M

F32 = np.float32
TWO_PI = 2.0 * math.pi
#: The iq register's scale (mA -> A).
A_PER_MA = F32(1e-3)


def _s16(w: int) -> int:
    return w - 0x10000 if w & 0x8000 else w


_VOLT_TABLES: dict[float, list] = {}


def _volt_table(lsb: float) -> list:
    """[F32(code) * F32(lsb) for every 16-bit code]: the same float32 products the decode
    would compute, looked up instead of recomputed 6 times per step (replay speed)."""
    table = _VOLT_TABLES.get(lsb)
    if table is None:
        codes = np.arange(1 << 16, dtype=np.float32) * np.float32(lsb)
        table = _VOLT_TABLES[lsb] = list(codes)
    return table


def analog_decoder(a: B.AnalogInput, cal: FirmwareCalibration) -> tuple[float, float, float]:
    """(v0, mul, div) with which the MCU decodes analog input ``a``:
    ``SI = (V - v0) * mul / div`` (one of mul, div is 1, so the products are exact)."""
    v0, gain = cal.analog[a.name]
    mul, div = (1.0, gain) if a.volts_per_unit else (gain, 1.0)
    return v0, mul, div


def strain_decoder(cal: FirmwareCalibration) -> tuple[int, float]:
    """(mid-scale code, N per count) of the strain gauge's conversion: a 24-bit code ``c``
    reads ``(c - mid) * n_per_count`` N, as :func:`upstream_si` decodes it."""
    return MIDSCALE, cal.strain_full_scale_n / MIDSCALE


def upstream_si(up: np.ndarray, cal: FirmwareCalibration) -> dict[str, np.ndarray]:
    """SI values of logged upstream memories ``up`` (n rows of at least ``FIRST_N_UP``
    words) with the calibration's scales, float64 and vectorised, for offline decoding
    (:meth:`Measurements.update` is the MCU's own, float32, one memory at a time): ``iq``,
    ``theta_m`` (the ABI counter unwrapped), ``x_piston``, ``f_strain_raw`` and every
    analog input the rows hold, by its ``si_name``."""
    u = np.asarray(up).astype(np.int64) & 0xFFFF
    iq = u[:, B.U_IQ] - ((u[:, B.U_IQ] & 0x8000) << 1)
    code = ((u[:, B.U_STRAIN_HI] & 0xFF) << 16) | u[:, B.U_STRAIN_LO]
    out = {"iq": iq * 1e-3,
           "theta_m": _unwrap16(u[:, B.U_ABI]) * (TWO_PI / cal.abi_counts_per_rev),
           "x_piston": piston_x(piston_count(u), cal),
           "f_strain_raw": (code - strain_decoder(cal)[0]) * strain_decoder(cal)[1]}
    for a in B.ANALOG_INPUTS:
        if a.register < u.shape[1]:
            v0, mul, div = analog_decoder(a, cal)
            out[a.si_name] = (u[:, a.register] * padc.DEFAULT.lsb_v - v0) * mul / div
    return out


def piston_count(up: np.ndarray) -> np.ndarray:
    """The BiSS piston count (int64) assembled from the two upstream words of memories
    ``up`` (..., >= ``U_PISTON_HI`` + 1 words), high word first as the MCU reads it."""
    u = np.asarray(up)  # the two words only: a block of frames is large
    hi = u[..., B.U_PISTON_HI].astype(np.int64) & 0xFFFF
    return (hi << 16) | (u[..., B.U_PISTON_LO].astype(np.int64) & 0xFFFF)


def piston_x(count: np.ndarray, cal: FirmwareCalibration) -> np.ndarray:
    """Piston position [m] about mid-stroke of BiSS counts ``count`` (float64)."""
    return (count - cal.biss_zero_count) * LINEAR_COUNT_M


def _unwrap16(words: np.ndarray) -> np.ndarray:
    """A 16-bit wrapping counter as int64 counts, continuous; the first value signed."""
    w = words.astype(np.int64) & 0xFFFF
    first = w[:1] - ((w[:1] & 0x8000) << 1)
    step = (np.diff(w) + 0x8000) % 0x10000 - 0x8000
    return np.concatenate([first, first + np.cumsum(step)])


class Measurements:
    """One actuator's measurements, float32 SI, refreshed by :meth:`update`."""

    __slots__ = (*(a.si_name for a in B.ANALOG_INPUTS), "f_pres", "tau_q", "f_strain_raw",
                 "omega_m", "v_pump", "x_piston", "iq", "theta_rotor", "strain_samples",
                 "status", "_k", "_analog", "_volts", "_lsb_v")

    def __init__(self, cal: FirmwareCalibration) -> None:
        cal = calibration(cal)
        adc = padc.DEFAULT
        kc = cal.kc_m2
        kp = cal.kp_m3_per_rad
        window = cal.fpga["speed_window_ticks"]
        tick_s = cal.tick_ns * 1e-9
        self._k = (
            F32(kc),
            F32(TWO_PI / (cal.abi_counts_per_rev * window * tick_s)),   # rad/s per count
            F32(kp / kc),                                                 # m per rad
            F32(cal.strain_full_scale_n / MIDSCALE), MIDSCALE,
            cal.biss_zero_count, F32(5e-9),
            F32(TWO_PI / (1 << cal.ssi_bits)),
        )
        self._analog = [(a.si_name, a.register, *map(F32, analog_decoder(a, cal)))
                        for a in B.ANALOG_INPUTS]
        self._lsb_v = F32(adc.lsb_v)
        self._volts = _volt_table(float(self._lsb_v))
        z = F32(0.0)
        for name in self.__slots__[:-4]:
            setattr(self, name, z)
        self.strain_samples = 0
        self.status = 0

    def scales(self) -> dict[str, object]:
        """The decode's constants by name, as this object holds them (float32 scales, int
        offsets; per analog input in ``ANALOG_INPUTS`` order: register, v0, mul, div)."""
        (kc, rad_per_count, m_per_rad, n_per_code, mid, zero, m_per_count,
         rad_per_ssi) = self._k
        return {"adc_lsb_v": self._lsb_v, "kc": kc, "rad_per_count": rad_per_count,
                "m_per_rad": m_per_rad, "n_per_code": n_per_code, "strain_mid": mid,
                "biss_zero": zero, "m_per_count": m_per_count, "rad_per_ssi": rad_per_ssi,
                "a_per_ma": A_PER_MA, "analog": [row[1:] for row in self._analog]}

    def update(self, up: np.ndarray) -> None:
        """Decode the upstream memory ``up`` (int words) into SI values."""
        (kc, rad_per_count, m_per_rad, n_per_code, mid, zero, m_per_count,
         rad_per_ssi) = self._k
        u = up.tolist()  # Python ints: indexing a list is far cheaper than numpy scalars
        volts = self._volts  # F32(code) * lsb for every 16-bit word, computed once
        for name, reg, v0, mul, div in self._analog:
            setattr(self, name, (volts[u[reg]] - v0) * mul / div)
        self.f_pres = kc * (self.p_cyl_a - self.p_cyl_b)
        self.tau_q = kc * (self.p_pump_a - self.p_pump_b)
        hi = u[B.U_STRAIN_HI]
        code = ((hi & 0xFF) << 16) | u[B.U_STRAIN_LO]
        self.strain_samples = hi >> 8
        self.f_strain_raw = F32(code - mid) * n_per_code
        self.omega_m = F32(_s16(u[B.U_SPEED])) * rad_per_count
        self.v_pump = self.omega_m * m_per_rad
        count = (u[B.U_PISTON_HI] << 16) | u[B.U_PISTON_LO]
        self.x_piston = F32(count - zero) * m_per_count
        self.iq = F32(_s16(u[B.U_IQ])) * A_PER_MA
        self.theta_rotor = F32(u[B.U_SSI]) * rad_per_ssi
        self.status = u[B.U_STATUS]
