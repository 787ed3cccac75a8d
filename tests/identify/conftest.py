"""Session fixtures: identification datasets from the plant, generated once, and their
identification runs, cached so each is made once per session however many tests use it.

``effects`` is a tuple of library names (default magnitudes) or a dict of name -> magnitude
overrides (non-default magnitudes); ``profile`` the excitation of
:func:`hil.identify.synth.generate`."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import pytest

from hil.identify.pipeline import IdentifyReport, identify
from hil.identify.synth import SynthResult, generate
from plant.config import Config, load_config

Effects = tuple[str, ...] | Mapping[str, Mapping[str, float]]

_DATA: dict[tuple, SynthResult] = {}
_RUNS: dict[tuple, IdentifyReport] = {}


def _key(load: str, effects: Effects, seconds: float, seed: int, profile: str) -> tuple:
    if isinstance(effects, Mapping):
        eff = tuple(sorted((n, tuple(sorted(m.items()))) for n, m in effects.items()))
    else:
        eff = tuple(sorted((n, ()) for n in effects))
    return (load, eff, seconds, seed, profile)


@pytest.fixture(scope="session")
def ident_cfg() -> Config:
    """Constants and start values the tool uses (the default preset)."""
    return load_config("hydra_default")


@pytest.fixture(scope="session")
def dataset() -> Callable[..., SynthResult]:
    """``dataset(load, effects, seconds, seed, profile)`` -> SynthResult, generated once."""

    def make(load: str, effects: Effects = (), seconds: float = 6.0, seed: int = 1,
             profile: str = "multisine") -> SynthResult:
        k = _key(load, effects, seconds, seed, profile)
        if k not in _DATA:
            eff = ({n: dict(m) for n, m in effects.items()} if isinstance(effects, Mapping)
                   else list(effects))
            _DATA[k] = generate(load, eff, seconds=seconds, seed=seed, profile=profile)
        return _DATA[k]

    return make


@pytest.fixture(scope="session")
def identified(dataset, ident_cfg) -> Callable[..., tuple[SynthResult, IdentifyReport]]:
    """``identified(load, effects, seconds, seed, profile)`` -> (SynthResult, IdentifyReport)."""

    def run(load: str, effects: Effects = (), seconds: float = 6.0, seed: int = 1,
            profile: str = "multisine") -> tuple[SynthResult, IdentifyReport]:
        k = _key(load, effects, seconds, seed, profile)
        syn = dataset(load, effects, seconds, seed, profile)
        if k not in _RUNS:
            _RUNS[k] = identify(syn.data, ident_cfg)
        return syn, _RUNS[k]

    return run


@pytest.fixture(scope="session")
def jacobian_at() -> Callable:
    """``jacobian_at(fitter, free, theta)`` -> (the fit's Jacobian at ``theta`` over
    ``free`` with unit weights on its estimation mask, the simulations it took)."""
    import numpy as np

    def at(fitter, free: list[str], theta: np.ndarray) -> tuple[np.ndarray, int]:
        fun, jac = fitter._problem(free, theta, {c: 1.0 for c in fitter.exp.channels},
                                   fitter.fit_mask())
        x = fitter._to_x(theta, free)
        fun(x)
        before = fitter.n_sims
        out = jac(x)
        return out, fitter.n_sims - before

    return at
