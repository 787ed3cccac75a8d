"""What a sweep varies, and the list of points it makes.

* a grid parameter (``--param KEY=START:STOP:COUNT`` or ``KEY=V1,V2,...``): its values;
  several grid parameters make the full factorial, the first one outermost;
* noise seeds (``--seeds 0..9``): the configuration's ``sim.seed`` per point;
* a tolerance (``--tolerance KEY[,KEY...]=10%`` or ``=WIDTH`` in the key's unit): a value
  drawn per Monte Carlo sample (``--samples N``) from ``uniform`` (the whole band) or
  ``normal`` (sigma = a third of the band, cut at the band's edges: a part built to a 3-sigma
  process and inspected). Keys given together move by one common draw (the Coulomb and the
  breakaway force of one seal).

A draw depends only on the base draw seed, the sample number and the tolerance's keys: never
on the scheduling, the grid point or the other tolerances. Every grid point therefore meets
the same sample actuators (common random numbers), so a difference between two gains is the
gains', not the luck of the draw.

Values are checked here, against the configuration's own validation
(:meth:`plant.config.Config.with_overrides`: key, type, range), before anything runs; a
mistake raises :class:`plant.config.ConfigError` naming the option and the key.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hil.scenarios.knobs import Knob, is_knob_key, resolve, split_overrides
from plant.config import Config, ConfigError

DISTRIBUTIONS = ("uniform", "normal")
#: A normal tolerance band is this many standard deviations wide on each side.
NORMAL_SIGMAS = 3.0
#: At most this many points in one sweep (a typo such as 1:2:100000 x 100 samples).
MAX_POINTS = 1_000_000


@dataclass(frozen=True)
class GridParam:
    """A grid parameter: ``key`` takes each of ``values`` (already typed)."""

    key: str
    values: tuple[Any, ...]
    text: str


@dataclass(frozen=True)
class Tolerance:
    """``keys`` drawn together within +/- ``width`` (a fraction when ``relative``)."""

    keys: tuple[str, ...]
    width: float
    relative: bool
    text: str


@dataclass(frozen=True)
class Point:
    """One point: its number, its Monte Carlo sample (None without tolerances) and the
    configuration values it overrides."""

    index: int
    overrides: dict[str, Any]
    sample: int | None = None


@dataclass
class Plan:
    """The points of a sweep and what they vary (for the table's columns and the plots)."""

    points: list[Point]
    grid: list[GridParam] = field(default_factory=list)
    tolerances: list[Tolerance] = field(default_factory=list)
    seeds: tuple[int, ...] = ()
    samples: int = 0
    distribution: str = "uniform"
    draw_seed: int = 0

    @property
    def parameters(self) -> list[str]:
        """The configuration keys the points set, in column order."""
        keys = [g.key for g in self.grid]
        if self.seeds:
            keys.append("sim.seed")
        for tol in self.tolerances:
            keys += tol.keys
        return keys

    @property
    def kind(self) -> str:
        """``grid``, ``monte-carlo`` or ``grid+monte-carlo`` (what the plots show)."""
        if self.tolerances:
            return "grid+monte-carlo" if self.grid else "monte-carlo"
        return "grid"

    def fingerprint(self, scenario: str, base: Config) -> str:
        """A digest of everything a point's result depends on: scenario, base configuration
        and every point's overrides (a journal of another sweep does not resume this one)."""
        text = json.dumps({"scenario": scenario, "config": base.data,
                           "points": [[p.index, p.sample, p.overrides] for p in self.points]},
                          sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()


# --- command-line syntax (argparse types: one line, exit 2, before anything runs) ---------
def _split_key(text: str, what: str) -> tuple[str, str]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {what}")
    key, spec = (s.strip() for s in text.split("=", 1))
    if not key or not spec:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {what}")
    return key, spec


def _check_key(key: str, text: str) -> None:
    if "." not in key or any(not part for part in key.split(".")):
        raise argparse.ArgumentTypeError(f"{text!r}: {key!r} is not a SECTION.KEY")


def _literal(raw: str) -> Any:
    """A value as ``--set`` reads it: a TOML literal, bare words as strings."""
    import tomllib

    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def _number(raw: str, text: str) -> float:
    # The messages of the command line's own number type (hil.cli.args.finite_float),
    # which this layer may not import.
    try:
        value = float(raw)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: {raw!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: {raw!r}: need a finite number")
    return value


def parse_param(text: str) -> GridParam:
    """``KEY=START:STOP:COUNT`` (COUNT evenly spaced values, both ends included) or
    ``KEY=V1,V2,...`` (any values ``--set`` takes, e.g. ``mcu.force_feedback=pressure,strain``)."""
    what = "SECTION.KEY=START:STOP:COUNT or SECTION.KEY=V1,V2,..."
    key, spec = _split_key(text, what)
    _check_key(key, text)
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise argparse.ArgumentTypeError(f"{text!r}: expected START:STOP:COUNT")
        start, stop = _number(parts[0], text), _number(parts[1], text)
        try:
            count = int(parts[2])
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r}: COUNT {parts[2]!r} is not an integer") from None
        if count < 1 or (count == 1 and start != stop):
            raise argparse.ArgumentTypeError(f"{text!r}: COUNT needs to be at least 2 "
                                             "(1 only with START = STOP)")
        if count > MAX_POINTS:  # refused before the values are made, not after
            raise argparse.ArgumentTypeError(
                f"{text!r}: COUNT {count} is more than a sweep's {MAX_POINTS} points")
        values = tuple(float(v) for v in np.linspace(start, stop, count))
    else:
        items = [s.strip() for s in spec.split(",")]
        if any(not s for s in items):
            raise argparse.ArgumentTypeError(f"{text!r}: an empty value in the list")
        values = tuple(_literal(s) for s in items)
    if len(set(map(repr, values))) != len(values):
        raise argparse.ArgumentTypeError(f"{text!r}: a value appears twice")
    return GridParam(key, values, text)


def parse_tolerance(text: str) -> Tolerance:
    """``KEY[,KEY...]=P%`` (relative to each key's value in the base configuration) or
    ``KEY=WIDTH`` (absolute, in the key's unit): the half-width of the band."""
    key_text, spec = _split_key(text, "SECTION.KEY[,SECTION.KEY...]=P% or =WIDTH")
    keys = tuple(k.strip() for k in key_text.split(","))
    for key in keys:
        _check_key(key, text)
    if len(set(keys)) != len(keys):
        raise argparse.ArgumentTypeError(f"{text!r}: a key appears twice")
    relative = spec.endswith("%")
    width = _number(spec[:-1] if relative else spec, text)
    if relative:
        width /= 100.0
        if not 0.0 < width < 1.0:
            raise argparse.ArgumentTypeError(f"{text!r}: need a percentage in (0, 100) %")
    elif width <= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r}: need a width greater than 0")
    return Tolerance(keys, width, relative, text)


def parse_seeds(text: str) -> tuple[int, ...]:
    """``A..B`` (both included), ``A,B,C`` or one seed."""
    try:
        if ".." in text:
            lo, hi = (int(s, 10) for s in text.split(".."))
            if hi < lo:
                raise argparse.ArgumentTypeError(f"{text!r}: need A <= B in A..B")
            if hi - lo + 1 > MAX_POINTS:
                raise argparse.ArgumentTypeError(
                    f"{text!r}: {hi - lo + 1} seeds is more than a sweep's {MAX_POINTS} points")
            seeds = tuple(range(lo, hi + 1))
        else:
            seeds = tuple(int(s, 10) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected seeds as A..B or A,B,C (integers)") from None
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"{text!r}: a seed appears twice")
    return seeds


def _label(overrides: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in overrides.items())


# --- the plan ----------------------------------------------------------------------------
class _Keys:
    """Where a key's rules live: the configuration's, or the scenario's own settings
    (``scenario.NAME``, :mod:`hil.scenarios.knobs`)."""

    def __init__(self, base: Config, knobs: tuple[Knob, ...], scenario: str) -> None:
        self.base, self.scenario = base, scenario
        self.knobs = {k.key: k for k in knobs}

    def nominal(self, key: str) -> Any:
        """The key's value without the sweep; KeyError/TypeError if there is no such key."""
        if is_knob_key(key):
            return self.knobs[key].default
        return self.base.get(key)

    def check(self, overrides: dict[str, Any], option: str) -> None:
        """Raise ConfigError naming ``option`` and the key if a value is not allowed."""
        config, knob_values = split_overrides(overrides)
        if knob_values:
            resolve(self.knobs.values(), knob_values, option, self.scenario)
        if config:
            self.base.with_overrides(config, option)


def _typed(keys: _Keys, key: str, value: Any) -> Any:
    """A grid value converted to the key's type where that loses nothing (2.0 -> 2 for an
    integer key); anything else is left for the configuration's check to refuse."""
    try:
        template = keys.nominal(key)
    except (KeyError, TypeError):
        return value  # the check names the unknown key
    if (isinstance(template, int) and not isinstance(template, bool)
            and isinstance(value, float) and value.is_integer()):
        return int(value)
    return value


def draw(tol: Tolerance, draw_seed: int, sample: int, distribution: str) -> float:
    """The deviation of sample ``sample`` within ``tol``'s band, in [-width, +width]."""
    key_id = zlib.crc32(",".join(tol.keys).encode())
    u = float(np.random.default_rng([draw_seed, sample, key_id]).random())
    if distribution == "uniform":
        unit = 2.0 * u - 1.0
    elif distribution == "normal":
        from scipy.special import ndtr, ndtri

        lo = float(ndtr(-NORMAL_SIGMAS))
        unit = float(ndtri(lo + u * (1.0 - 2.0 * lo))) / NORMAL_SIGMAS
    else:
        raise ValueError(f"unknown distribution {distribution!r}")
    return unit * tol.width


def _toleranced(keys: _Keys, tol: Tolerance, key: str, deviation: float) -> float:
    nominal = keys.nominal(key)
    return nominal * (1.0 + deviation) if tol.relative else nominal + deviation


def build_plan(base: Config, grid: list[GridParam] = (), tolerances: list[Tolerance] = (),
               samples: int = 0, seeds: tuple[int, ...] = (), distribution: str = "uniform",
               draw_seed: int = 0, knobs: tuple[Knob, ...] = (),
               scenario: str = "",
               settings: Callable[[dict[str, Any], str], Any] | None = None,
               fixed: dict[str, Any] | None = None) -> Plan:
    """Every point of the sweep, each value checked against the configuration's rules (or,
    for ``scenario.NAME`` keys, against the scenario's ``knobs``; ``settings`` checks them
    together). ``fixed``: scenario settings every point takes (``--set scenario.NAME=V``:
    the base configuration cannot hold them)."""
    grid, tolerances, fixed = list(grid), list(tolerances), dict(fixed or {})
    keys_ = _Keys(base, tuple(knobs), scenario)
    _check = keys_.check
    keys = [g.key for g in grid] + (["sim.seed"] if seeds else [])
    keys += [k for t in tolerances for k in t.keys]
    for key in keys:
        if keys.count(key) > 1:
            raise ConfigError(f"sweep: {key} is varied twice (--param, --tolerance, --seeds)")
        if key in fixed:
            raise ConfigError(f"sweep: {key} is both set (--set) and varied")
    if tolerances and samples < 1:
        raise ConfigError("--tolerance: give the number of Monte Carlo samples (--samples N)")
    if samples and not tolerances:
        raise ConfigError("--samples: nothing to draw; give a --tolerance")
    # The size first: checking every value of a grid that is refused anyway takes minutes.
    n = math.prod(len(g.values) for g in grid) * max(len(seeds), 1) * max(samples, 1)
    if n > MAX_POINTS:
        raise ConfigError(f"sweep: {n} points; at most {MAX_POINTS} in one sweep")
    typed = []
    for g in grid:
        values = tuple(_typed(keys_, g.key, v) for v in g.values)
        for v in values:
            _check({g.key: v}, f"--param {g.key}")
        typed.append(GridParam(g.key, values, g.text))
    for s in seeds:
        _check({"sim.seed": s}, "--seeds")
    for tol in tolerances:
        for key in tol.keys:
            try:
                nominal = keys_.nominal(key)
            except (KeyError, TypeError):
                # The configuration's own message names the key and the keys there are.
                _check({key: 0.0}, f"--tolerance {key}")
                raise ConfigError(f"--tolerance {key}: unknown key") from None
            if isinstance(nominal, bool) or not isinstance(nominal, float):
                raise ConfigError(f"--tolerance {key}: a tolerance needs a real-valued key "
                                  f"(this one is {type(nominal).__name__}; use --param)")
            if tol.relative and nominal == 0.0:
                raise ConfigError(f"--tolerance {key}: its value is 0, so a relative "
                                  "tolerance moves nothing; give an absolute width")
            for sign in (-1.0, 1.0):  # the band's edges: any draw lies between them
                _check({key: _toleranced(keys_, tol, key, sign * tol.width)},
                       f"--tolerance {key}")
    deviations = [[draw(t, draw_seed, j, distribution) for t in tolerances]
                  for j in range(samples)]
    points = []
    combos = itertools.product(*(g.values for g in typed), seeds or (None,),
                               range(samples) if samples else (None,))
    for index, combo in enumerate(combos):
        *values, seed, sample = combo
        over = dict(fixed)
        over.update(zip((g.key for g in typed), values, strict=True))
        if seed is not None:
            over["sim.seed"] = seed
        if sample is not None:
            for tol, dev in zip(tolerances, deviations[sample], strict=True):
                for key in tol.keys:
                    over[key] = _toleranced(keys_, tol, key, dev)
        if settings is not None:  # the scenario's settings together (a kind and its link)
            settings(split_overrides(over)[1], f"sweep point {index} ({_label(over)})")
        points.append(Point(index, over, sample))
    return Plan(points, typed, tolerances, tuple(seeds), samples, distribution, draw_seed)
