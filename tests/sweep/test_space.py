"""What a sweep varies: the command-line syntax, the points, the Monte Carlo draws."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from hil.sweep.space import (
    Tolerance,
    build_plan,
    draw,
    parse_param,
    parse_seeds,
    parse_tolerance,
)
from plant.config import ConfigError


def test_grid_form_spans_start_to_stop_evenly():
    g = parse_param("mcu.kp_force=1.5:3.0:7")
    assert g.key == "mcu.kp_force"
    assert len(g.values) == 7
    assert g.values[0] == 1.5 and g.values[-1] == 3.0
    assert np.allclose(np.diff(g.values), 0.25)


def test_list_form_takes_what_set_takes():
    g = parse_param("mcu.force_feedback=pressure,strain")
    assert g.values == ("pressure", "strain")
    assert parse_param("mcu.kp_force=1,2,4").values == (1, 2, 4)


@pytest.mark.parametrize("text", ["mcu.kp_force", "kp_force=1,2", "mcu.kp_force=1:2",
                                  "mcu.kp_force=1:2:x", "mcu.kp_force=1:2:1",
                                  "mcu.kp_force=1,,2", "mcu.kp_force=1,1", "mcu.kp_force=nan:1:3"])
def test_bad_param_syntax_is_one_argparse_error(text):
    with pytest.raises(argparse.ArgumentTypeError):
        parse_param(text)


def test_tolerance_relative_and_absolute():
    t = parse_tolerance("effects.seal_friction.coulomb_n,effects.seal_friction.static_n=30%")
    assert t.keys == ("effects.seal_friction.coulomb_n", "effects.seal_friction.static_n")
    assert t.relative and t.width == pytest.approx(0.3)
    a = parse_tolerance("load.x0_m=0.002")
    assert not a.relative and a.width == 0.002
    for bad in ("hydraulics.jp_kg=0%", "hydraulics.jp_kg=150%", "hydraulics.jp_kg=-1",
                "hydraulics.jp_kg,hydraulics.jp_kg=5%"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_tolerance(bad)


def test_seeds():
    assert parse_seeds("3..6") == (3, 4, 5, 6)
    assert parse_seeds("1,7") == (1, 7)
    for bad in ("6..3", "a..b", "1,1"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_seeds(bad)


def test_full_factorial_first_parameter_outermost(default_cfg):
    plan = build_plan(default_cfg, [parse_param("mcu.kp_force=1,2,3"),
                                    parse_param("mcu.force_feedback=pressure,strain")],
                      seeds=(5, 6))
    assert len(plan.points) == 3 * 2 * 2
    assert [p.index for p in plan.points] == list(range(12))
    assert plan.points[0].overrides == {"mcu.kp_force": 1.0, "mcu.force_feedback": "pressure",
                                        "sim.seed": 5}
    assert plan.points[5].overrides == {"mcu.kp_force": 2.0, "mcu.force_feedback": "pressure",
                                        "sim.seed": 6}
    assert plan.parameters == ["mcu.kp_force", "mcu.force_feedback", "sim.seed"]


def test_integer_key_takes_integral_grid_values(default_cfg):
    plan = build_plan(default_cfg, [parse_param("fpga.speed_window_ticks=16:64:2")])
    assert [p.overrides["fpga.speed_window_ticks"] for p in plan.points] == [16, 64]
    assert all(type(p.overrides["fpga.speed_window_ticks"]) is int for p in plan.points)


@pytest.mark.parametrize("kwargs, words", [
    ({"grid": [parse_param("mcu.kp_force=-1:1:3")]}, ["--param mcu.kp_force", "negative"]),
    ({"grid": [parse_param("mcu.nope=1,2")]}, ["--param mcu.nope", "unknown key"]),
    ({"tolerances": [parse_tolerance("mcu.nope=5%")], "samples": 2}, ["--tolerance mcu.nope"]),
    ({"tolerances": [parse_tolerance("mcu.controller=5%")], "samples": 2},
     ["--tolerance mcu.controller", "real-valued"]),
    ({"tolerances": [parse_tolerance("load.x0_m=5%")], "samples": 2},
     ["--tolerance load.x0_m", "absolute"]),
    ({"tolerances": [parse_tolerance("hydraulics.jp_kg=5%")]}, ["--samples"]),
    ({"samples": 3}, ["--samples", "--tolerance"]),
    ({"grid": [parse_param("sim.seed=1,2")], "seeds": (3,)}, ["sim.seed", "twice"]),
    ({"seeds": (-1,)}, ["--seeds"]),
])
def test_plan_mistakes_name_the_option_and_key(default_cfg, kwargs, words):
    with pytest.raises(ConfigError) as err:
        build_plan(default_cfg, **kwargs)
    for w in words:
        assert w in str(err.value)
    assert "\n" not in str(err.value)


def test_tolerance_edges_are_checked_against_the_range(default_cfg):
    # An absolute band reaching below zero is refused before anything runs.
    jp = default_cfg.get("hydraulics.jp_kg")
    with pytest.raises(ConfigError, match="--tolerance hydraulics.jp_kg"):
        build_plan(default_cfg, tolerances=[parse_tolerance(f"hydraulics.jp_kg={jp * 2}")],
                   samples=2)


@pytest.mark.parametrize("distribution", ["uniform", "normal"])
def test_draws_stay_in_the_band_and_fill_it(distribution):
    tol = Tolerance(("hydraulics.jp_kg",), 0.1, True, "")
    d = np.array([draw(tol, 0, j, distribution) for j in range(2000)])
    assert np.all(np.abs(d) <= 0.1)
    assert abs(d.mean()) < 0.01
    if distribution == "uniform":
        assert d.std() == pytest.approx(0.1 / np.sqrt(3), rel=0.05)
    else:  # sigma a third of the band (slightly less: cut at 3 sigma)
        assert d.std() == pytest.approx(0.1 / 3, rel=0.05)


def test_a_sample_is_the_same_actuator_in_every_plan(default_cfg):
    jp = parse_tolerance("hydraulics.jp_kg=10%")
    seal = parse_tolerance("effects.seal_friction.coulomb_n,effects.seal_friction.static_n=30%")
    alone = build_plan(default_cfg, tolerances=[jp], samples=4, draw_seed=7)
    both = build_plan(default_cfg, [parse_param("mcu.kp_force=1,2")], [seal, jp], samples=4,
                      draw_seed=7)
    want = [p.overrides["hydraulics.jp_kg"] for p in alone.points]
    # Grid point kp=1 and kp=2 meet the same four J_p values, whatever else is drawn.
    assert [p.overrides["hydraulics.jp_kg"] for p in both.points] == want * 2
    assert [p.sample for p in both.points] == [0, 1, 2, 3] * 2
    # Keys given together move by one factor.
    for p in both.points:
        c = p.overrides["effects.seal_friction.coulomb_n"] / default_cfg.get(
            "effects.seal_friction.coulomb_n")
        s = p.overrides["effects.seal_friction.static_n"] / default_cfg.get(
            "effects.seal_friction.static_n")
        assert c == pytest.approx(s)
    other = build_plan(default_cfg, tolerances=[jp], samples=4, draw_seed=8)
    assert [p.overrides["hydraulics.jp_kg"] for p in other.points] != want


def test_fingerprint_follows_the_points(default_cfg):
    a = build_plan(default_cfg, [parse_param("mcu.kp_force=1,2")])
    b = build_plan(default_cfg, [parse_param("mcu.kp_force=1,3")])
    assert a.fingerprint("f3", default_cfg) == a.fingerprint("f3", default_cfg)
    assert a.fingerprint("f3", default_cfg) != b.fingerprint("f3", default_cfg)
    assert a.fingerprint("f3", default_cfg) != a.fingerprint("f5", default_cfg)
