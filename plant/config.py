"""Actuator configuration: TOML presets shipped in the package, user files, CLI overrides.

``hydra_default.toml`` is the schema: every key a configuration may hold appears in it, with
a value whose type is the key's type; :data:`RANGES` holds each number's range. Other
presets and user files are overlays on it. A mistake (unknown key, wrong type, non-finite
number or one outside its range, bad choice, missing, empty or unparsable file, a file that
is not ``.toml``) raises :class:`ConfigError` whose one-line message names the key and the
file, so the CLI can print it and exit with code 2.
"""

from __future__ import annotations

import copy
import math
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from firmware_model.fpga.layout import ANALOG_INPUTS

DEFAULT_PRESET = "hydra_default"

#: The newest of the plant kernel's arithmetic recipes (``sim.plant_numerics``, docs/plant.md).
#: A recipe changes rounding and the noise realisation, never the model; a run keeps the
#: recipe it was recorded with, so its log replays bit for bit.
PLANT_NUMERICS = 4
#: Values of keys that a configuration recorded before the key existed ran with.
RECORDED_BEFORE: dict[str, Any] = {
    "sim.plant_numerics": 1,
    # Runs recorded before entrained air existed had none (the fraction is then unused).
    "effects.entrained_air.enabled": False,
    "effects.entrained_air.volume_fraction": 0.01,
    # Read only by the F1 and F6 scenarios, never by a plant a log recorded.
    "load.beam_reinforced_axial_stiffness_n_per_m": 5.813e6,
}

#: Keys that take one of a fixed set of strings.
CHOICES: dict[str, tuple[str, ...]] = {
    "load.kind": ("fixed", "free", "conrod", "cart"),
    "mcu.controller": ("current", "velocity"),
    "mcu.force_feedback": ("pressure", "strain", "complementary"),
    "mcu.impl": ("python", "c", "image"),
    "fpga.impl": ("python", "rtl"),
}


@dataclass(frozen=True)
class Range:
    """The values a numeric key may take: ``lo <= v <= hi`` (``lo < v`` when ``open_lo``).

    Bounds are physical plausibility, not design limits: wide enough for any actuator of
    this kind, narrow enough that the models' arithmetic (divisions, fixed-point scaling,
    array sizes) stays meaningful.
    """

    lo: float
    hi: float
    open_lo: bool = False


def _pos(hi: float) -> Range:
    """Greater than zero (a zero would divide or stall the clock), at most ``hi``."""
    return Range(0.0, hi, open_lo=True)


def _span(lo: float, hi: float) -> Range:
    return Range(lo, hi)


