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

F32 = np.float32
TWO_PI = 2.0 * math.pi


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


class Measurements:
    """One actuator's measurements, float32 SI, refreshed by :meth:`update`."""

    __slots__ = ("p_acc", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "f_pres", "tau_q",
                 "f_strain_raw", "omega_m", "v_pump", "x_piston", "iq", "theta_rotor",
                 "temperature_c", "strain_samples", "status", "_k", "_volts")

    def __init__(self, cal: FirmwareCalibration) -> None:
        cal = calibration(cal)
        adc = padc.DEFAULT
        kc = cal.kc_m2
        kp = cal.kp_m3_per_rad
        window = cal.fpga["speed_window_ticks"]
        tick_s = cal.tick_ns * 1e-9
        self._k = (
            F32(adc.lsb_v), F32(adc.v_at_zero), F32(adc.pa_per_v), F32(kc),
            F32(TWO_PI / (cal.abi_counts_per_rev * window * tick_s)),   # rad/s per count
            F32(kp / kc),                                                 # m per rad
            F32(cal.strain_full_scale_n / MIDSCALE), MIDSCALE,
            cal.biss_zero_count, F32(5e-9),
            F32(TWO_PI / (1 << cal.ssi_bits)),
            F32(cal.temperature_v_at_0c), F32(cal.temperature_v_per_c),
        )
        self._volts = _volt_table(float(F32(adc.lsb_v)))
        z = F32(0.0)
        for name in self.__slots__[:-2]:
            setattr(self, name, z)
        self.strain_samples = 0
        self.status = 0

    def update(self, up: np.ndarray) -> None:
        """Decode the upstream memory ``up`` (int words) into SI values."""
        (lsb, v0, pa_per_v, kc, rad_per_count, m_per_rad, n_per_code, mid, zero, m_per_count,
         rad_per_ssi, t_v0, t_vpc) = self._k
        u = up.tolist()  # Python ints: indexing a list is far cheaper than numpy scalars
        volts = self._volts  # F32(code) * lsb for every 16-bit word, computed once
        self.p_acc = (volts[u[B.U_P_ACC]] - v0) * pa_per_v
        self.p_pump_a = (volts[u[B.U_P_PUMP_A]] - v0) * pa_per_v
        self.p_pump_b = (volts[u[B.U_P_PUMP_B]] - v0) * pa_per_v
        self.p_cyl_a = (volts[u[B.U_P_CYL_A]] - v0) * pa_per_v
        self.p_cyl_b = (volts[u[B.U_P_CYL_B]] - v0) * pa_per_v
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
        self.iq = F32(_s16(u[B.U_IQ])) * F32(1e-3)
        self.theta_rotor = F32(u[B.U_SSI]) * rad_per_ssi
        self.temperature_c = (volts[u[B.U_TEMPERATURE]] - t_v0) / t_vpc
        self.status = u[B.U_STATUS]
