"""Actuator configuration: TOML presets shipped in the package, user files, CLI overrides.

``hydra_default.toml`` is the schema: every key a configuration may hold appears in it, with
a value whose type is the key's type. Other presets and user files are overlays on it. A
mistake (unknown key, wrong type, negative or non-finite number, bad choice, missing or
unparsable file) raises :class:`ConfigError` whose one-line message names the key and the
file, so the CLI can print it and exit with code 2.
"""

from __future__ import annotations

import copy
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

DEFAULT_PRESET = "hydra_default"

#: Keys whose numbers may be negative (positions about mid-stroke, phases, temperatures).
SIGNED_KEYS = frozenset(
    {
        "load.x0_m",
        "effects.pulsation.phase_rad",
        "effects.oil_temperature.reference_c",
        "effects.oil_temperature.initial_c",
        "effects.oil_temperature.ambient_c",
        "sensors.ssi_mount_rad",
        "sensors.hall_offset_rad",
    }
)

#: Keys that take one of a fixed set of strings.
CHOICES: dict[str, tuple[str, ...]] = {
    "load.kind": ("fixed", "free", "conrod", "cart"),
    "mcu.controller": ("current", "velocity"),
    "mcu.force_feedback": ("pressure", "strain", "complementary"),
}

#: Keys that must be strictly positive (a zero would divide or stall the clock).
POSITIVE_KEYS = frozenset(
    {
        "hydraulics.kp_m3_per_rad",
        "hydraulics.kq_m2",
        "hydraulics.kc_m2",
        "hydraulics.jp_kg",
        "hydraulics.jc_kg",
        "hydraulics.ds_ns_per_m",
        "hydraulics.ks_n_per_m",
        "hydraulics.ks_pipe_n_per_m",
        "hydraulics.bulk_modulus_pa",
        "hydraulics.stroke_m",
        "motor.pole_pairs",
        "motor.iq_rated_a",
        "motor.force_at_rated_n",
        "motor.inductance_h",
        "inverter.pwm_hz",
        "load.cart_mass_kg",
        "sim.tick_ns",
        "effects.pulsation.order",
        "effects.pump_coulomb.velocity_eps_m_per_s",
        "effects.seal_friction.velocity_eps_m_per_s",
        "effects.seal_friction.stribeck_velocity_m_per_s",
        "effects.oil_temperature.heat_capacity_j_per_k",
        "effects.strain_drift.rod_time_constant_s",
        "effects.quantisation.motor_counts_per_rev",
        "fpga.clock_hz",
        "fpga.current_full_scale_a",
        "fpga.watchdog_s",
        "fpga.speed_window_ticks",
        "fpga.lvds_bit_rate_hz",
        "sensors.ssi_bits",
        "sensors.abi_counts_per_rev",
        "sensors.biss_bits",
        "sensors.strain_full_scale_n",
        "sensors.strain_odr_hz",
        "sensors.temperature_v_per_c",
        "mcu.period_ticks",
        "mcu.derivative_filter_hz",
        "mcu.complementary_cutoff_hz",
        "mcu.seal_observer_hz",
        "mcu.command_timeout_s",
    }
)


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
    """The default preset, which doubles as the schema of every configuration."""
    return _read_toml_text(_preset_text(DEFAULT_PRESET), f"preset {DEFAULT_PRESET}")


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    for key, value in tree.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from _flatten(value, dotted + ".")
        else:
            yield dotted, value


def _check_value(key: str, value: Any, template: Any, where: str) -> Any:
    """Return ``value`` converted to the template's type, or raise ConfigError."""
    if isinstance(template, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: {key}: expected true or false, got {value!r}")
        return value
    if isinstance(template, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}: {key}: expected a string, got {value!r}")
        choices = CHOICES.get(key)
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
    if key not in SIGNED_KEYS and value < 0:
        raise ConfigError(f"{where}: {key}: must not be negative, got {value!r}")
    if key in POSITIVE_KEYS and value == 0:
        raise ConfigError(f"{where}: {key}: must be greater than zero")
    return value


def _set_checked(data: dict[str, Any], key: str, value: Any, where: str) -> None:
    parts = key.split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        if not isinstance(node, dict) or part not in node or not isinstance(node[part], dict):
            raise ConfigError(f"{where}: unknown section '{'.'.join(parts[: i + 1])}'")
        node = node[part]
    leaf = parts[-1]
    if not isinstance(node, dict) or leaf not in node or isinstance(node[leaf], dict):
        known = ", ".join(k for k, v in node.items() if not isinstance(v, dict))
        raise ConfigError(f"{where}: unknown key '{key}' (known here: {known})")
    node[leaf] = _check_value(key, value, node[leaf], where)


def _overlay(base: dict[str, Any], tree: Mapping[str, Any], where: str) -> None:
    for key, value in _flatten(tree):
        _set_checked(base, key, value, where)


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
    half = data["hydraulics"]["stroke_m"] / 2
    if abs(data["load"]["x0_m"]) > half:
        raise ConfigError(f"{where}: load.x0_m: outside the stroke (+/- {half} m)")


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
            if not path.is_file():
                raise ConfigError(f"{where}: no such file (and not a preset name)")
            try:
                text = path.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise ConfigError(f"{where}: cannot read: {exc}") from None
            tree = _read_toml_text(text, where)
        _overlay(data, tree, where)
        _check_consistency(data, where)
        sources.append(where)
    for item in overrides:
        key, value = parse_override(item)
        where = f"--set {key}"
        _set_checked(data, key, value, where)
        _check_consistency(data, where)
        sources.append(where)
    _check_consistency(data, sources[-1])
    return Config(data, sources)