#: Range of every numeric key of the schema (a test checks that none is missing).
#: Negative values are allowed only where the key says a position, phase or temperature.
RANGES: dict[str, Range] = {
    # hydraulics
    "hydraulics.kp_m3_per_rad": _pos(1e-5),
    "hydraulics.kq_m2": _pos(1e-2),
    "hydraulics.kc_m2": _pos(1e-2),
    "hydraulics.jp_kg": _pos(1e5),
    "hydraulics.jc_kg": _pos(1e4),
    "hydraulics.dp_ns_per_m": _span(0.0, 1e8),
    "hydraulics.dc_ns_per_m": _span(0.0, 1e8),
    "hydraulics.ds_ns_per_m": _pos(1e10),
    "hydraulics.ks_n_per_m": _pos(1e11),
    "hydraulics.ks_pipe_n_per_m": _pos(1e12),
    "hydraulics.bulk_modulus_pa": _pos(1e11),
    "hydraulics.dead_volume_m3": _span(0.0, 1e-2),
    "hydraulics.pipe_volume_m3": _span(0.0, 1e-2),
    "hydraulics.stroke_m": _pos(2.0),
    "hydraulics.precharge_pa": _span(0.0, 1e8),
    "hydraulics.force_limit_n": _pos(1e6),
    # motor
    "motor.pole_pairs": _span(1, 64),
    "motor.iq_rated_a": _pos(1e3),
    "motor.force_at_rated_n": _pos(1e5),
    "motor.resistance_ohm": _span(0.0, 100.0),
    "motor.inductance_h": _pos(1.0),
    # inverter
    "inverter.dc_bus_v": _span(1.0, 1000.0),
    "inverter.pwm_hz": _span(1e3, 2e5),
    "inverter.dead_time_s": _span(0.0, 1e-3),
    "inverter.duty_min": _span(0.0, 1.0),
    "inverter.duty_max": _span(0.0, 1.0),
    "inverter.dead_time_current_a": _span(0.0, 1e3),
    # load
    "load.conrod_stiffness_n_per_m": _pos(1e11),
    "load.conrod_damping_ns_per_m": _span(0.0, 1e8),
    "load.beam_axial_stiffness_n_per_m": _pos(1e11),
    "load.beam_reinforcement_ratio": _pos(1e3),
    "load.beam_reinforced_axial_stiffness_n_per_m": _pos(1e11),
    "load.cart_mass_kg": _pos(1e5),
    "load.cart_damping_ns_per_m": _span(0.0, 1e8),
    "load.x0_m": _span(-1.0, 1.0),
    # sim
    "sim.tick_ns": _span(1_000, 1_000_000),
    "sim.substeps": _span(0, 1000),
    "sim.seed": _span(0, 2**32 - 1),
    "sim.plant_numerics": _span(1, PLANT_NUMERICS),
    # effects
    "effects.pulsation.order": _span(1, 64),
    "effects.pulsation.amplitude": _span(0.0, 1.0),
    "effects.pulsation.phase_rad": _span(-2 * math.pi, 2 * math.pi),
    "effects.pulsation.torque_n": _span(0.0, 1e5),
    "effects.pulsation.torque_amplitude": _span(0.0, 1.0),
    "effects.pump_coulomb.force_n": _span(0.0, 1e5),
    "effects.pump_coulomb.velocity_eps_m_per_s": _pos(10.0),
    "effects.seal_friction.coulomb_n": _span(0.0, 1e5),
    "effects.seal_friction.static_n": _span(0.0, 1e5),
    "effects.seal_friction.stribeck_velocity_m_per_s": _pos(10.0),
    "effects.seal_friction.velocity_eps_m_per_s": _pos(10.0),
    "effects.entrained_air.volume_fraction": _span(0.0, 0.2),
    "effects.oil_temperature.reference_c": _span(-40.0, 150.0),
    "effects.oil_temperature.initial_c": _span(-40.0, 150.0),
    "effects.oil_temperature.viscosity_coeff_per_c": _span(0.0, 0.1),
    "effects.oil_temperature.heat_capacity_j_per_k": _pos(1e8),
    "effects.oil_temperature.cooling_w_per_k": _span(0.0, 1e6),
    "effects.oil_temperature.ambient_c": _span(-40.0, 150.0),
    "effects.strain_drift.n_per_c": _span(0.0, 1e4),
    "effects.strain_drift.rod_time_constant_s": _pos(1e6),
    "effects.sensor_noise.pressure_pa": _span(0.0, 1e7),
    "effects.sensor_noise.strain_n": _span(0.0, 1e5),
    "effects.sensor_noise.temperature_c": _span(0.0, 100.0),
    "effects.quantisation.motor_counts_per_rev": _span(1, 1 << 24),
    "effects.quantisation.piston_lsb_m": _span(0.0, 1e-3),
    "effects.quantisation.pressure_lsb_pa": _span(0.0, 1e6),
    "effects.quantisation.strain_lsb_n": _span(0.0, 1e3),
    "effects.quantisation.temperature_lsb_c": _span(0.0, 10.0),
    # fpga
    "fpga.clock_hz": _span(1_000_000, 1_000_000_000),
    "fpga.current_full_scale_a": _pos(1e4),
    "fpga.current_kp_v_per_a": _span(0.0, 1e3),
    "fpga.current_ki_v_per_a_s": _span(0.0, 1e7),
    "fpga.current_limit_a": _span(0.0, 1e4),
    "fpga.trip_current_a": _pos(1e4),
    "fpga.watchdog_s": _pos(10.0),
    "fpga.speed_window_ticks": _span(1, 256),
    "fpga.lvds_bit_rate_hz": _span(100_000, 1_000_000_000),
    # sensors
    "sensors.ssi_bits": _span(1, 16),
    "sensors.ssi_mount_rad": _span(-2 * math.pi, 2 * math.pi),
    "sensors.abi_counts_per_rev": _span(4, 1 << 24),
    "sensors.biss_bits": _span(18, 36),
    "sensors.biss_zero_count": _span(0, (1 << 36) - 1),
    "sensors.strain_full_scale_n": _pos(1e6),
    "sensors.strain_odr_hz": _span(1, 4800),
    "sensors.temperature_v_at_0c": _span(0.0, 10.0),
    "sensors.temperature_v_per_c": _pos(1.0),
    "sensors.hall_offset_rad": _span(-2 * math.pi, 2 * math.pi),
    # mcu
    "mcu.period_ticks": _span(1, 20),
    "mcu.kp_force": _span(0.0, 1e3),
    "mcu.kd_force_s": _span(0.0, 10.0),
    "mcu.derivative_filter_hz": _pos(1e5),
    "mcu.friction_observer_hz": _span(0.0, 1e4),
    "mcu.vel_kp_n_per_m_s": _span(0.0, 1e9),
    "mcu.vel_ki_n_per_m": _span(0.0, 1e12),
    "mcu.vel_force_kp_m_s_per_n": _span(0.0, 1.0),
    "mcu.vel_force_ki_m_per_n": _span(0.0, 1e3),
    "mcu.complementary_cutoff_hz": _pos(1e3),
    "mcu.seal_observer_hz": _pos(1e4),
    "mcu.position_kp_n_per_m": _span(0.0, 1e9),
    "mcu.conrod_length_m": _span(0.0, 10.0),
    "mcu.conrod_offset_m": _span(0.0, 10.0),
    "mcu.force_limit_n": _span(0.0, 1e6),
    "mcu.pressure_limit_pa": _span(0.0, 1e9),
    "mcu.current_limit_a": _span(0.0, 1e4),
    "mcu.command_timeout_s": _pos(100.0),
    "mcu.safe_off_delay_s": _span(0.0, 100.0),
}

