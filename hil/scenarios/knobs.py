"""A scenario's own settings (knobs): what an experiment varies that is not the actuator.

A fault rate or the effect an identification record carries is not a property of the
actuator, so it has no key in the configuration. A scenario declares such settings as
:class:`Knob` s; they are addressed as ``scenario.NAME`` wherever configuration keys are
(``eha-hil run SCENARIO --set scenario.rate=0.02``, ``eha-hil sweep SCENARIO --param
scenario.rate=0:0.1:6``). Their values are checked here, in one place: type, range and
choices, with one :class:`plant.config.ConfigError` line naming the option and the key.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from plant.config import ConfigError, check_typed, parse_override

#: Keys under this section are a scenario's knobs; every other key is the configuration's.
PREFIX = "scenario."


@dataclass(frozen=True)
class Knob:
    """One setting of a scenario: its type is ``default``'s (bool, int, float or str)."""

    name: str
    default: Any
    help: str
    unit: str = ""
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        return PREFIX + self.name

    def check(self, value: Any, where: str) -> Any:
        """``value`` converted to the knob's type, or ConfigError naming ``where``."""
        value = check_typed(self.key, value, self.default, where, self.choices)
        if isinstance(value, bool | str):
            return value
        if not self.lo <= value <= self.hi:
            raise ConfigError(f"{where}: {self.key}: must be in [{self.lo:g}, {self.hi:g}]"
                              f"{' ' + self.unit if self.unit else ''}, got {value!r}")
        return value


def is_knob_key(key: str) -> bool:
    return key.startswith(PREFIX)


def resolve(knobs: Iterable[Knob], values: Mapping[str, Any], where: str,
            scenario: str) -> dict[str, Any]:
    """Every knob's value by name: ``values`` (keys ``scenario.NAME``) checked, defaults for
    the rest. An unknown ``scenario.*`` key is an error that lists the known ones."""
    table = {k.key: k for k in knobs}
    out = {k.name: k.default for k in table.values()}
    for key, value in values.items():
        knob = table.get(key)
        if knob is None:
            known = ", ".join(table) or "none"
            raise ConfigError(f"{where}: scenario {scenario} has no setting {key!r} "
                              f"(its settings: {known})")
        out[knob.name] = knob.check(value, where)
    return out


def split_sets(sets: Iterable[str]) -> tuple[list[str], dict[str, Any]]:
    """``--set`` items split into the configuration's (as given) and the scenario's
    (parsed: {``scenario.NAME``: value})."""
    config_sets: list[str] = []
    knob_values: dict[str, Any] = {}
    for item in sets:
        key, value = parse_override(item)
        if is_knob_key(key):
            knob_values[key] = value
        else:
            config_sets.append(item)
    return config_sets, knob_values


def split_overrides(overrides: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A point's overrides split into (configuration keys, ``scenario.*`` keys)."""
    config = {k: v for k, v in overrides.items() if not is_knob_key(k)}
    knobs = {k: v for k, v in overrides.items() if is_knob_key(k)}
    return config, knobs
