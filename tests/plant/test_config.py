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
        ("[mcu]\nconrod_length_m = 0.1\nconrod_offset_m = 0.2\n", "conrod_offset_m"),
        ("[mcu]\nfriction_observer_hz = 2000.0\n", "friction_observer_hz"),
        # each temperature in range, together 300x thinner oil than the table's
        ("[effects.oil_temperature]\nenabled = true\nreference_c = -40.0\ninitial_c = 150.0\n",
         "oil_temperature.initial_c"),
        ("[effects.oil_temperature]\nenabled = true\nviscosity_coeff_per_c = 0.1\n"
         "ambient_c = 100.0\n", "oil_temperature.ambient_c"),
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


def test_every_numeric_key_has_a_range():
    from plant.config import RANGES, schema

    def numeric(tree, prefix=""):
        for k, v in tree.items():
            if isinstance(v, dict):
                yield from numeric(v, f"{prefix}{k}.")
            elif not isinstance(v, bool | str):
                yield f"{prefix}{k}"

    assert set(numeric(schema())) == set(RANGES)


def test_every_range_holds_its_default_and_accepts_its_bounds():
    from plant.config import RANGES

    cfg = load_config()
    for key, r in RANGES.items():
        default = cfg.get(key)
        assert r.lo <= default <= r.hi and not (r.open_lo and default == r.lo), key
        kind = type(default)
        bounds = [r.hi] if r.open_lo else [r.lo, r.hi]
        for v in bounds:
            try:
                assert cfg.with_overrides({key: kind(v)}).get(key) == kind(v), (key, v)
            except ConfigError as exc:
                # The bound passes its range; only a rule between keys (a dead time of half
                # a PWM period at the default frequency) may refuse it.
                assert "must be" not in str(exc) and "must not" not in str(exc), (key, exc)


@pytest.mark.parametrize(
    "override, fragment",
    [
        ("inverter.dc_bus_v=0", "must be at least 1"),
        ("mcu.period_ticks=100000", "must be at most 20"),
        ("mcu.period_ticks=0", "must be at least 1"),
        ("sim.tick_ns=0", "must be at least 1000"),
        ("effects.pulsation.amplitude=2.0", "must be at most 1"),
        ("effects.oil_temperature.initial_c=300.0", "must be at most 150"),
        ("effects.seal_friction.stribeck_velocity_m_per_s=0.0", "must be greater than 0"),
        ("load.x0_m=-5.0", "must be at least -1"),
        ("hydraulics.jp_kg=-3", "must not be negative"),
    ],
)
def test_out_of_range_values_are_refused(override, fragment):
    key = override.split("=")[0]
    with pytest.raises(ConfigError) as err:
        load_config(None, [override])
    assert key in str(err.value) and fragment in str(err.value)
    assert str(err.value).count(key) == 1, err.value  # named once, not "--set k: k: ..."


@pytest.mark.parametrize("name, text, fragment", [
    ("dir", None, "is a directory"),
    ("data.csv", "t,iq\n0,1\n", "expected NAME.toml"),
    ("empty.toml", "  \n", "is empty"),
])
def test_config_file_that_is_not_one(tmp_path, name, text, fragment):
    path = tmp_path / name
    if text is None:
        path.mkdir()
    else:
        path.write_text(text)
    with pytest.raises(ConfigError, match=fragment):
        load_config(path)


def test_with_overrides_checks_the_rules_between_keys():
    """Each key in range is not enough: an override that breaks a rule between keys is
    refused with the source's name, as the same keys in a file would be."""
    cfg = load_config().with_overrides({"mcu.conrod_length_m": 0.2})
    with pytest.raises(ConfigError, match="sweep point 3: mcu.conrod_offset_m: need less "
                       "than mcu.conrod_length_m"):
        cfg.with_overrides({"mcu.conrod_offset_m": 0.3}, "sweep point 3")
    assert cfg.with_overrides({"mcu.conrod_offset_m": 0.1}).get("mcu.conrod_offset_m") == 0.1
