"""Null data add nothing and call the residual white; an effect outside the library is
reported as unexplained, not misattributed."""

from __future__ import annotations

import pytest

# whole identifications of several-second records: the full lane only
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("load", ["fixed_piston", "free_piston", "conrod_fixed"])
def test_null_dataset_adds_nothing_and_is_white(identified, load):
    _, rep = identified(load, ())
    assert rep.effects_added == []
    assert rep.residual_before.white and rep.residual_after.white
    assert not rep.unexplained
    for c in rep.channels:
        assert c.nrmse_after == c.nrmse_before


def test_null_dataset_recovers_table_2_1(identified):
    _, rep = identified("fixed_piston", ())
    truth = {"d_s": 6.79e4, "d_p": 1.50e4, "k_s": 2.24e7, "K": 2150.0 / 18.0}
    for sym, want in truth.items():
        p = rep.baseline[sym]
        assert p.ci_low <= want <= p.ci_high or abs(p.value / want - 1) < 1e-3, (sym, p)


def test_null_free_piston_holds_nothing_it_can_fit(identified):
    _, rep = identified("free_piston", ())
    assert abs(rep.baseline["d_c"].value / 413.0 - 1) < 0.02


@pytest.mark.parametrize("outside", ["mains_hum", "backlash"])
def test_outside_effect_is_unexplained(identified, outside):
    _, rep = identified("fixed_piston", (outside,))
    assert rep.effects_added == [], [e.label for e in rep.effects_added]
    assert rep.unexplained
    assert not rep.residual_after.white
    channel = "p_pump_a" if outside == "mains_hum" else "omega_m"
    assert channel in rep.unexplained_detail
    if outside == "mains_hum":
        assert "50.0 Hz" in rep.unexplained_detail


def test_two_effects_at_once(identified):
    """A mix: pulsation and pump Coulomb friction together are both found."""
    _, rep = identified("fixed_piston", ("pump_coulomb_friction", "pump_pulsation"), seconds=4.0)
    names = {e.name for e in rep.effects_added}
    assert names == {"pump_coulomb_friction", "pump_pulsation"}
    assert not rep.unexplained