#: The firmware calibration set's nominal values (``[firmware]``) and the plant key each
#: stands for. A preset or file that sets the plant key and not the firmware one gets
#: firmware built for its actuator; ``--set`` and ``with_overrides`` change only what they
#: name. A log written before ``[firmware]`` existed is read with these (its firmware was
#: built from the plant's values then).
FIRMWARE_NOMINAL: dict[str, str] = {
    "firmware.kc_m2": "hydraulics.kc_m2",
    "firmware.kp_m3_per_rad": "hydraulics.kp_m3_per_rad",
    "firmware.jp_kg": "hydraulics.jp_kg",
    "firmware.force_at_rated_n": "motor.force_at_rated_n",
    "firmware.iq_rated_a": "motor.iq_rated_a",
    "firmware.pole_pairs": "motor.pole_pairs",
    "firmware.dc_bus_v": "inverter.dc_bus_v",
    "firmware.pwm_hz": "inverter.pwm_hz",
    "firmware.strain_full_scale_n": "sensors.strain_full_scale_n",
    "firmware.temperature_v_at_0c": "sensors.temperature_v_at_0c",
    "firmware.temperature_v_per_c": "sensors.temperature_v_per_c",
    "firmware.ssi_mount_rad": "sensors.ssi_mount_rad",
    "firmware.biss_zero_count": "sensors.biss_zero_count",
    "firmware.abi_counts_per_rev": "sensors.abi_counts_per_rev",
}
#: Keys an analog sensor declares in its row of ``ANALOG_INPUTS`` rather than in the preset:
#: its true scales (``sensors.<key>``) and the firmware's (``firmware.<key>``), with the
#: same default and range; and whether the part is fitted (``sensors.<key>``, false).
DECLARED: dict[str, Any] = {}
for _a in ANALOG_INPUTS:
    for _name, _default, _lo, _hi in _a.keys:
        for _section in ("sensors", "firmware"):
            DECLARED[f"{_section}.{_name}"] = float(_default)
            RANGES[f"{_section}.{_name}"] = _span(_lo, _hi)
        FIRMWARE_NOMINAL[f"firmware.{_name}"] = f"sensors.{_name}"
    if _a.fitted_key is not None:
        DECLARED[f"sensors.{_a.fitted_key}"] = False
