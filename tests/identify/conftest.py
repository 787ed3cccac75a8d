"""Session fixtures: identification datasets from the plant, generated once, and their
identification runs, cached so each is made once per session however many tests use it."""

from __future__ import annotations

import pytest

from hil.identify.pipeline import IdentifyReport, identify
from hil.identify.synth import SynthResult, generate
from plant.config import load_config

_DATA: dict[tuple, SynthResult] = {}
_RUNS: dict[tuple, IdentifyReport] = {}


def _key(load: str, effects: tuple[str, ...], seconds: float, seed: int) -> tuple:
    return (load, tuple(sorted(effects)), seconds, seed)


@pytest.fixture(scope="session")
def ident_cfg():
    """Constants and start values the tool uses (the default preset)."""
    return load_config("hydra_default")


@pytest.fixture(scope="session")
def dataset():
    """``dataset(load, effects, seconds, seed)`` -> SynthResult, generated once."""

    def make(load: str, effects: tuple[str, ...] = (), seconds: float = 6.0,
             seed: int = 1) -> SynthResult:
        k = _key(load, effects, seconds, seed)
        if k not in _DATA:
            _DATA[k] = generate(load, list(effects), seconds=seconds, seed=seed)
        return _DATA[k]

    return make


@pytest.fixture(scope="session")
def identified(dataset, ident_cfg):
    """``identified(load, effects, seconds, seed)`` -> (SynthResult, IdentifyReport)."""

    def run(load: str, effects: tuple[str, ...] = (), seconds: float = 6.0,
            seed: int = 1) -> tuple[SynthResult, IdentifyReport]:
        k = _key(load, effects, seconds, seed)
        syn = dataset(load, effects, seconds, seed)
        if k not in _RUNS:
            _RUNS[k] = identify(syn.data, ident_cfg)
        return syn, _RUNS[k]

    return run
