"""AD7195 strain-gauge bridge ADC: registers, codes, a device model and a firmware-like master.

Sources (register layout and reset values): AD7195 data sheet (Analog Devices, Rev. 0) and
Linux ``drivers/iio/adc/ad7192.c`` (covers AD7190/2/3/4/5; note the AC-excitation bit ACX
is configuration bit 22 on the AD7195 — older kernels put it in the mode register by
mistake and a 2023 fix moved it). No code was copied from either.

Layers, all pure (no timing, no I/O):

* Register declarations: each register is a frozen dataclass whose fields carry their bit
  positions (``bits(msb, lsb)``); ``encode()``/``decode()`` are derived from that single
  declaration by :class:`BitRegister`.
* Code <-> value: :func:`voltage_to_code`, :func:`code_to_voltage` (bipolar offset binary or
  unipolar straight binary), :func:`force_to_code`, :func:`code_to_force` (bridge scale,
  +/- ``full_scale_n`` onto the bipolar code range), and the numpy batch decoder
  :func:`decode_data_words` for logged 32-bit data+status words.
* :class:`AD7195Device`: a state machine that answers an SPI master bit for bit as the part
  does (mode 3, MSB first). ``clock(din) -> dout`` is the bit-level path; ``transfer(bytes)``
  is the byte-level path (same state machine, whole bytes when aligned).
* :class:`AD7195Master`: reads the strain force as firmware does (comms byte 0x58, clock out
  24 or 32 bits, check /RDY, ERR, channel and parity).

Force scale definition (the "full span at 3000 N" of the thesis): in bipolar mode
``force_n = full_scale_n * (code - 2**23) / 2**23``, i.e. code 0x000000 -> -3000 N,
0x800000 -> 0 N, 0xFFFFFF -> +3000 N * (1 - 2**-23). One LSB is 3000 N / 2**23 = 0.358 mN.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, NamedTuple, TypeVar

import numpy as np

from protocols.errors import (
    CrcError,
    FrameError,
    RangeError,
    as_bit,
    as_bytes,
    as_int,
    finite_number,
)

# --------------------------------------------------------------------------------------
# Declarative bit registers
# --------------------------------------------------------------------------------------


def bits(msb: int, lsb: int | None = None, default: int = 0) -> Any:
    """Declare a dataclass field occupying bits ``msb..lsb`` (inclusive) of a register."""
    return field(default=default, metadata={"msb": msb, "lsb": msb if lsb is None else lsb})


R = TypeVar("R", bound="BitRegister")


class BitRegister:
    """Mixin: derive ``encode``/``decode`` from the ``bits(...)`` metadata of dataclass fields.

    Subclasses set ``ADDRESS`` (RS2..RS0) and ``WIDTH`` (bits). Bits not covered by a field
    are reserved and must be 0 (the data sheet: "must be programmed with 0").
    """

    ADDRESS: ClassVar[int]
    WIDTH: ClassVar[int]
    _layout_cache: ClassVar[dict[type, tuple[tuple[str, int, int], ...]]] = {}

    @classmethod
    def layout(cls) -> tuple[tuple[str, int, int], ...]:
        """``(name, msb, lsb)`` of every field, most significant first."""
        cached = BitRegister._layout_cache.get(cls)
        if cached is None:
            items = [
                (f.name, f.metadata["msb"], f.metadata["lsb"])
                for f in fields(cls)  # type: ignore[arg-type]
                if "msb" in f.metadata
            ]
            cached = tuple(sorted(items, key=lambda t: -t[1]))
            BitRegister._layout_cache[cls] = cached
        return cached

    @classmethod
    def reserved_mask(cls) -> int:
        """Mask of the reserved (must-be-zero) bits."""
        used = 0
        for _, msb, lsb in cls.layout():
            used |= ((1 << (msb - lsb + 1)) - 1) << lsb
        return ((1 << cls.WIDTH) - 1) & ~used

    def encode(self) -> int:
        """Pack the fields into the register word. Raises :class:`RangeError` on overflow."""
        word = 0
        for name, msb, lsb in self.layout():
            width = msb - lsb + 1
            value = as_int(getattr(self, name), f"{type(self).__name__}.{name}", 0,
                           (1 << width) - 1)
            word |= value << lsb
        return word

    @classmethod
    def decode(cls: type[R], word: int, strict: bool = True) -> R:
        """Unpack a register word.

        Raises :class:`FrameError` if ``word`` does not fit the register or (``strict``) a
        reserved bit is set.
        """
        if not isinstance(word, int) or not 0 <= word < (1 << cls.WIDTH):
            raise FrameError(f"{word!r} is not a {cls.WIDTH}-bit {cls.__name__} word")
        if strict and word & cls.reserved_mask():
            raise FrameError(f"{cls.__name__}: reserved bits set in {word:#x}")
        values = {
            name: (word >> lsb) & ((1 << (msb - lsb + 1)) - 1) for name, msb, lsb in cls.layout()
        }
        return cls(**values)  # type: ignore[call-arg]


# Register addresses (RS2..RS0 of the communications register).
REG_COMMS = 0  # write: communications register
REG_STATUS = 0  # read: status register
REG_MODE = 1
REG_CONFIG = 2
REG_DATA = 3
REG_ID = 4
REG_GPOCON = 5
REG_OFFSET = 6
REG_FULLSCALE = 7

#: Width in bits of each register as read or written (data: 24, +8 with DAT_STA).
REG_WIDTH: dict[int, int] = {0: 8, 1: 24, 2: 24, 3: 24, 4: 8, 5: 8, 6: 24, 7: 24}


@dataclass(frozen=True)
class Comms(BitRegister):
    """Communications register (write only, 8 bit). Every access starts with this byte."""

    ADDRESS: ClassVar[int] = REG_COMMS
    WIDTH: ClassVar[int] = 8
    wen: int = bits(7)  # write enable: must be 0, a 1 is ignored by the part
    read: int = bits(6)  # 1 = the next operation reads the register, 0 = writes it
    address: int = bits(5, 3)  # RS2..RS0, register to access
    cread: int = bits(2)  # continuous read of the data register


@dataclass(frozen=True)
class Status(BitRegister):
    """Status register (read only, 8 bit); also appended to data reads when DAT_STA = 1."""

    ADDRESS: ClassVar[int] = REG_STATUS
    WIDTH: ClassVar[int] = 8
    rdy_n: int = bits(7, default=1)  # 0 = a new conversion result is in the data register
    err: int = bits(6)  # result clamped to all 0s/1s (over/under range, no reference)
    noref: int = bits(5)  # no valid reference (only with REFDET enabled)
    parity: int = bits(4)  # odd number of 1s in the data register (with ENPAR)
    channel: int = bits(2, 0)  # CHD2..CHD0: channel the data register result belongs to


@dataclass(frozen=True)
class Mode(BitRegister):
    """Mode register (24 bit). Reset value 0x080060."""

    ADDRESS: ClassVar[int] = REG_MODE
    WIDTH: ClassVar[int] = 24
    md: int = bits(23, 21)  # 0 cont., 1 single, 2 idle, 3 power-down, 4..7 calibrations
    dat_sta: int = bits(20)  # append the status byte to every data register read
    clk: int = bits(19, 18, default=2)  # 2 = internal 4.92 MHz clock, MCLK2 tristate
    sinc3: int = bits(15)  # sinc3 instead of sinc4 filter
    enpar: int = bits(13)  # parity bit in the status register enabled
    single: int = bits(11)  # single-cycle conversion (settled result only)
    rej60: int = bits(10)  # extra 60 Hz notch
    fs: int = bits(9, 0, default=0x060)  # filter word: output rate = fclk / 1024 / fs


@dataclass(frozen=True)
class Config(BitRegister):
    """Configuration register (24 bit). Reset value 0x000117."""

    ADDRESS: ClassVar[int] = REG_CONFIG
    WIDTH: ClassVar[int] = 24
    chop: int = bits(23)
    acx: int = bits(22)  # AC excitation of the bridge (AD7195 only)
    channels: int = bits(15, 8, default=0x01)  # CH7..CH0 enable mask; CH0 = AIN1(+)-AIN2(-)
    burn: int = bits(7)  # 500 nA burnout currents
    refdet: int = bits(6)  # reference detect -> NOREF
    buf: int = bits(4, default=1)  # analog input buffer
    unipolar: int = bits(3)  # 1 = unipolar straight binary, 0 = bipolar offset binary
    gain: int = bits(2, 0, default=7)  # G2..G0, see GAIN_OF_CODE


@dataclass(frozen=True)
class Gpocon(BitRegister):
    """GPOCON register (8 bit): bridge power-down switch and digital outputs. Reset 0x00."""

    ADDRESS: ClassVar[int] = REG_GPOCON
    WIDTH: ClassVar[int] = 8
    bpdsw: int = bits(6)
    gp32en: int = bits(5)
    gp10en: int = bits(4)
    p3dat: int = bits(3)
    p2dat: int = bits(2)
    p1dat: int = bits(1)
    p0dat: int = bits(0)


#: Gain of each G2..G0 code; 1 and 2 are reserved on the AD7190/2/5.
GAIN_OF_CODE: dict[int, int] = {0: 1, 3: 8, 4: 16, 5: 32, 6: 64, 7: 128}

MODE_RESET = 0x080060
CONFIG_RESET = 0x000117
STATUS_RESET = 0x80
GPOCON_RESET = 0x00
OFFSET_RESET = 0x800000
#: The data sheet gives 0x5XXXX0 (factory calibrated); the X digits are part specific.
FULLSCALE_RESET = 0x500000
#: Low nibble of the ID register that identifies an AD7195 (ad7192.c: ID_AD7195 = 0x6).
ID_PART_AD7195 = 0x6
#: Default whole ID byte; the high nibble is not specified for use, 0xA is what the brief
#: quotes. Masters compare only the low nibble.
ID_DEFAULT = 0xA6
#: Comms byte for a single read of the data register: R/W = 1, RS = 3 -> 0b0101_1000.
CMD_READ_DATA = 0x58
#: Comms byte entering continuous read: 0x58 | CREAD.
CMD_CONT_READ = 0x5C
#: The part resets after this many consecutive 1s on DIN.
RESET_ONES = 40

CODE_BITS = 24
CODE_MAX = (1 << CODE_BITS) - 1
MIDSCALE = 1 << (CODE_BITS - 1)  # 0x800000: 0 V in bipolar mode
DEFAULT_FULL_SCALE_N = 3000.0


def comms_byte(address: int, read: bool, cread: bool = False) -> int:
    """Return the communications byte that starts an access to ``address``."""
    return Comms(read=as_bit(read, "read", RangeError), address=address,
                 cread=as_bit(cread, "cread", RangeError)).encode()


# --------------------------------------------------------------------------------------
# Codes <-> values
# --------------------------------------------------------------------------------------




def voltage_to_code(
    ain_v: float, vref_v: float, gain: int = 1, bipolar: bool = True
) -> tuple[int, bool]:
    """Ideal conversion of a differential input voltage to a 24-bit code.

    Bipolar: ``code = 2**23 * (ain * gain / vref + 1)``; unipolar: ``2**24 * ain * gain /
    vref``; rounded to nearest (half up). Returns ``(code, clamped)``: like the part, an input
    beyond the range gives all 0s or all 1s and ``clamped`` (the part's ERR bit) is True.
    """
    ain = finite_number(ain_v, "ain_v")
    vref = finite_number(vref_v, "vref_v")
    gain = as_int(gain, "gain")
    if vref <= 0 or gain not in GAIN_OF_CODE.values():
        raise RangeError(f"vref {vref} V / gain {gain} invalid")
    ratio = ain * gain / vref
    x = (ratio + 1.0) * MIDSCALE if bipolar else ratio * (1 << CODE_BITS)
    if x < -0.5:
        return 0, True
    if x >= CODE_MAX + 0.5:
        return CODE_MAX, True
    return int(math.floor(x + 0.5)), False


def code_to_voltage(code: int, vref_v: float, gain: int = 1, bipolar: bool = True) -> float:
    """Input voltage (V) represented by a 24-bit code (inverse of :func:`voltage_to_code`)."""
    code = _check_code(code)
    vref_v = _positive(vref_v, "vref_v")
    gain = as_int(gain, "gain")
    if gain not in GAIN_OF_CODE.values():
        raise RangeError(f"gain {gain} invalid")
    if bipolar:
        return (code / MIDSCALE - 1.0) * vref_v / gain
    return code / (1 << CODE_BITS) * vref_v / gain


def _positive(x: object, what: str) -> float:
    """A finite number > 0 (a reference voltage, a full scale), else RangeError."""
    v = finite_number(x, what)
    if v <= 0:
        raise RangeError(f"{what}: {v} must be > 0")
    return v


def _check_code(code: int) -> int:
    """Return ``code`` as a Python int (numpy integers accepted) or raise RangeError."""
    if not isinstance(code, numbers.Integral) or isinstance(code, bool):
        raise RangeError(f"{code!r} is not a 24-bit code")
    code = int(code)  # numpy scalars would wrap in the unsigned arithmetic below
    if not 0 <= code <= CODE_MAX:
        raise RangeError(f"{code:#x} is not a 24-bit code")
    return code


def code_to_force(code: int, full_scale_n: float = DEFAULT_FULL_SCALE_N) -> float:
    """Bridge force (N) of a bipolar code: ``(code - 2**23) * full_scale_n / 2**23``."""
    code = _check_code(code)
    full_scale_n = _positive(full_scale_n, "full_scale_n")
    return (code - MIDSCALE) * (full_scale_n / MIDSCALE)


def force_to_code(force_n: float, full_scale_n: float = DEFAULT_FULL_SCALE_N) -> int:
    """Bipolar code for a force (N), rounded to nearest.

    Raises :class:`RangeError` if the force lies outside what the code can carry
    (about -3000 N .. +3000 N minus one LSB at the default scale).
    """
    f = finite_number(force_n, "force_n")
    full_scale_n = _positive(full_scale_n, "full_scale_n")
    x = f * (MIDSCALE / full_scale_n) + MIDSCALE
    if not -0.5 <= x < CODE_MAX + 0.5:
        raise RangeError(f"{f} N is outside +/-{full_scale_n} N")
    return int(math.floor(x + 0.5))


def clamp_force_to_code(
    force_n: float, full_scale_n: float = DEFAULT_FULL_SCALE_N
) -> tuple[int, bool]:
    """Like :func:`force_to_code` but saturating as the ADC does; returns ``(code, clamped)``."""
    f = finite_number(force_n, "force_n")
    full_scale_n = _positive(full_scale_n, "full_scale_n")
    x = f * (MIDSCALE / full_scale_n) + MIDSCALE
    if x < -0.5:
        return 0, True
    if x >= CODE_MAX + 0.5:
        return CODE_MAX, True
    return int(math.floor(x + 0.5)), False


def parity_of(code: int) -> int:
    """1 if ``code`` has an odd number of 1 bits (the status PARITY bit with ENPAR)."""
    return as_int(code, "code", 0).bit_count() & 1


# --------------------------------------------------------------------------------------
# Data words (24-bit code with the status byte appended)
# --------------------------------------------------------------------------------------


class DataWord(NamedTuple):
    """A data register read with DAT_STA: ``(code << 8) | status``."""

    code: int
    status: int

    def encode(self) -> int:
        """The 32-bit word as clocked out (code first, status last)."""
        code = _check_code(self.code)
        if not isinstance(self.status, int) or not 0 <= self.status <= 0xFF:
            raise RangeError(f"status {self.status!r} is not a byte")
        return (code << 8) | self.status

    @classmethod
    def decode(cls, word: int) -> DataWord:
        """Split a 32-bit data+status word. :class:`FrameError` if not a 32-bit value."""
        if not isinstance(word, int) or not 0 <= word <= 0xFFFFFFFF:
            raise FrameError(f"{word!r} is not a 32-bit data word")
        return cls(word >> 8, word & 0xFF)


@dataclass(frozen=True)
class ForceSample:
    """One strain reading as the firmware sees it: force in N, raw code, status byte."""

    force_n: float
    code: int
    status: int | None  # None when DAT_STA is off (no status appended)


_STATUS_RESERVED = Status.reserved_mask()


def check_status(status: int, channel: int | None = 0, code: int | None = None) -> None:
    """Firmware checks on a status byte read with the data.

    Raises :class:`FrameError` if /RDY = 1 (no new result: stale data), a reserved bit is
    set or the channel is not ``channel``; :class:`RangeError` if ERR = 1 (clamped result);
    :class:`CrcError` if ``code`` is given and the PARITY bit disagrees with it (only
    meaningful with ENPAR set).
    """
    if not isinstance(status, int) or not 0 <= status <= 0xFF:
        raise FrameError(f"{status!r} is not a status byte")
    if status & 0x80:
        raise FrameError("status /RDY = 1: no new conversion (stale data)")
    if status & _STATUS_RESERVED:
        raise FrameError(f"status reserved bit set: {status:#04x}")
    if channel is not None and status & 0x07 != channel:
        raise FrameError(f"result of channel {status & 7}, expected {channel}")
    if status & 0x40:
        raise RangeError("status ERR = 1: result clamped (over/under range or no reference)")
    if code is not None and ((status >> 4) & 1) != parity_of(code):
        raise CrcError("status PARITY does not match the data register")


@dataclass(frozen=True)
class DataBatch:
    """Vectorised decode of logged data+status words (all arrays of the input's length)."""

    force_n: np.ndarray  # float64, N
    code: np.ndarray  # uint32, 24-bit codes
    rdy_n: np.ndarray  # bool, True = stale (no new result)
    err: np.ndarray  # bool, clamped result
    noref: np.ndarray  # bool
    parity: np.ndarray  # bool
    channel: np.ndarray  # uint8
    valid: np.ndarray  # bool: fresh, no error, reserved bit clear


def decode_data_words(words: np.ndarray, full_scale_n: float = DEFAULT_FULL_SCALE_N) -> DataBatch:
    """Decode an array of 32-bit ``(code << 8) | status`` words to forces and flags.

    Raises :class:`RangeError` if ``words`` is not an integer array of values in 0..2**32-1.
    """
    full_scale_n = _positive(full_scale_n, "full_scale_n")
    w = np.asarray(words)
    if w.dtype.kind not in "ui":
        raise RangeError(f"words must be an integer array, got dtype {w.dtype}")
    if w.dtype.kind == "i" or w.dtype.itemsize > 4:
        if w.size and (int(w.min()) < 0 or int(w.max()) > 0xFFFFFFFF):
            raise RangeError("data words must lie in 0..2**32-1")
    w = w.astype(np.uint32, copy=False)
    code = w >> np.uint32(8)
    status = (w & np.uint32(0xFF)).astype(np.uint8)
    force = (code.astype(np.int64) - MIDSCALE) * (full_scale_n / MIDSCALE)
    rdy_n = (status & 0x80) != 0
    err = (status & 0x40) != 0
    reserved = (status & _STATUS_RESERVED) != 0
    return DataBatch(
        force_n=force,
        code=code,
        rdy_n=rdy_n,
        err=err,
        noref=(status & 0x20) != 0,
        parity=(status & 0x10) != 0,
        channel=status & np.uint8(0x07),
        valid=~(rdy_n | err | reserved),
    )


# --------------------------------------------------------------------------------------
# Device model
# --------------------------------------------------------------------------------------

_COMMS, _WRITE, _READ = 0, 1, 2

# Runs of 1s at the MSB end / LSB end of each byte, for the byte-level reset counter.
_LEAD1 = tuple(next((k for k in range(8) if not (b << k) & 0x80), 8) for b in range(256))
_TRAIL1 = tuple(next((k for k in range(8) if not (b >> k) & 1), 8) for b in range(256))


class AD7195Device:
    """Bit-exact model of the AD7195 serial interface and register file.

    The caller supplies conversion results with :meth:`set_code`, :meth:`set_input` or
    :meth:`set_force` (each one is "a conversion just finished": /RDY goes low). A master
    talks to it with :meth:`clock` (one SCLK period, mode 3) or :meth:`transfer` (whole
    bytes). Behaviour follows the data sheet; where it is silent the choice is documented in
    ``docs/protocols-buses.md`` (e.g. writes to read-only registers are consumed and dropped;
    CS is taken as held low, so it does not reset the interface).
    """

    def __init__(
        self,
        *,
        id_value: int = ID_DEFAULT,
        vref_v: float = 5.0,
        full_scale_n: float = DEFAULT_FULL_SCALE_N,
        fullscale_reset: int = FULLSCALE_RESET,
    ) -> None:
        if not 0 <= id_value <= 0xFF:
            raise RangeError("id_value must be a byte")
        self.id_value = id_value
        self.vref_v = vref_v
        self.full_scale_n = full_scale_n
        self._fullscale_reset = fullscale_reset
        self.reset()

    # ---- register file ------------------------------------------------------------------
    def reset(self) -> None:
        """Power-on / 40-ones reset: every register to its reset value, interface idle."""
        self.mode = MODE_RESET
        self.config = CONFIG_RESET
        self.status = STATUS_RESET
        self.gpocon = GPOCON_RESET
        self.offset = OFFSET_RESET
        self.fullscale = self._fullscale_reset
        self.data = 0
        self.cread = False
        self._phase = _COMMS
        self._acc = 0
        self._nbits = 0
        self._need = 0
        self._addr = 0
        self._out = 0
        self._left = 0
        self._is_data_read = False
        self._cmd = 0  # DIN bits seen during a continuous-read data read
        self._cmd_bits = 0
        self._ones = 0

    @property
    def dat_sta(self) -> bool:
        """Whether data reads carry the status byte (mode bit 20)."""
        return bool(self.mode & (1 << 20))

    @property
    def ready(self) -> bool:
        """True when an unread conversion result is waiting (/RDY low)."""
        return not self.status & 0x80

    def read_register_value(self, address: int) -> int:
        """Value a read of ``address`` would return (data: without status)."""
        address = as_int(address, "register address", 0, 7)
        return {
            REG_STATUS: self.status,
            REG_MODE: self.mode,
            REG_CONFIG: self.config,
            REG_DATA: self.data,
            REG_ID: self.id_value,
            REG_GPOCON: self.gpocon,
            REG_OFFSET: self.offset,
            REG_FULLSCALE: self.fullscale,
        }[address]

    # ---- conversion results (set by the plant side) ------------------------------------
    def _default_channel(self) -> int:
        mask = (self.config >> 8) & 0xFF
        return (mask & -mask).bit_length() - 1 if mask else 0

    def set_code(
        self, code: int, *, channel: int | None = None, err: bool = False, noref: bool = False
    ) -> None:
        """A conversion finished with result ``code`` (24 bit): data register, /RDY = 0."""
        code = _check_code(code)
        ch = self._default_channel() if channel is None else as_int(channel, "channel", 0, 7)
        par = parity_of(code) if self.mode & (1 << 13) else 0
        self.data = code
        self.status = (int(err) << 6) | (int(noref) << 5) | (par << 4) | ch

    def set_input(self, ain_v: float, *, channel: int | None = None) -> int:
        """Convert a differential input voltage (V) with the configured gain/polarity.

        Out-of-range inputs clamp and set ERR, as on the part. Returns the code.
        """
        gain_code = self.config & 0x7
        gain = GAIN_OF_CODE.get(gain_code)
        if gain is None:
            raise RangeError(f"gain code {gain_code} is reserved")
        code, clamped = voltage_to_code(
            ain_v, self.vref_v, gain, bipolar=not self.config & (1 << 3)
        )
        self.set_code(code, channel=channel, err=clamped)
        return code

    def set_force(self, force_n: float, *, channel: int | None = None) -> int:
        """Convert a bridge force (N) with the bridge scale; clamps and sets ERR beyond it."""
        code, clamped = clamp_force_to_code(force_n, self.full_scale_n)
        self.set_code(code, channel=channel, err=clamped)
        return code

    # ---- serial interface -------------------------------------------------------------
    def _start_read(self, address: int) -> None:
        if address == REG_DATA:
            if self.dat_sta:
                self._out, self._left = (self.data << 8) | self.status, 32
            else:
                self._out, self._left = self.data, 24
            self._is_data_read = True
        else:
            self._out, self._left = self.read_register_value(address), REG_WIDTH[address]
            self._is_data_read = False
        self._phase = _READ

    def _on_comms(self, byte: int) -> None:
        # Bits 1..0 "must be 0": the part's reaction otherwise is not documented; ignored.
        read = byte & 0x40
        address = (byte >> 3) & 0x7
        if read and address == REG_DATA and byte & 0x04:
            # 0x5C: continuous read. No read starts now; the next clocks after /RDY falls
            # shift out the data register without a comms byte.
            self.cread = True
            self._phase = _COMMS
        elif read:
            self._start_read(address)
        elif address == REG_COMMS:
            self._phase = _COMMS  # writing the comms register: next byte is a comms byte
        else:
            self._addr, self._need, self._acc, self._nbits = address, REG_WIDTH[address], 0, 0
            self._phase = _WRITE

    def _on_write_done(self) -> None:
        value, addr = self._acc, self._addr
        if addr == REG_MODE:
            self.mode = value
            self.status |= 0x80  # a mode write restarts conversion: pending result dropped
        elif addr == REG_CONFIG:
            self.config = value
            self.status |= 0x80
        elif addr == REG_GPOCON:
            self.gpocon = value
        elif addr == REG_OFFSET:
            self.offset = value
        elif addr == REG_FULLSCALE:
            self.fullscale = value
        # REG_DATA / REG_ID are read only: the bits were consumed and are dropped.
        self._phase = _COMMS
        self._acc = self._nbits = 0

    def _on_read_done(self) -> None:
        if self._is_data_read:
            self.status |= 0x80  # /RDY returns high once the data register has been read
            # Exit instruction: 0x58 on DIN in the first 8 clocks of a continuous read.
            if self.cread and self._cmd_bits >= 8 and self._cmd == CMD_READ_DATA:
                self.cread = False
        self._phase = _COMMS
        self._acc = self._nbits = 0
        self._cmd, self._cmd_bits = 0, 0

    def _idle_dout(self) -> int:
        return (self.status >> 7) & 1

    def clock(self, din: int) -> int:
        """One SCLK period (mode 3): return the DOUT bit, then sample ``din`` (0 or 1;
        anything else is a :class:`FrameError`)."""
        if din.__class__ is not int or not (din == 0 or din == 1):
            din = as_bit(din, "DIN")
        # DOUT is shifted on the falling edge, before DIN is sampled on the rising edge.
        if self._phase == _READ:
            dout = (self._out >> (self._left - 1)) & 1
        elif self.cread and self._phase == _COMMS and self.ready:
            # Continuous read: clocks after /RDY falls read the data register directly.
            self._start_read(REG_DATA)
            dout = (self._out >> (self._left - 1)) & 1
        else:
            dout = self._idle_dout()
        # Reset detection runs on DIN regardless of the interface state.
        if din:
            self._ones += 1
            if self._ones >= RESET_ONES:
                self.reset()
                return dout
        else:
            self._ones = 0
        if self._phase == _READ:
            if self.cread and self._is_data_read and self._cmd_bits < 8:
                self._cmd, self._cmd_bits = (self._cmd << 1) | din, self._cmd_bits + 1
            self._left -= 1
            if self._left == 0:
                self._on_read_done()
        elif self._phase == _WRITE:
            self._acc = (self._acc << 1) | din
            self._nbits += 1
            if self._nbits == self._need:
                self._on_write_done()
        elif self.cread:
            pass  # continuous read waiting for /RDY: DIN is only watched during a read
        elif self._nbits == 0 and din:
            pass  # WEN = 1: the part stays at this bit until a 0 arrives
        else:
            self._acc = (self._acc << 1) | din
            self._nbits += 1
            if self._nbits == 8:
                byte, self._acc, self._nbits = self._acc, 0, 0
                self._on_comms(byte)
        return dout

    def _clock_byte(self, byte: int) -> int:
        """Eight clocks at once when the interface is byte aligned; else bit by bit."""
        ones = self._ones
        if byte == 0xFF:
            if ones + 8 >= RESET_ONES:
                return self._clock_bits(byte)
            new_ones = ones + 8
        else:
            if ones + _LEAD1[byte] >= RESET_ONES:
                return self._clock_bits(byte)
            new_ones = _TRAIL1[byte]
        phase = self._phase
        if phase == _READ and not self._left & 7:
            self._ones = new_ones
            self._left -= 8
            out = (self._out >> self._left) & 0xFF
            if self.cread and self._is_data_read and self._cmd_bits == 0:
                self._cmd, self._cmd_bits = byte, 8
            if self._left == 0:
                self._on_read_done()
            return out
        if self.cread:
            return self._clock_bits(byte)
        if phase == _WRITE and not self._nbits & 7:
            self._ones = new_ones
            dout = 0xFF if self.status & 0x80 else 0x00
            self._acc = (self._acc << 8) | byte
            self._nbits += 8
            if self._nbits == self._need:
                self._on_write_done()
            return dout
        if phase == _COMMS and self._nbits == 0 and not byte & 0x80:
            self._ones = new_ones
            dout = 0xFF if self.status & 0x80 else 0x00
            self._on_comms(byte)
            return dout
        return self._clock_bits(byte)

    def _clock_bits(self, byte: int) -> int:
        out = 0
        for k in range(7, -1, -1):
            out = (out << 1) | self.clock((byte >> k) & 1)
        return out

    def transfer(self, data: bytes) -> bytes:
        """Full-duplex transfer of whole bytes (MSB first); returns the bytes on DOUT."""
        cb = self._clock_byte
        return bytes([cb(b) for b in as_bytes(data, "SPI transfer data")])


# --------------------------------------------------------------------------------------
# Master (firmware view)
# --------------------------------------------------------------------------------------

Transfer = Callable[[bytes], bytes]


@dataclass
class AD7195Master:
    """Reads the strain force the way the FPGA/MCU firmware does.

    ``status_appended``: the firmware has set DAT_STA, so each data read clocks 32 bits and
    the status is checked (/RDY, ERR, channel, and parity if ``check_parity``).
    """

    full_scale_n: float = DEFAULT_FULL_SCALE_N
    status_appended: bool = True
    channel: int = 0
    check_parity: bool = False
    #: Byte clocked on DIN while reading (DIN must not reach 40 consecutive ones).
    fill: int = 0x00

    def __post_init__(self) -> None:
        n = 4 if self.status_appended else 3
        self._request = bytes([CMD_READ_DATA]) + bytes([self.fill]) * n
        self._scale = self.full_scale_n / MIDSCALE

    def data_read_request(self) -> bytes:
        """Bytes to clock on DIN for one data read: 0x58 then 3 or 4 fill bytes."""
        return self._request

    def parse_data_read(self, response: bytes) -> ForceSample:
        """Decode what DOUT carried during :meth:`data_read_request`.

        Raises :class:`FrameError` (wrong length, stale, wrong channel), :class:`RangeError`
        (ERR) or :class:`CrcError` (parity).
        """
        response = as_bytes(response, "data read response")
        if len(response) != len(self._request):
            raise FrameError(f"data read needs {len(self._request)} bytes, got {len(response)}")
        if self.status_appended:
            word = int.from_bytes(response[1:5], "big")
            code, status = word >> 8, word & 0xFF
            check_status(status, self.channel, code if self.check_parity else None)
        else:
            code, status = int.from_bytes(response[1:4], "big"), None
        return ForceSample((code - MIDSCALE) * self._scale, code, status)

    def read_force(self, transfer: Transfer) -> ForceSample:
        """One complete data read through ``transfer`` (e.g. ``device.transfer``)."""
        return self.parse_data_read(transfer(self._request))

    # ---- register access and start-up --------------------------------------------------
    @staticmethod
    def reset(transfer: Transfer) -> None:
        """Reset the part: 48 ones on DIN (>= 40 required)."""
        transfer(b"\xff" * 6)

    def read_register(self, transfer: Transfer, address: int) -> int:
        """Read register ``address`` (data: 24 bits, or 32 with status if appended)."""
        address = as_int(address, "register address", 0, 7)
        width = REG_WIDTH[address]
        if address == REG_DATA and self.status_appended:
            width = 32
        n = width // 8
        response = transfer(bytes([comms_byte(address, read=True)]) + bytes([self.fill]) * n)
        if len(response) != n + 1:
            raise FrameError("short response")
        return int.from_bytes(response[1:], "big")

    @staticmethod
    def write_register(transfer: Transfer, address: int, value: int) -> None:
        """Write ``value`` to a writable register (mode, config, GPOCON, offset, full-scale)."""
        if address not in (REG_MODE, REG_CONFIG, REG_GPOCON, REG_OFFSET, REG_FULLSCALE):
            raise RangeError(f"register {address!r} is not writable")
        n = REG_WIDTH[address] // 8
        value = as_int(value, f"register {address} value", 0, (1 << (8 * n)) - 1)
        transfer(bytes([comms_byte(address, read=False)]) + value.to_bytes(n, "big"))

    def start(
        self, transfer: Transfer, mode: Mode | None = None, config: Config | None = None
    ) -> int:
        """Firmware start-up: reset, check the ID, write config and mode. Returns the ID byte.

        Raises :class:`FrameError` if the ID's low nibble is not the AD7195's 0x6.
        """
        self.reset(transfer)
        ident = self.read_register(transfer, REG_ID)
        if ident & 0x0F != ID_PART_AD7195:
            raise FrameError(f"ID {ident:#04x} is not an AD7195 (low nibble 0x6)")
        cfg = config or Config(channels=1 << self.channel)
        md = mode or Mode(dat_sta=int(self.status_appended), enpar=int(self.check_parity))
        self.write_register(transfer, REG_CONFIG, cfg.encode())
        self.write_register(transfer, REG_MODE, md.encode())
        return ident


__all__ = [
    "AD7195Device",
    "AD7195Master",
    "BitRegister",
    "Comms",
    "Config",
    "DataBatch",
    "DataWord",
    "ForceSample",
    "Gpocon",
    "Mode",
    "Status",
    "check_status",
    "clamp_force_to_code",
    "code_to_force",
    "code_to_voltage",
    "comms_byte",
    "decode_data_words",
    "force_to_code",
    "parity_of",
    "voltage_to_code",
]