RANGES.update({fw: RANGES[plant] for fw, plant in FIRMWARE_NOMINAL.items()})
#: Keys that choose how a model is run, not what it computes (``mcu.impl``: the Python MCU,
#: its bit-identical C build or a firmware image; ``mcu.image``: which image; ``fpga.impl``:
#: the board's current loop or its RTL): a log written before one existed replays with its
#: default.
RUN_CHOICES = ("mcu.impl", "mcu.image", "fpga.impl", "fpga.rtl_dir")

class ConfigError(Exception):
    """A configuration mistake; ``str(err)`` is one line naming the key and the file."""


@dataclass
class Config:
    """A validated actuator configuration: nested sections of plain values.

    ``sources`` says, for display and error messages, which files and overrides made it.
    """

    data: dict[str, Any]
    sources: list[str] = field(default_factory=list)

    def get(self, dotted: str) -> Any:
        """Value at a dotted key such as ``"hydraulics.kc_m2"``."""
        node: Any = self.data
        for part in dotted.split("."):
            node = node[part]
        return node

    def section(self, dotted: str) -> dict[str, Any]:
        """A section as a dict (e.g. ``"effects.pulsation"``)."""
        sec = self.get(dotted)
        if not isinstance(sec, dict):
            raise KeyError(dotted)
        return sec

    def with_overrides(self, overrides: Mapping[str, Any], source: str = "override") -> Config:
        """A copy with dotted-key values replaced and validated (values already typed)."""
        data = copy.deepcopy(self.data)
        for key, value in overrides.items():
            _set_checked(data, key, value, source)
        # The rules between keys hold for an override as for a file (a sweep point, a
        # scenario's variant): each key alone in range is not enough.
        _check_consistency(data, source)
        return Config(data, [*self.sources, source])


def linearised(cfg: Config) -> Config:
    """The same actuator with every effect switched off: the thesis's linear model."""
    off = {f"effects.{name}.enabled": False for name in cfg.section("effects")}
    return cfg.with_overrides(off, source="all effects off")


def preset_names() -> list[str]:
    """Names of the presets shipped in :mod:`plant.presets`."""
    files = resources.files("plant.presets").iterdir()
    return sorted(p.name[:-5] for p in files if p.name.endswith(".toml"))


