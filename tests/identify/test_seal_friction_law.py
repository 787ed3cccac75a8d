"""The seal friction's law as the fit may shape it: a Stribeck velocity that runs far below
the regularisation velocity is a degenerate law, held (:meth:`SealFriction.implausible`)."""

from __future__ import annotations

import pytest


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
    exp = SimpleNamespace(const=SimpleNamespace(eps_seal=2e-3))
    odd = EFFECTS["seal_friction"].implausible(fit, exp)
    assert (set(odd) == {"sf_vs_m_per_s"}) is degenerate
    held_fit = SimpleNamespace(free=["sf_coulomb_n", "sf_static_n"], value=fit.value)
    assert not EFFECTS["seal_friction"].implausible(held_fit, exp)
