"""Configuration loading: presets, user files, overrides and every kind of mistake."""

from __future__ import annotations

import pytest

from plant.config import ConfigError, linearised, load_config, parse_override, preset_names


def test_shipped_presets_load():
    names = preset_names()
    assert {"hydra_default", "hydra_linear", "hydra_nonlinear"} <= set(names)
    for name in names:
        cfg = load_config(name)
        assert cfg.get("hydraulics.kc_m2") > 0


def test_default_is_table_2_1():
    # A spot check of values the thesis states, so an edit of the preset is noticed.
    cfg = load_config()
    assert cfg.get("hydraulics.jp_kg") == 118.0
    assert cfg.get("hydraulics.ds_ns_per_m") == 6.79e4
    assert cfg.get("load.kind") == "fixed"


def test_user_file_overlays_default(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text("[load]\nkind = 'free'\n[effects.pulsation]\norder = 6\n")
    cfg = load_config(f)
    assert cfg.get("load.kind") == "free"
    assert cfg.get("effects.pulsation.order") == 6
    assert cfg.get("hydraulics.jc_kg") == 0.295  # untouched keys keep the default
    assert str(f) in cfg.sources


def test_overrides_are_typed():
    cfg = load_config(None, ["load.kind=conrod", "hydraulics.jc_kg=1", "sim.seed=7",
                             "effects.pulsation.enabled=false"])
    assert cfg.get("load.kind") == "conrod"
    assert cfg.get("hydraulics.jc_kg") == 1.0 and isinstance(cfg.get("hydraulics.jc_kg"), float)
    assert cfg.get("sim.seed") == 7
    assert cfg.get("effects.pulsation.enabled") is False


def test_linearised_switches_every_effect_off(default_cfg):
    lin = linearised(default_cfg)
    assert all(not sec["enabled"] for sec in lin.section("effects").values())
    assert default_cfg.get("effects.pulsation.enabled")  # the original is not changed


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("[hydraulics]\nkp = 1.0\n", "hydraulics.kp"),
        ("[hydraulic]\nkp_m3_per_rad = 1.0\n", "hydraulic"),
        ("[hydraulics]\njp_kg = 'heavy'\n", "hydraulics.jp_kg"),
        ("[hydraulics]\njp_kg = -1.0\n", "hydraulics.jp_kg"),
        ("[hydraulics]\njp_kg = nan\n", "hydraulics.jp_kg"),
        ("[hydraulics]\njp_kg = inf\n", "hydraulics.jp_kg"),
        ("[hydraulics]\njp_kg = 0.0\n", "hydraulics.jp_kg"),
        ("[motor]\npole_pairs = 2.5\n", "motor.pole_pairs"),
        ("[effects.pulsation]\nenabled = 1\n", "effects.pulsation.enabled"),
        ("[load]\nkind = 'rubber'\n", "load.kind"),
        ("[load]\nx0_m = 0.3\n", "load.x0_m"),
        ("[inverter]\nduty_min = 0.9\nduty_max = 0.1\n", "duty_min"),
        ("[hydraulics\n", "not valid TOML"),
    ],
)
def test_bad_file_names_key_and_file(tmp_path, text, fragment):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(f)
    msg = str(err.value)
    assert fragment in msg
    assert str(f) in msg
    assert "\n" not in msg


def test_missing_file():
    with pytest.raises(ConfigError, match="no-such.toml: no such file"):
        load_config("no-such.toml")


def test_signed_keys_accept_negative():
    cfg = load_config(None, ["load.x0_m=-0.01", "effects.oil_temperature.ambient_c=-10"])
    assert cfg.get("load.x0_m") == -0.01


@pytest.mark.parametrize("bad", ["novalue", "=3", "kind=free", "load.nokey=1", "load.kind=7"])
def test_bad_overrides(bad):
    with pytest.raises(ConfigError, match="--set"):
        load_config(None, [bad])


def test_parse_override_bare_word():
    assert parse_override("load.kind = cart") == ("load.kind", "cart")
    assert parse_override("sim.seed=3") == ("sim.seed", 3)