def _read_toml_text(text: str, where: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: not valid TOML: {exc}") from None


def _preset_text(name: str) -> str:
    res = resources.files("plant.presets").joinpath(f"{name}.toml")
    if not res.is_file():
        known = ", ".join(preset_names())
        raise ConfigError(f"preset '{name}': no such preset (known: {known})")
    return res.read_text(encoding="utf-8")


def schema() -> dict[str, Any]:
    """The default preset, which doubles as the schema of every configuration, with the
    keys the sensors declare (:data:`DECLARED`) where it does not hold them."""
    tree = _read_toml_text(_preset_text(DEFAULT_PRESET), f"preset {DEFAULT_PRESET}")
    for dotted, default in DECLARED.items():
        section, key = dotted.split(".")
        tree[section].setdefault(key, default)
    return tree


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    for key, value in tree.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from _flatten(value, dotted + ".")
        else:
            yield dotted, value


def _check_value(key: str, value: Any, template: Any, where: str) -> Any:
    """Return ``value`` converted to the template's type, or raise ConfigError."""
    value = check_typed(key, value, template, where, CHOICES.get(key))
    if isinstance(template, int | float) and not isinstance(template, bool):
        _check_range(key, value, where)
    return value


def check_typed(key: str, value: Any, template: Any, where: str,
                choices: Sequence[str] | None = None) -> Any:
    """``value`` as the type of ``template`` (bool, str within ``choices``, int, finite
    float), or ConfigError naming ``where`` and ``key``. Ranges are the caller's."""
    if isinstance(template, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: {key}: expected true or false, got {value!r}")
        return value
    if isinstance(template, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}: {key}: expected a string, got {value!r}")
        if choices and value not in choices:
            raise ConfigError(f"{where}: {key}: '{value}' is not one of {', '.join(choices)}")
        return value
    if isinstance(template, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: {key}: expected an integer, got {value!r}")
    elif isinstance(template, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: {key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{where}: {key}: must be finite, got {value!r}")
    return value


def _check_range(key: str, value: float, where: str) -> None:
    # A key missing from RANGES (a test prevents that) is at least kept non-negative.
    rng = RANGES.get(key, Range(0.0, math.inf))
    if rng.lo == 0 and value < 0:
        raise ConfigError(f"{where}: {key}: must not be negative, got {value!r}")
    if rng.open_lo and value <= rng.lo:
        raise ConfigError(f"{where}: {key}: must be greater than {rng.lo:g}, got {value!r}")
    if value < rng.lo:
        raise ConfigError(f"{where}: {key}: must be at least {rng.lo:g}, got {value!r}")
    if value > rng.hi:
        raise ConfigError(f"{where}: {key}: must be at most {rng.hi:g}, got {value!r}")


def _set_checked(data: dict[str, Any], key: str, value: Any, where: str) -> None:
    parts = key.split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        if not isinstance(node, dict) or part not in node or not isinstance(node[part], dict):
            raise ConfigError(f"{where}: unknown section '{'.'.join(parts[: i + 1])}'")
        node = node[part]
    leaf = parts[-1]
    if isinstance(node, dict) and isinstance(node.get(leaf), dict):
        # a section, not a value: say what it holds (e.g. effects.pulsation=3)
        inner = ", ".join(f"{key}.{k}" for k, v in node[leaf].items() if not isinstance(v, dict))
        raise ConfigError(f"{where}: '{key}' is a section, not a value; give one of its keys: "
                          f"{inner or 'none (it holds only sections)'}")
    if not isinstance(node, dict) or leaf not in node:
        keys = [k for k, v in node.items() if not isinstance(v, dict)] if isinstance(
            node, dict) else []
        subs = [f"[{k}]" for k, v in node.items() if isinstance(v, dict)] if isinstance(
            node, dict) else []
        known = ", ".join(keys + subs) or "none"
        raise ConfigError(f"{where}: unknown key '{key}' (known here: {known})")
    node[leaf] = _check_value(key, value, node[leaf], where)


def _overlay(base: dict[str, Any], tree: Mapping[str, Any], where: str) -> None:
    """Apply a preset's or file's keys; its actuator's firmware follows (FIRMWARE_NOMINAL)."""
    given = dict(_flatten(tree))
    for key, value in given.items():
        _set_checked(base, key, value, where)
    for fw, plant in FIRMWARE_NOMINAL.items():
        if plant in given and fw not in given:
            _set_checked(base, fw, given[plant], where)


def as_recorded(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Flat keys of a configuration read from a log, completed with what its run used for
    the keys it predates: the nominal firmware (:func:`with_nominal_firmware`) and the
    values of :data:`RECORDED_BEFORE`."""
    out = with_nominal_firmware(flat)
    for key, value in RECORDED_BEFORE.items():
        out.setdefault(key, value)
    return out


def with_nominal_firmware(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Flat keys of a configuration written before ``[firmware]`` existed, completed with
    the firmware its run was built with: the plant's values (FIRMWARE_NOMINAL)."""
    out = dict(flat)
    for fw, plant in FIRMWARE_NOMINAL.items():
        if fw not in out and plant in out:
            out[fw] = out[plant]
    return out


#: Smallest viscosity ratio mu(T)/mu_ref (initial and ambient oil temperature) the plant
#: runs with: the fixed-step integration of the leakage diverges below it.
VISCOSITY_RATIO_MIN = 0.01


def _check_consistency(data: dict[str, Any], where: str) -> None:
    inv = data["inverter"]
    if inv["duty_min"] >= inv["duty_max"] or inv["duty_max"] > 1.0:
        raise ConfigError(f"{where}: inverter.duty_min/duty_max: need 0 <= min < max <= 1")
    if inv["dead_time_s"] * inv["pwm_hz"] >= 0.5:
        raise ConfigError(f"{where}: inverter.dead_time_s: longer than half a PWM period")
    fpga = data["fpga"]
    window = fpga["speed_window_ticks"]
    if window & (window - 1) or window > 256:
        raise ConfigError(f"{where}: fpga.speed_window_ticks: need a power of two <= 256")
    sens = data["sensors"]
    if not 1 <= sens["ssi_bits"] <= 16:
        raise ConfigError(f"{where}: sensors.ssi_bits: need 1..16")
    if sens["biss_bits"] not in (18, 26, 32, 36):
        raise ConfigError(f"{where}: sensors.biss_bits: need 18, 26, 32 or 36")
    if sens["biss_zero_count"] >= 1 << sens["biss_bits"]:
        raise ConfigError(f"{where}: sensors.biss_zero_count: beyond the {sens['biss_bits']}"
                          "-bit scale")
    if data["firmware"]["biss_zero_count"] >= 1 << sens["biss_bits"]:
        raise ConfigError(f"{where}: firmware.biss_zero_count: beyond the {sens['biss_bits']}"
                          "-bit scale")
    mcu = data["mcu"]
    mcu_dt = mcu["period_ticks"] * data["sim"]["tick_ns"] * 1e-9
    f_max = 1.0 / (math.pi * mcu_dt)
    if mcu["friction_observer_hz"] >= f_max:
        # The discrete momentum observer r += k_o dt (...) diverges once k_o dt >= 2.
        raise ConfigError(f"{where}: mcu.friction_observer_hz: need less than {f_max:.0f} Hz "
                          "at this MCU period (the discrete observer diverges)")
    if mcu["conrod_length_m"] > 0 and mcu["conrod_offset_m"] >= mcu["conrod_length_m"]:
        # cos(alpha) = sqrt(1 - (d/l)^2) of Eq. 6.5 needs a rod longer than its offset.
        raise ConfigError(f"{where}: mcu.conrod_offset_m: need less than mcu.conrod_length_m")
    half = data["hydraulics"]["stroke_m"] / 2
    if abs(data["load"]["x0_m"]) > half:
        raise ConfigError(f"{where}: load.x0_m: outside the stroke (+/- {half} m)")
    oil = data["effects"]["oil_temperature"]
    if oil["enabled"]:
        # Below ~1 % of their table values the dampers no longer hold the fixed-step plant.
        for key in ("initial_c", "ambient_c"):
            ratio = math.exp(-oil["viscosity_coeff_per_c"] * (oil[key] - oil["reference_c"]))
            if ratio < VISCOSITY_RATIO_MIN:
                raise ConfigError(
                    f"{where}: effects.oil_temperature.{key}: {oil[key]} degC makes the oil "
                    f"{1 / ratio:.0f}x thinner than at reference_c {oil['reference_c']} degC; "
                    f"the plant needs mu(T)/mu_ref >= {VISCOSITY_RATIO_MIN}")


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``section.key=value`` (value as a TOML literal, bare words as strings)."""
    if "=" not in text:
        raise ConfigError(f"--set {text}: expected section.key=value")
    key, raw = (s.strip() for s in text.split("=", 1))
    if not key or "." not in key:
        raise ConfigError(f"--set {text}: expected section.key=value")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # bare word such as free / conrod
    return key, value


def load_config(
    source: str | Path | None = None, overrides: Iterable[str] = ()
) -> Config:
    """Build a validated configuration.

    ``source`` is a preset name (see :func:`preset_names`), a path to a TOML file, or None
    for the default preset. ``overrides`` are ``section.key=value`` strings applied last.
    """
    data = schema()
    sources = [f"preset {DEFAULT_PRESET}"]
    if source is not None and str(source) != DEFAULT_PRESET:
        text_source = str(source)
        if text_source in preset_names():
            where = f"preset {text_source}"
            tree = _read_toml_text(_preset_text(text_source), where)
        else:
            path = Path(text_source)
            where = str(path)
            if path.is_dir():
                raise ConfigError(f"{where}: is a directory, not a TOML file")
            if not path.is_file():
                raise ConfigError(f"{where}: no such file (and not a preset name)")
            if path.suffix.lower() != ".toml":
                # A data file given by mistake can parse as (empty) TOML and mean nothing.
                raise ConfigError(f"{where}: not a configuration file (expected NAME.toml)")
            try:
                text = path.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise ConfigError(f"{where}: cannot read: {exc}") from None
            if not text.strip():
                raise ConfigError(f"{where}: is empty (a configuration file holds the keys "
                                  "that differ from hydra_default)")
            tree = _read_toml_text(text, where)
        _overlay(data, tree, where)
        _check_consistency(data, where)
        sources.append(where)
    for item in overrides:
        key, value = parse_override(item)
        where = f"--set {key}"
        _set_checked(data, key, value, "--set")  # its messages name the key themselves
        _check_consistency(data, where)
        sources.append(where)
    _check_consistency(data, sources[-1])
    return Config(data, sources)
