"""The firmware calibration set: where its values come from, and that the firmware reads
nothing else."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga.driver_board import DriverBoard
from firmware_model.mcu.controller import ActuatorController
from plant.config import FIRMWARE_NOMINAL, ConfigError, load_config, with_nominal_firmware

ROOT = Path(__file__).resolve().parents[2]


def test_defaults_are_the_presets_nominal_values(default_cfg):
    for fw, plant in FIRMWARE_NOMINAL.items():
        assert default_cfg.get(fw) == default_cfg.get(plant), fw


def test_set_changes_the_plant_only(default_cfg):
    cfg = load_config(overrides=["hydraulics.jp_kg=130.0"])
    assert cfg.get("hydraulics.jp_kg") == 130.0
    assert cfg.get("firmware.jp_kg") == default_cfg.get("firmware.jp_kg")
    assert ActuatorController(cfg).observer.j == pytest.approx(118.0)
    cfg = load_config(overrides=["firmware.jp_kg=130.0"])
    assert ActuatorController(cfg).observer.j == pytest.approx(130.0)
    assert cfg.get("hydraulics.jp_kg") == default_cfg.get("hydraulics.jp_kg")


def test_a_file_describes_an_actuator_and_its_firmware_follows(tmp_path):
    path = tmp_path / "bigger.toml"
    path.write_text("[hydraulics]\njp_kg = 140.0\n[motor]\npole_pairs = 4\n"
                    "[firmware]\npole_pairs = 3\n")
    cfg = load_config(path)
    assert cfg.get("firmware.jp_kg") == 140.0  # left out: follows the file's plant value
    assert cfg.get("firmware.pole_pairs") == 3  # given: taken as given
    assert DriverBoard(cfg).params[0] == 3  # C_POLE_PAIRS


def test_the_calibration_knows_no_plant_truth(default_cfg):
    cal = FirmwareCalibration.from_config(default_cfg)
    names = set(vars(cal))
    assert "dp_ns_per_m" not in names and "ks_n_per_m" not in names
    assert cal.kt_eq_n_per_a == pytest.approx(2150.0 / 18.0)


def test_a_log_from_before_the_firmware_section_gets_the_plants_values():
    flat = {"hydraulics.jp_kg": 99.0, "motor.pole_pairs": 2}
    out = with_nominal_firmware(flat)
    assert out["firmware.jp_kg"] == 99.0 and out["firmware.pole_pairs"] == 2
    assert with_nominal_firmware({**flat, "firmware.jp_kg": 1.0})["firmware.jp_kg"] == 1.0


def test_firmware_zero_count_is_checked_against_the_scale(tmp_path):
    path = tmp_path / "short_scale.toml"
    path.write_text("[sensors]\nbiss_bits = 18\nbiss_zero_count = 1\n"
                    "[firmware]\nbiss_zero_count = 300000\n")
    with pytest.raises(ConfigError, match="firmware.biss_zero_count"):
        load_config(path)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_firmware_model_does_not_import_the_plant_or_the_harness():
    bad = {}
    for path in sorted((ROOT / "firmware_model").rglob("*.py")):
        hit = [m for m in _imports(path) if m.split(".")[0] in ("plant", "hil")]
        if hit:
            bad[str(path.relative_to(ROOT))] = hit
    assert not bad
