"""The eha-hil command line: every verb, JSON output, plots, and one-line errors."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from hil.cli import main


def run(capsys, *argv: str) -> tuple[int, str, str]:
    """``eha-hil ARGV`` in this process: the exit code, stdout, stderr. A value refused by
    its argument type ends in argparse's SystemExit, as in the console script."""
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_main_job_prints_f1_f2(capsys):
    code, out, err = run(capsys, "main")
    assert code == 0
    assert "F1 open loop" in out and "F2 T-N curve at 18 A" in out
    assert "OUT" not in out  # every F2 figure inside its band


def test_main_job_json(capsys):
    code, out, _ = run(capsys, "main", "--json")
    data = json.loads(out)
    assert all(data["F2"]["within_band"].values())
    assert 50 <= data["F1"]["model_peak_hz"] <= 65
    assert data["F1"]["linear_max_gain_error_db"] < 0.5


def test_bode_table_json_and_plot(capsys, tmp_path):
    png = tmp_path / "bode.png"
    code, out, _ = run(capsys, "plant", "bode", "--linear", "--points", "6", "--plot", str(png))
    assert code == 0 and "d_s k_s / G1" in out and "d_s k_s / G3" in out
    assert png.stat().st_size > 10_000
    code, out, _ = run(capsys, "plant", "bode", "--load", "fixed", "--points", "5", "--json")
    data = json.loads(out)
    assert [r["load"] for r in data["responses"]] == ["fixed"]
    assert len(data["responses"][0]["points"]) == 5


def test_tn_curve_plot(capsys, tmp_path):
    png = tmp_path / "tn.png"
    code, out, err = run(capsys, "plant", "tn-curve", "--points", "5", "--plot", str(png))
    assert code == 0 and "stall force" in out
    assert "tn-curve: 5/5" in err  # progress on stderr
    assert png.stat().st_size > 10_000


def test_bench_plant(capsys):
    code, out, _ = run(capsys, "bench", "plant", "--seconds", "0.2", "--json")
    data = json.loads(out)
    assert {r["path"] for r in data["results"]} == {"scheduled", "kernel"}
    assert all(r["real_time_factor"] > 0 for r in data["results"])


def test_bench_codecs_covers_every_codec(capsys):
    code, out, _ = run(capsys, "bench", "codecs", "--seconds", "0.02", "--json")
    names = " ".join(r["name"] for r in json.loads(out)["results"]).lower()
    for codec in ("ssi", "biss", "lvds", "ad7195", "pressure", "ethercat"):
        assert codec in names
    assert code == 0


def test_config_show_and_presets(capsys):
    code, out, _ = run(capsys, "config", "show", "--set", "load.kind=cart")
    assert code == 0 and 'kind = "cart"' in out
    code, out, _ = run(capsys, "config", "presets")
    assert "hydra_linear" in out.split()


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["main", "--set", "hydraulics.jp_kg=-3"], "hydraulics.jp_kg"),
        (["main", "--set", "hydraulics.nokey=3"], "hydraulics.nokey"),
        (["main", "-c", "missing.toml"], "missing.toml"),
        (["plant", "tn-curve", "--plot", "/no/such/dir/x.png"], "--plot"),
        (["plant", "tn-curve", "--plot", "x.txt"], "--plot"),
        (["plant", "bode", "--fmin", "10", "--fmax", "5"], "--fmin"),
        (["plant", "bode", "--linear", "-c", "hydra_default"], "--linear"),
        (["bench", "plant", "--seconds", "-1"], "--seconds"),
        (["bench", "fpga", "--bit-seconds", "0"], "--bit-seconds"),
        (["run", "no-such-scenario"], "no-such-scenario"),
        (["run", "current-step", "--set", "fpga.speed_window_ticks=24"], "speed_window"),
        (["run", "current-step", "--set", "sensors.biss_bits=20"], "biss_bits"),
        (["run", "thesis", "--plot", "x.png"], "--plot-dir"),
        (["run", "current-step", "--plot", "x.png", "--plot-dir", "d"], "--plot-dir"),
        (["run", "current-step", "--plot-dir", "/no/such/dir/d"], "--plot-dir"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(capsys, argv, fragment):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert fragment in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_bad_file_exit_code_through_the_console_script(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[motor]\npole_pairs = 'two'\n")
    exe = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
    proc = subprocess.run([exe, "main", "-c", str(bad)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert str(bad) in proc.stderr and "motor.pole_pairs" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_unknown_verb_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["frobnicate"])
    assert exc.value.code == 2


def test_run_current_step_table_json_and_plot(capsys, tmp_path):
    png = tmp_path / "step.png"
    code, out, _ = run(capsys, "run", "current-step", "--plot", str(png))
    assert code == 0 and "rise time 10-90 %" in out and "overshoot" in out
    assert png.stat().st_size > 10_000
    code, out, _ = run(capsys, "run", "current-step", "--plot-dir", str(tmp_path / "plots"))
    assert code == 0 and (tmp_path / "plots" / "current-step.png").stat().st_size > 10_000
    code, out, _ = run(capsys, "run", "current-step", "--json")
    data = json.loads(out)
    names = {m["name"] for m in data["metrics"]}
    assert {"rise time 10-90 %", "overshoot", "steady-state error"} <= names


def test_run_current_bode_meets_its_requirement(capsys):
    code, out, _ = run(capsys, "run", "current-bode", "--json")
    data = json.loads(out)
    assert code == 0 and data["ok"]


def test_bench_fpga_reports_both_paths(capsys):
    code, out, _ = run(capsys, "bench", "fpga", "--seconds", "0.05", "--bit-seconds", "0.002",
                       "--json")
    data = json.loads(out)
    assert code == 0
    assert [r["path"] for r in data["results"]] == ["value-level", "bit-level"]
    assert all(r["real_time_factor"] > 0 for r in data["results"])
