"""Shared fixtures: configurations built from the shipped presets."""

from __future__ import annotations

import pytest

from plant.config import load_config


@pytest.fixture(scope="session")
def linear_cfg():
    """The thesis's linear model: every effect off."""
    return load_config("hydra_linear")


@pytest.fixture(scope="session")
def default_cfg():
    """The default preset, effects as shipped."""
    return load_config()
