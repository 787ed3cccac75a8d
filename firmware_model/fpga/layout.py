"""Index layout of the driver board's integer arrays and its LVDS register maps.

The compiled tick addresses everything by these module constants (no string lookups per
tick). The ``*_REGISTERS`` tuples document the two shared memories of the LVDS link: one
entry per 16-bit word (address, name, type, unit/scale, meaning). ``docs/fpga.md`` prints
them as tables.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from protocols import pressure_adc as padc

# --- downstream memory (MCU -> driver), 16-bit words ------------------------------------
DOWN_REGISTERS = (
    (0x00, "control", "u16", "bits", "bit0 ENABLE (level), bit1 CLEAR_FAULT (rising edge)"),
    (0x01, "mode", "u16", "enum", "0 off, 1 current (PI on iq/id refs), 2 voltage (vd/vq refs)"),
    (0x02, "iq_ref", "s16", "mA", "q-axis current reference"),
    (0x03, "id_ref", "s16", "mA", "d-axis current reference"),
    (0x04, "vq_ff", "s16", "mV", "q-axis voltage feed-forward (back-EMF compensation)"),
    (0x05, "vd_ref", "s16", "mV", "d-axis voltage, voltage mode"),
    (0x06, "vq_ref", "s16", "mV", "q-axis voltage, voltage mode"),
    (0x07, "current_limit", "u16", "mA", "clamp of |iq_ref| and |id_ref|"),
    (0x08, "trip_current", "u16", "mA", "over-current trip level, any phase"),
    (0x09, "angle_offset", "u16", "2^16/turn", "electrical angle of SSI count 0 (calibration)"),
    (0x0A, "kp", "u16", "x 2^-12 V/V", "PI proportional gain multiplier (shift 12)"),
    (0x0B, "ki", "u16", "x 2^-16 V/V/tick", "PI integral gain multiplier (shift 16)"),
    (0x0C, "sequence", "u16", "count", "free counter from the MCU, echoed upstream"),
)
DOWN_WORDS = 16
(D_CONTROL, D_MODE, D_IQ_REF, D_ID_REF, D_VQ_FF, D_VD_REF, D_VQ_REF, D_CURRENT_LIMIT,
 D_TRIP_CURRENT, D_ANGLE_OFFSET, D_KP, D_KI, D_SEQUENCE) = range(len(DOWN_REGISTERS))

CTRL_ENABLE = 1
CTRL_CLEAR_FAULT = 2


class BoardMode(IntEnum):
    """The driver board's ``mode`` register (downstream 0x01); numba compiles the members to
    constants. Not the plant's :class:`plant.layout.DriveMode`, which says how the plant's
    motor is driven."""

    OFF = 0
    CURRENT = 1   # PI current loop on iq_ref / id_ref
    VOLTAGE = 2   # vd_ref / vq_ref straight to the modulator


# --- the 8-channel ADC's inputs: one row per analog sensor ---------------------------------
@dataclass(frozen=True)
class AnalogInput:
    """A linear analog sensor on the driver board's 8-channel ADC, as the whole chain needs
    it: the board copies its 12-bit code (raw word ``name``) from ADC channel
    ``adc_channel`` to the upstream register ``name`` at ``register``; the MCU turns it into
    the SI measurement ``si_name``.

    Transfer: ``V = v_at_zero + x * gain`` when ``volts_per_unit``, else
    ``V = v_at_zero + x / gain`` (gain in SI units per volt). ``v_at_zero`` and ``gain`` are
    numbers (facts of the part, the same for plant and firmware) or the name of a key that
    exists twice: ``sensors.<key>`` (the part's truth, which the plant digitises with) and
    ``firmware.<key>`` (what the MCU decodes with). ``keys`` declares such keys that the
    preset does not hold: (name, default, lo, hi); ``fitted_key`` a ``sensors.<key>``
    (boolean, default false) saying whether the part is mounted: an empty input reads 0 V.
    The part's plant side (which plant output it measures) is in its module under
    :mod:`plant.sensors` (``ANALOG_SOURCES``).
    """

    name: str
    adc_channel: int
    register: int
    unit: str
    meaning: str
    v_at_zero: float | str
    gain: float | str
    volts_per_unit: bool
    keys: tuple[tuple[str, float, float, float], ...] = ()
    fitted_key: str | None = None
    measurement: str = ""   # the MCU's name of the SI value, if not ``name``

    @property
    def si_name(self) -> str:
        """The attribute of the MCU's measurements that holds the SI value."""
        return self.measurement or self.name

    def scales(self, keys: Mapping[str, Any]) -> tuple[float, float]:
        """(v_at_zero, gain) with the key values of ``keys`` (``[sensors]`` for the part's
        truth, ``[firmware]`` for what the MCU decodes with)."""
        return tuple(float(keys[v]) if isinstance(v, str) else float(v)  # type: ignore[return-value]
                     for v in (self.v_at_zero, self.gain))

    def register_row(self) -> tuple[int, str, str, str, str]:
        """Its upstream register, as a row of :data:`UP_REGISTERS`."""
        return (self.register, self.name, "u16", "ADC code", self.meaning)


_P = padc.DEFAULT
#: The thesis does not give the board's ADC pin-out: the channel assignment is an assumption.
ANALOG_INPUTS = (
    AnalogInput("p_acc", 0, 0x0C, "Pa", "accumulator pressure, 12-bit code (1..3.3 V = 0..7 MPa)",
                _P.v_at_zero, _P.pa_per_v, False),
    AnalogInput("p_pump_a", 1, 0x0D, "Pa", "pump port A pressure",
                _P.v_at_zero, _P.pa_per_v, False),
    AnalogInput("p_pump_b", 2, 0x0E, "Pa", "pump port B pressure",
                _P.v_at_zero, _P.pa_per_v, False),
    AnalogInput("p_cyl_a", 3, 0x0F, "Pa", "cylinder chamber A pressure",
                _P.v_at_zero, _P.pa_per_v, False),
    AnalogInput("p_cyl_b", 4, 0x10, "Pa", "cylinder chamber B pressure",
                _P.v_at_zero, _P.pa_per_v, False),
    AnalogInput("temperature", 5, 0x13, "degC",
                "oil temperature, 12-bit code (0.5 V + 10 mV/degC)",
                "temperature_v_at_0c", "temperature_v_per_c", True, measurement="temperature_c"),
    AnalogInput("rod_temperature", 6, 0x1F, "degC",
                "connecting-rod temperature, 12-bit code (MCP9701: 0.4 V + 19.5 mV/degC)",
                "rod_temperature_v_at_0c", "rod_temperature_v_per_c", True,
                keys=(("rod_temperature_v_at_0c", 0.4, 0.0, 10.0),
                      ("rod_temperature_v_per_c", 0.0195, 1e-4, 1.0)),
                fitted_key="rod_temperature_fitted", measurement="rod_temperature_c"),
)
N_ANALOG = len(ANALOG_INPUTS)

# --- upstream memory (driver -> MCU), 16-bit words ----------------------------------------
_FIXED_UP_REGISTERS = (
    (0x00, "status", "u16", "bits", "see STATUS_BITS"),
    (0x01, "state", "u16", "enum", "enable state machine: 0 disabled, 1 enabled, 2 fault"),
    (0x02, "ssi_angle", "u16", "count", "motor SSI absolute angle, 0..2047 per rev"),
    (0x03, "abi_count", "u16", "count", "motor ABI quadrature counter, wraps at 2^16"),
    (0x04, "speed", "s16", "count/window", "ABI count change over speed_window ticks"),
    (0x05, "theta_e", "u16", "2^16/turn", "electrical angle used by the FOC"),
    (0x06, "piston_lo", "u16", "count", "BiSS piston position, bits 15..0 (5 nm/count)"),
    (0x07, "piston_hi", "u16", "count", "BiSS piston position, bits 31..16"),
    (0x08, "iq", "s16", "mA", "measured q-axis current"),
    (0x09, "id", "s16", "mA", "measured d-axis current"),
    (0x0A, "ia", "s16", "mA", "phase a current"),
    (0x0B, "ib", "s16", "mA", "phase b current"),
    (0x11, "strain_lo", "u16", "code", "AD7195 code bits 15..0 (offset binary, +/-3000 N)"),
    (0x12, "strain_hi", "u16", "code", "bits 7..0: AD7195 code bits 23..16; 15..8: sample count"),
    (0x14, "hall", "u16", "code", "hall sensor code Ha<<2|Hb<<1|Hc (debug/calibration)"),
    (0x15, "vd_out", "s16", "mV", "d-axis voltage applied"),
    (0x16, "vq_out", "s16", "mV", "q-axis voltage applied"),
    (0x17, "err_ssi", "u16", "count", "SSI frames rejected (saturating)"),
    (0x18, "err_biss", "u16", "count", "BiSS frames rejected or with the error bit"),
    (0x19, "err_strain", "u16", "count", "AD7195 reads rejected"),
    (0x1A, "err_link_crc", "u16", "count", "downstream words discarded for CRC"),
    (0x1B, "oc_trips", "u16", "count", "over-current trips"),
    (0x1C, "wd_trips", "u16", "count", "link watchdog trips"),
    (0x1D, "sequence_echo", "u16", "count", "last downstream sequence word received"),
    (0x1E, "tick", "u16", "tick", "FPGA tick counter, low 16 bits"),
)
#: One row per 16-bit word (address order): the board's own registers and one per analog
#: input. The link carries UP_WORDS words whatever the map uses (a property of the link).
UP_REGISTERS = tuple(sorted(_FIXED_UP_REGISTERS + tuple(a.register_row() for a in ANALOG_INPUTS)))
UP_WORDS = 32
if [r[0] for r in UP_REGISTERS] != list(range(len(UP_REGISTERS))) or len(UP_REGISTERS) > UP_WORDS:
    raise ImportError("upstream register map: addresses must be 0, 1, ... without gaps or "
                      f"repeats and fit the link's {UP_WORDS} words")
(U_STATUS, U_STATE, U_SSI, U_ABI, U_SPEED, U_THETA_E, U_PISTON_LO, U_PISTON_HI, U_IQ, U_ID,
 U_IA, U_IB, U_P_ACC, U_P_PUMP_A, U_P_PUMP_B, U_P_CYL_A, U_P_CYL_B, U_STRAIN_LO,
 U_STRAIN_HI, U_TEMPERATURE, U_HALL, U_VD_OUT, U_VQ_OUT, U_ERR_SSI, U_ERR_BISS,
 U_ERR_STRAIN, U_ERR_LINK_CRC, U_OC_TRIPS, U_WD_TRIPS, U_SEQ_ECHO, U_TICK) = range(0x1F)

STATUS_BITS = (
    (0, "ENABLED", "PWM running"),
    (1, "FAULT", "a trip is latched; clear with CLEAR_FAULT while ENABLE is low"),
    (2, "OVER_CURRENT", "latched: a phase current reached trip_current"),
    (3, "LINK_LOST", "latched: no valid downstream word for watchdog_s"),
    (4, "ENABLE_REFUSED", "ENABLE requested while a fault is present"),
    (5, "ENCODER_ERROR", "the latest SSI or BiSS read failed"),
    (6, "STRAIN_ERROR", "the latest AD7195 read failed (held until the next read)"),
    (7, "LINK_OK", "a valid downstream word arrived within the watchdog time"),
)
ST_ENABLED, ST_FAULT, ST_OVER_CURRENT, ST_LINK_LOST, ST_ENABLE_REFUSED, ST_ENCODER_ERROR, \
    ST_STRAIN_ERROR, ST_LINK_OK = (1 << b for b, _, _ in STATUS_BITS)

STATE_DISABLED, STATE_ENABLED, STATE_FAULT = 0, 1, 2
STATE_NAMES = ("disabled", "enabled", "fault")

# --- raw sensor inputs (R_*): what the sensor masters deliver each tick -------------------
RAW_NAMES = (
    "ssi_count",      # motor SSI angle, 0 .. 2^ssi_bits - 1
    "ssi_ok",         # 1 if the frame was accepted
    "abi_count",      # quadrature counter, 16 bit
    "biss_count",     # piston position counts (5 nm), position_bits wide
    "biss_ok",        # 1 if the frame was accepted and its error bit clear
    "strain_code",    # AD7195 24-bit code
    "strain_new",     # 1 if a new conversion was read this tick
    "strain_ok",      # 1 if that read was accepted
    "p_acc", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b",  # 12-bit ADC codes
    "temperature",    # 12-bit ADC code
    "ia_code", "ib_code",  # 12-bit current ADC codes, mid-scale = 0 A
    "hall",           # 3-bit hall code
)
(R_SSI, R_SSI_OK, R_ABI, R_BISS, R_BISS_OK, R_STRAIN, R_STRAIN_NEW, R_STRAIN_OK, R_P_ACC,
 R_P_PUMP_A, R_P_PUMP_B, R_P_CYL_A, R_P_CYL_B, R_TEMP, R_IA, R_IB, R_HALL) = range(
    len(RAW_NAMES))


#: Raw words of analog inputs the list above does not name yet are appended, so that the
#: words of every older layout keep their index (logs are written by index).
RAW_NAMES += tuple(a.name for a in ANALOG_INPUTS if a.name not in RAW_NAMES)
N_RAW = len(RAW_NAMES)
#: Raw words and upstream registers of the first layout. Later layouts only append (a
#: sensor added since), so a log written with n words holds the first n of today's.
FIRST_N_RAW = 17
FIRST_N_UP = 31
#: Per analog input (in :data:`ANALOG_INPUTS` order): its raw word, upstream register and
#: ADC channel; constant arrays, which the compiled code takes as constants.
ANALOG_RAW = np.array([RAW_NAMES.index(a.name) for a in ANALOG_INPUTS], dtype=np.int64)
ANALOG_UP = np.array([a.register for a in ANALOG_INPUTS], dtype=np.int64)
ANALOG_CHANNEL = np.array([a.adc_channel for a in ANALOG_INPUTS], dtype=np.int64)

# --- constant parameters (C_*), set once from the configuration ---------------------------
PARAM_NAMES = (
    "pole_pairs", "ssi_shift",        # theta_e = (count * pole_pairs) << ssi_shift + offset
    "adc_mid", "adc_shift",           # current code -> s16: (code - mid) << shift
    "pwm_top",                        # compare counts per half carrier period
    "v_limit",                        # voltage circle radius, Q1.15 of V_dc
    "kp_shift", "ki_shift",
    "ma_to_i", "i_to_ma",             # mA <-> s16 current: multiply, shift 15
    "mv_to_v", "v_to_mv",             # mV <-> s16 voltage: multiply, shift 15
    "wd_ticks",                       # watchdog time in ticks
    "speed_window",                   # ABI speed window, ticks (power of two, <= 256)
    # The current loop as compiled RTL (``fpga.impl = "rtl"``, firmware_model/fpga/rtl_abi.py):
    # the library's tick function, its model and the exchange buffer, as addresses valid in
    # this process only; 0: the board's own loop.
    "rtl_tick", "rtl_handle", "rtl_io",
)
(C_POLE_PAIRS, C_SSI_SHIFT, C_ADC_MID, C_ADC_SHIFT, C_PWM_TOP, C_V_LIMIT, C_KP_SHIFT,
 C_KI_SHIFT, C_MA_TO_I, C_I_TO_MA, C_MV_TO_V, C_V_TO_MV, C_WD_TICKS, C_SPEED_WINDOW,
 C_RTL_TICK, C_RTL_HANDLE, C_RTL_IO) = range(len(PARAM_NAMES))
N_PARAMS = len(PARAM_NAMES)

# --- internal state (F_*) -------------------------------------------------------------------
STATE_VARS = (
    "state",            # enable state machine
    "latched",          # latched fault bits (ST_OVER_CURRENT | ST_LINK_LOST)
    "status_extra",     # non-latched status bits of this tick
    "integ_d", "integ_q",  # PI integrators, s32
    "duty_a", "duty_b", "duty_c",  # compare counts applied
    "pwm_on",           # 1 while the gates switch
    "since_valid",      # ticks since the last valid downstream word
    "prev_control",     # control word of the previous tick (edge detection)
    "tick",             # FPGA tick counter
    "ring_pos",         # speed ring buffer write index
    "strain_samples",   # AD7195 samples taken (8-bit counter)
    "err_ssi", "err_biss", "err_strain", "err_link_crc", "oc_trips", "wd_trips",
    "id_meas", "iq_meas",  # last measured dq currents, s16
    "vd_out", "vq_out",    # last applied dq voltages, s16
    "theta_e",
)
(F_STATE, F_LATCHED, F_STATUS_EXTRA, F_INTEG_D, F_INTEG_Q, F_DUTY_A, F_DUTY_B, F_DUTY_C,
 F_PWM_ON, F_SINCE_VALID, F_PREV_CONTROL, F_TICK, F_RING_POS, F_STRAIN_SAMPLES, F_ERR_SSI,
 F_ERR_BISS, F_ERR_STRAIN, F_ERR_LINK_CRC, F_OC_TRIPS, F_WD_TRIPS, F_ID, F_IQ, F_VD, F_VQ,
 F_THETA_E) = range(len(STATE_VARS))
RING_BASE = len(STATE_VARS)     # the ABI speed ring buffer follows the named states
RING_MAX = 256
N_STATE = RING_BASE + RING_MAX


def down_address(name: str) -> int:
    """Address of a downstream register by name; KeyError names the register map."""
    for addr, n, *_ in DOWN_REGISTERS:
        if n == name:
            return addr
    raise KeyError(f"no downstream register {name!r}")


def up_address(name: str) -> int:
    """Address of an upstream register by name."""
    for addr, n, *_ in UP_REGISTERS:
        if n == name:
            return addr
    raise KeyError(f"no upstream register {name!r}")
