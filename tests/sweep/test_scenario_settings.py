"""A scenario's own settings (``scenario.NAME``): checked in one place, reaching the run
through ``eha-hil run --set`` and through a sweep's ``--param``/``--set``; the bus-faults
scenario's figures follow the MCU's command watchdog; identify-rig sweeps judged by the
rig's truth."""

from __future__ import annotations

import math

import pytest

from hil import scenarios
from hil.cli import main
from hil.scenarios.bus_faults import fault_entry, rising_edges
from hil.scenarios.knobs import Knob, resolve, split_sets
from hil.sweep import space, table
from plant.config import ConfigError, load_config


def _code(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


# --- the settings themselves -----------------------------------------------------------------

def test_a_knob_checks_type_range_and_choices():
    rate = Knob("rate", 0.05, "p", lo=0.0, hi=1.0)
    n = Knob("box", 0, "b", lo=0)
    kind = Knob("kind", "drop", "k", choices=("drop", "delay"))
    assert rate.check(1, "w") == 1.0 and isinstance(rate.check(1, "w"), float)
    assert n.check(3, "w") == 3 and isinstance(n.check(3, "w"), int)
    for knob, bad, words in [(rate, 1.5, "must be in [0, 1]"), (rate, "x", "expected a number"),
                             (rate, True, "expected a number"), (rate, math.nan, "finite"),
                             (n, 2.5, "expected an integer"), (n, -1, "must be in"),
                             (kind, "stuck", "not one of drop, delay"),
                             (kind, 3, "expected a string")]:
        with pytest.raises(ConfigError) as err:
            knob.check(bad, "--set")
        assert str(err.value).startswith(f"--set: {knob.key}") and words in str(err.value)


def test_resolve_fills_defaults_and_refuses_unknown_names():
    knobs = (Knob("rate", 0.05, "p"), Knob("kind", "drop", "k"))
    assert resolve(knobs, {"scenario.rate": 0.5}, "w", "s") == {"rate": 0.5, "kind": "drop"}
    with pytest.raises(ConfigError, match="scenario s has no setting 'scenario.rat' "
                       r"\(its settings: scenario.rate, scenario.kind\)"):
        resolve(knobs, {"scenario.rat": 0.5}, "w", "s")


def test_split_sets_keeps_configuration_keys_as_given():
    cfg_sets, knob_values = split_sets(["mcu.kp_force=2", "scenario.rate=0.5",
                                        "scenario.kind=delay"])
    assert cfg_sets == ["mcu.kp_force=2"]
    assert knob_values == {"scenario.rate": 0.5, "scenario.kind": "delay"}


def test_fault_declaration_from_settings():
    v = scenarios.get("bus-faults").settings({"scenario.link": "lvds.up",
                                              "scenario.kind": "delay",
                                              "scenario.delay": 7}, "w")
    entry = fault_entry(v, 4)
    assert entry == {"link": "lvds.up", "kind": "delay", "start_s": 0.1, "seed": 4,
                     "box": 0, "slot": 0, "delay_ticks": 7}
    assert fault_entry({**v, "link": "none"}, 4) is None


def test_rising_edges_count_each_set_once_per_actuator():
    import numpy as np

    flags = np.array([[1, 0], [1, 0], [0, 1], [1, 1], [0, 0]], dtype=bool)
    assert rising_edges(flags) == 3  # actuator 0 at rows 0 and 3, actuator 1 at row 2


# --- command lines -------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, words", [
    (["run", "bus-faults", "--set", "scenario.rat=1"], ["has no setting 'scenario.rat'"]),
    (["run", "bus-faults", "--set", "scenario.rate=2"], ["scenario.rate", "must be in"]),
    (["run", "bus-faults", "--set", "scenario.link=lvds.up", "--set", "scenario.kind=stuck"],
     ["'stuck' does not apply to scenario.link 'lvds.up'"]),
    (["run", "bus-faults", "--set", "scenario.start_s=0.3", "--set", "scenario.end_s=0.2"],
     ["scenario.end_s", "after scenario.start_s"]),
    (["run", "f3", "--set", "scenario.rate=1"], ["scenario f3 has no setting"]),
    (["run", "identify-rig", "--set", "scenario.profile=slide"], ["needs scenario.load"]),
    (["sweep", "bus-faults", "--param", "scenario.kind=drop,stuck"],
     ["sweep point 1", "'stuck' does not apply"]),
    (["sweep", "bus-faults", "--param", "scenario.rate=0:2:3"],
     ["--param scenario.rate", "must be in"]),
    (["sweep", "bus-faults", "--param", "scenario.rate=0:1:3", "--set", "scenario.rate=0.5"],
     ["both set (--set) and varied"]),
    (["sweep", "bus-faults", "--tolerance", "scenario.box=10%", "--samples", "3"],
     ["needs a real-valued key"]),
])
def test_setting_mistakes_are_one_line_and_exit_2(capsys, argv, words):
    code = _code(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    for w in words:
        assert w in err


def _bus(knobs: dict, cfg_over: dict | None = None):
    cfg = load_config("hydra_default")
    if cfg_over:
        cfg = cfg.with_overrides(cfg_over)
    res = scenarios.get("bus-faults").call(cfg, None, knobs)
    return {m.name: m.value for m in res.metrics}


def test_the_watchdog_trips_exactly_when_the_outage_outlasts_its_timeout():
    """All frames to the box lost for a window: the MCU's command watchdog (command_timeout_s
    of the configuration) trips once when the window is longer than the timeout, never when
    it is shorter; every frame of the window is counted lost."""
    cfg = load_config("hydra_default")
    timeout = cfg.get("mcu.command_timeout_s")
    base = {"scenario.seconds": 0.12, "scenario.rate": 1.0, "scenario.start_s": 0.04}
    short = _bus({**base, "scenario.end_s": 0.04 + 0.5 * timeout})
    long = _bus({**base, "scenario.end_s": 0.04 + 3.0 * timeout})
    assert short["watchdog trips"] == 0
    assert long["watchdog trips"] == 1
    assert short["frames lost"] == round(0.5 * timeout / 1e-3)
    assert long["frames lost"] == round(3.0 * timeout / 1e-3)
    # a longer timeout in the configuration rides out the same outage
    relaxed = _bus({**base, "scenario.end_s": 0.04 + 3.0 * timeout},
                   {"mcu.command_timeout_s": 4.0 * timeout})
    assert relaxed["watchdog trips"] == 0


def test_sweep_over_a_setting_reaches_every_point(tmp_path, capsys):
    out = tmp_path / "bf.csv"
    code = _code(["sweep", "bus-faults", "--param", "scenario.rate=0,1", "--set",
                  "scenario.seconds=0.05", "--set", "scenario.start_s=0.01", "--workers", "1",
                  "--out", str(out), "--json"])
    capsys.readouterr()
    assert code == 0
    df = table.read(out)
    assert list(df["scenario.rate"]) == [0.0, 1.0]
    assert list(df["frames lost"]) == [0.0, 40.0]  # 40 cycles of the 50 in the window


@pytest.mark.slow
def test_identify_rig_sweep_finds_the_effect_that_is_there(tmp_path, capsys):
    out = tmp_path / "id.csv"
    code = _code(["sweep", "identify-rig", "--param",
                  "scenario.effect=none,pump_coulomb_friction", "--set", "scenario.seconds=3",
                  "--workers", "1", "--out", str(out), "--json"])
    capsys.readouterr()
    assert code == 0
    df = table.read(out).set_index("scenario.effect")
    assert df.loc["none", "effects added"] == 0
    assert df.loc["pump_coulomb_friction", "effects added"] == 1
    assert df.loc["pump_coulomb_friction", "magnitude error [%]"] < 10.0
    assert bool(df.loc["none", "right: pass"]) and bool(df.loc["pump_coulomb_friction",
                                                               "right: pass"])


def test_plan_checks_settings_together():
    scen = scenarios.get("identify-rig")
    base = load_config("hydra_default")
    grid = [space.parse_param("scenario.effect=seal_friction,backlash"),
            space.parse_param("scenario.effect2=seal_friction")]
    with pytest.raises(ConfigError, match="sweep point 0 .*is scenario.effect already"):
        space.build_plan(base, grid, knobs=scen.knobs, scenario=scen.name,
                         settings=scen.settings)


def _runs_closed(lost: list[bool], n: int) -> int:
    """Runs of at least ``n`` consecutive lost cycles that end before the record does."""
    count = run = 0
    for x in lost:
        if x:
            run += 1
        else:
            count += run >= n
            run = 0
    return count


@pytest.mark.parametrize("model", ["stack", "echo"])
def test_watchdog_trips_are_the_outages_longer_than_the_timeout(model):
    """Random frame losses: every run of lost cycles at least command_timeout_s long trips
    the watchdog once, counted in the boxes (also where the replies telling of it are lost);
    shorter runs never do. The runs are read off the PC's freshness flags."""
    cfg = load_config("hydra_default").with_overrides({"sim.seed": 5})
    res = scenarios.get("bus-faults").call(cfg, None, {
        "scenario.seconds": 0.6, "scenario.rate": 0.8, "scenario.start_s": 0.0,
        "scenario.model": model})
    metrics = {m.name: m.value for m in res.metrics}
    lost = [f == 0.0 for f in res.series["fresh"]]
    n = round(cfg.get("mcu.command_timeout_s") / 1e-3)
    expected = _runs_closed(lost, n)
    assert expected >= 3  # the draw must make the point
    assert metrics["watchdog trips"] == expected
    assert metrics["watchdog trips seen"] <= metrics["watchdog trips"]


def test_the_settings_tables_in_the_docs_are_the_declared_ones():
    """docs/scenarios.md lists every setting of every scenario with its default, and no
    other: the table rows are parsed and compared with the declarations."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "scenarios.md").read_text()
    documented: dict[str, dict[str, str]] = {}
    section = None
    for line in text.splitlines():
        if line.startswith("## `"):
            section = line.split("`")[1]
        elif line.startswith("| `scenario.") and section:
            cells = [c.strip() for c in line.strip("|").split("|")]
            documented.setdefault(section, {})[cells[0].strip("`")] = cells[1].strip("`")
    declared = {n: {k.key: str(k.default) for k in scenarios.get(n).knobs}
                for n in scenarios.names() if scenarios.get(n).knobs}
    assert documented == declared


def test_bus_run_injects_the_faults_of_a_file_and_replays_them(tmp_path, capsys):
    """``bus run --faults``: every frame of a dropped window is counted by the fault layer
    and lost at the master; the run exits 0 (the losses were asked for), its log replays
    bit for bit; a fault file naming a box the topology lacks is one line, exit 2."""
    import json

    faults = tmp_path / "f.toml"
    faults.write_text('[[fault]]\nlink = "fieldbus.down"\nkind = "drop"\nrate = 1.0\n'
                      'start_s = 0.02\nend_s = 0.05\n')
    log = tmp_path / "run.mcap"
    code = _code(["bus", "run", "--seconds", "0.08", "--faults", str(faults), "--log",
                  str(log), "--json"])
    data = json.loads(capsys.readouterr().out)
    assert code == 0
    assert data["fault_counts"]["down_dropped"] == 30
    assert data["master"]["lost_frames"] == 30
    assert _code(["replay", str(log), "--json"]) == 0
    capsys.readouterr()
    faults.write_text('[[fault]]\nlink = "lvds.up"\nkind = "dead"\nbox = 3\nslot = 0\n')
    assert _code(["bus", "run", "--seconds", "0.01", "--faults", str(faults)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert f"--faults {faults}: fault #0 (lvds.up dead): key 'box' = 3" in err
