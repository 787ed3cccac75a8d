"""The firmware calibration set: the numbers the FPGA and MCU programs are built with.

Real firmware does not know the actuator it drives; it is compiled (or flashed) with nominal
values: the pump inertia J_p the momentum observer uses, the torque constant that turns a
force into a current reference, the piston area that turns pressures into a force, the
sensor scales that turn codes into SI units. This dataclass is that set. Every model in
:mod:`firmware_model` is built from it and from nothing else, so it never reads the plant's
true parameters; a scenario can run firmware built for one actuator on a plant that differs
(the study that calibration from measured data is for).

Where the numbers come from (:meth:`FirmwareCalibration.from_config`):

* ``[firmware]``: the actuator's nominal values and the sensor scales. A preset or
  configuration file describes an actuator, so a key it leaves out follows the plant value
  the same file gives (``plant.config.FIRMWARE_NOMINAL``); ``--set`` and
  ``Config.with_overrides`` change only the key they name, so ``--set hydraulics.jp_kg=130``
  changes the plant and leaves the firmware built for 118 kg;
* ``[fpga]`` and ``[mcu]``: the programs' own settings (gains, limits, timing);
* ``[sensors]``: only the data formats both ends of a sensor link agree on (bit widths and
  output data rate), which are facts of the part, not calibrations;
* ``sim.tick_ns``: the board clock's tick.

The builder takes anything with ``get(dotted_key)`` and ``section(name)``, so this package
does not import the configuration code of :mod:`plant`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Protocol

from firmware_model.fpga.layout import ANALOG_INPUTS


class _ConfigLike(Protocol):
    def get(self, dotted: str) -> Any: ...

    def section(self, dotted: str) -> dict[str, Any]: ...


@dataclass(frozen=True)
class FirmwareCalibration:
    """What the FPGA and MCU are built with; SI units as in the configuration's keys."""

    # Actuator, nominal (piston-equivalent where the plant's keys are).
    kc_m2: float               # piston area: pressures -> force
    kp_m3_per_rad: float       # pump displacement per rad: rotor speed -> pump velocity
    jp_kg: float               # pump + rotor inertia seen from the piston (observer)
    force_at_rated_n: float    # piston force at iq_rated_a: the torque constant
    iq_rated_a: float
    pole_pairs: int
    dc_bus_v: float            # the board's voltage scaling
    pwm_hz: float              # the board's PWM carrier
    # Sensor scales the programs decode with.
    strain_full_scale_n: float
    #: Analog input name -> (volts at zero, gain) the MCU decodes it with (``ANALOG_INPUTS``).
    analog: Mapping[str, tuple[float, float]]
    ssi_mount_rad: float       # the PC's calibration table: SSI zero against the d axis
    biss_zero_count: int       # piston encoder count at mid-stroke
    abi_counts_per_rev: int
    # Data formats of the sensor parts (both ends of the link agree on them).
    ssi_bits: int
    biss_bits: int
    strain_odr_hz: int
    # The programs' own settings, and the clock.
    fpga: Mapping[str, Any]
    mcu: Mapping[str, Any]
    tick_ns: int

    @property
    def kt_eq_n_per_a(self) -> float:
        """Torque constant seen from the piston, N per q-axis A."""
        return self.force_at_rated_n / self.iq_rated_a

    @property
    def kt_nm_per_a(self) -> float:
        """Motor torque constant, Nm per q-axis A (through k_p / k_c)."""
        return self.force_at_rated_n * (self.kp_m3_per_rad / self.kc_m2) / self.iq_rated_a

    @property
    def tick_s(self) -> float:
        return self.tick_ns * 1e-9

    @classmethod
    def from_config(cls, cfg: _ConfigLike) -> FirmwareCalibration:
        """The calibration set of a configuration (see the module docstring)."""
        fw = cfg.section("firmware")
        s = cfg.section("sensors")
        return cls(
            kc_m2=fw["kc_m2"], kp_m3_per_rad=fw["kp_m3_per_rad"], jp_kg=fw["jp_kg"],
            force_at_rated_n=fw["force_at_rated_n"], iq_rated_a=fw["iq_rated_a"],
            pole_pairs=fw["pole_pairs"], dc_bus_v=fw["dc_bus_v"], pwm_hz=fw["pwm_hz"],
            strain_full_scale_n=fw["strain_full_scale_n"],
            analog=MappingProxyType({a.name: a.scales(fw) for a in ANALOG_INPUTS}),
            ssi_mount_rad=fw["ssi_mount_rad"], biss_zero_count=fw["biss_zero_count"],
            abi_counts_per_rev=fw["abi_counts_per_rev"],
            ssi_bits=s["ssi_bits"], biss_bits=s["biss_bits"], strain_odr_hz=s["strain_odr_hz"],
            fpga=MappingProxyType(dict(cfg.section("fpga"))),
            mcu=MappingProxyType(dict(cfg.section("mcu"))),
            tick_ns=cfg.get("sim.tick_ns"),
        )


def calibration(source: FirmwareCalibration | _ConfigLike) -> FirmwareCalibration:
    """``source`` itself if it is a calibration set, else the set of that configuration."""
    if isinstance(source, FirmwareCalibration):
        return source
    return FirmwareCalibration.from_config(source)
