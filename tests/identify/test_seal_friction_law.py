"""The seal friction's law as the fit may shape it: a Stribeck velocity that runs far below
the regularisation velocity, or above the record's top piston speed, is a degenerate law,
held (:meth:`SealFriction.implausible`)."""

from __future__ import annotations

import numpy as np
import pytest

#: measured piston speeds of a slide record: up to 43 mm/s, both ways, one sample lost
SPEEDS = {"v_piston": np.array([0.0, 0.012, -0.043, 0.031, np.nan, -0.0004])}


@pytest.mark.parametrize("vs,degenerate", [(4.7e-5, True), (4.9e-4, True), (1.97e-3, False),
                                           (3.6e-3, False)])
def test_a_stribeck_velocity_below_the_regularisation_is_held(vs, degenerate):
    """v_s far below eps hides the dip inside the linear zone of the sign law, where a static
    level of any size sits in a band no sample reaches (the slide profile, rig seed 2, ran
    to v_s 47 um/s, F_s 1e12 N): held at its start and the refit made again."""
    from types import SimpleNamespace

    from hil.identify.effects import EFFECTS

    fit = SimpleNamespace(free=["sf_coulomb_n", "sf_static_n", "sf_vs_m_per_s"],
                          value=lambda name: {"sf_vs_m_per_s": vs}[name])
    exp = SimpleNamespace(const=SimpleNamespace(eps_seal=2e-3), measured=SPEEDS)
    odd = EFFECTS["seal_friction"].implausible(fit, exp)
    assert (set(odd) == {"sf_vs_m_per_s"}) is degenerate
    held_fit = SimpleNamespace(free=["sf_coulomb_n", "sf_static_n"], value=fit.value)
    assert not EFFECTS["seal_friction"].implausible(held_fit, exp)


@pytest.mark.parametrize("vs,degenerate", [(3.6e-3, False), (0.0425, False), (0.0435, True),
                                           (1.418, True)])
def test_a_stribeck_velocity_above_the_top_speed_is_held(vs, degenerate):
    """v_s above every sample's speed keeps exp(-(v/v_s)^2) above 1/e throughout: no sample
    reaches the Coulomb level, which then runs along a ridge with v_s (the slide profile, rig
    seed 3, 16 s: v_s 1.4 m/s, F_c 502 N, the static level 19 N acting as the Coulomb one,
    the pressures' residual left with structure): held at its start, refit made again."""
    from types import SimpleNamespace

    from hil.identify.effects import EFFECTS

    fit = SimpleNamespace(free=["sf_coulomb_n", "sf_static_n", "sf_vs_m_per_s"],
                          value=lambda name: {"sf_vs_m_per_s": vs}[name])
    seal = EFFECTS["seal_friction"]
    exp = SimpleNamespace(const=SimpleNamespace(eps_seal=2e-3), measured=SPEEDS)
    odd = seal.implausible(fit, exp)
    assert (set(odd) == {"sf_vs_m_per_s"}) is degenerate
    if degenerate:
        assert "top piston speed" in odd["sf_vs_m_per_s"]
    # without a piston encoder the record says nothing of the speeds: not judged
    blind = SimpleNamespace(const=exp.const, measured={})
    assert not seal.implausible(fit, blind)
