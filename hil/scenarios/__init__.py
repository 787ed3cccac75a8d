"""Scenarios: named experiments on the simulated stack, run by ``eha-hil run NAME``.

A scenario takes a configuration and returns a :class:`ScenarioResult`: metrics (value,
unit, the requirement it is held to), the time series or frequency response behind them,
and a plot. Figures always come out of the simulation; requirements are stated beside them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hil.scenarios.knobs import Knob, resolve
from plant.config import Config, ConfigError


@dataclass
class Metric:
    """One figure of a scenario: ``value`` in ``unit``; ``ok`` is None when not judged."""

    name: str
    value: float
    unit: str
    requirement: str = ""
    ok: bool | None = None
    thesis: float | None = None  # the thesis's figure in the same unit, when there is one


@dataclass
class ScenarioResult:
    """What a scenario run produced."""

    name: str
    title: str
    metrics: list[Metric]
    series: dict[str, Any] = field(default_factory=dict)
    plot: Callable[[ScenarioResult, Path], None] | None = None
    notes: list[str] = field(default_factory=list)

    def metric(self, name: str) -> Metric:
        """A metric by name; KeyError lists the names there are."""
        for m in self.metrics:
            if m.name == name:
                return m
        raise KeyError(f"{self.name}: no metric {name!r} (have {[m.name for m in self.metrics]})")

    @property
    def ok(self) -> bool:
        """True when no judged metric failed its requirement."""
        return all(m.ok is not False for m in self.metrics)


Progress = Callable[[int, int], None] | None
Runner = Callable[[Config, Progress], ScenarioResult]


@dataclass(frozen=True)
class Scenario:
    """A named experiment. ``knobs``: its own settings (:mod:`hil.scenarios.knobs`); a
    scenario with knobs is run as ``run(cfg, progress, values)`` with every knob's value by
    name, one without as ``run(cfg, progress)``."""

    name: str
    summary: str
    run: Callable[..., ScenarioResult]
    knobs: tuple[Knob, ...] = ()
    #: Checks the knobs together (raises ConfigError), e.g. a fault kind against its link.
    validate: Callable[[dict[str, Any]], None] | None = None

    def settings(self, knob_values: Mapping[str, Any], where: str) -> dict[str, Any]:
        """Every knob's value by name from ``knob_values`` ({``scenario.NAME``: value}) and
        the defaults, checked one by one and together; ConfigError naming ``where``."""
        values = resolve(self.knobs, knob_values, where, self.name)
        if self.validate is not None:
            try:
                self.validate(values)
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
        return values

    def call(self, cfg: Config, progress: Progress = None,
             knob_values: Mapping[str, Any] | None = None,
             where: str = "--set") -> ScenarioResult:
        """Run on ``cfg`` with ``knob_values`` ({``scenario.NAME``: value}, checked here)."""
        values = self.settings(knob_values or {}, where)
        if not self.knobs:
            return self.run(cfg, progress)
        return self.run(cfg, progress, values)


SCENARIOS: dict[str, Scenario] = {}


def register(name: str, validate: Callable[[dict[str, Any]], None] | None = None
             ) -> Callable[[Callable[..., ScenarioResult]], Callable[..., ScenarioResult]]:
    """Decorator adding a scenario runner to :data:`SCENARIOS` under ``name``, a name of
    :data:`hil.scenarios.catalog.CATALOG` (its summary and settings come from there), with
    the settings' joint check ``validate`` (:class:`Scenario`)."""
    from hil.scenarios.catalog import CATALOG

    entry = CATALOG[name]  # a KeyError here: list the scenario in hil/scenarios/catalog.py

    def deco(fn: Callable[..., ScenarioResult]) -> Callable[..., ScenarioResult]:
        SCENARIOS[name] = Scenario(name, entry.summary, fn, entry.knobs, validate)
        return fn

    return deco


def get(name: str) -> Scenario:
    """A scenario by name; KeyError with the list of known names (:func:`check_name`)."""
    check_name(name)
    _load_all()
    return SCENARIOS[name]


def check_name(name: str) -> None:
    """KeyError with the list of known names unless ``name`` is a scenario's: one of the
    catalogue (its module not loaded yet: that loads the simulation) or one put into
    :data:`SCENARIOS` directly."""
    from hil.scenarios.catalog import CATALOG

    if name not in CATALOG and name not in SCENARIOS:
        known = ", ".join(sorted({*CATALOG, *SCENARIOS}))
        raise KeyError(f"unknown scenario {name!r} (known: {known})")


def names() -> list[str]:
    """Names of all scenarios."""
    _load_all()
    return sorted(SCENARIOS)


#: The thesis experiments ``eha-hil run thesis`` runs, in order: F1 as measured (the plant
#: alone, with and without entrained air), F3-F8 on the full stack, and the hip's F9
#: (pitch, and roll as Fig. 6.22) through the whole joint stack.
THESIS = ("f1-measured", "f3", "f4", "f5", "f6", "f7", "f8", "f9", "f9-roll")
#: Scenarios that run on the thesis's preset (``-c hydra_thesis``) unless ``-c`` says
#: otherwise: the thesis experiments.
ON_THESIS_PRESET = THESIS
#: The main job's figures (plant alone), which ``eha-hil main`` runs and prints.
MAIN = ("f1", "f2")


def _load_all() -> None:
    # Importing the modules registers their scenarios.
    from hil.scenarios import (  # noqa: F401
        bus_faults,
        current,
        f1_measured,
        hip,
        identify_rig,
        plant_figures,
        thesis,
    )
    try:
        from hil.scenarios import strain  # noqa: F401
    except ImportError:  # pragma: no cover - only while F7/F8 are being written
        pass


__all__ = ["MAIN", "ON_THESIS_PRESET", "THESIS", "Metric", "SCENARIOS", "Scenario",
           "ScenarioResult", "check_name", "get", "names", "register"]
