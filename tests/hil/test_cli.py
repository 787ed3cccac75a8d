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


@pytest.mark.slow
def test_main_job_prints_f1_f2(capsys):
    code, out, err = run(capsys, "main")
    assert code == 0
    assert "F1 open loop" in out and "F2 T-N curve at 18 A" in out
    assert "OUT" not in out  # every F2 figure inside its band


def test_main_job_json(capsys, monkeypatch):
    # The main job's figures are the scenarios f1 and f2, run once each and reported.
    import dataclasses

    from hil import scenarios

    ran = {}
    for name in scenarios.MAIN:
        sc = scenarios.get(name)

        def counted(cfg, progress=None, _run=sc.run, _name=name):
            ran[_name] = _run(cfg, progress)
            return ran[_name]
        monkeypatch.setitem(scenarios.SCENARIOS, name, dataclasses.replace(sc, run=counted))
    code, out, _ = run(capsys, "main", "--json")
    data = json.loads(out)
    assert set(ran) == {"f1", "f2"}
    assert data["F1"]["simulated_peak_hz"] == ran["f1"].metric("simulated peak").value
    assert data["F2"]["simulated"]["stall_force_n"] == ran["f2"].metric("stall force").value
    assert all(data["F2"]["within_band"].values()) and ran["f2"].ok
    assert 50 <= data["F1"]["model_peak_hz"] <= 65
    assert data["F1"]["linear_max_gain_error_db"] < 0.5


@pytest.mark.slow
def test_bode_table_json_and_plot(capsys, tmp_path):
    png = tmp_path / "bode.png"
    code, out, _ = run(capsys, "plant", "bode", "--linear", "--points", "6", "--plot", str(png))
    assert code == 0 and "d_s k_s / G1" in out and "d_s k_s / G3" in out
    assert png.stat().st_size > 10_000
    code, out, _ = run(capsys, "plant", "bode", "--load", "fixed", "--points", "5", "--json")
    data = json.loads(out)
    assert [r["load"] for r in data["responses"]] == ["fixed"]
    assert len(data["responses"][0]["points"]) == 5


@pytest.mark.slow
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
        # Values the configuration check accepted and a model divided by.
        (["run", "current-step", "--set", "inverter.dc_bus_v=0"], "inverter.dc_bus_v"),
        (["run", "f5", "--set", "mcu.period_ticks=100000"], "mcu.period_ticks"),
        # Numbers: refused by their argument type before anything runs.
        (["plant", "bode", "--points", "0"], "--points"),
        (["plant", "bode", "--points", "-3"], "--points"),
        (["plant", "tn-curve", "--current", "1e6"], "--current"),
        (["plant", "tn-curve", "--current", "nan"], "--current"),
        (["bus", "run", "--seconds", "nan"], "--seconds"),
        (["bus", "run", "--seconds", "inf"], "--seconds"),
        (["bus", "run", "--amplitude", "nan"], "--amplitude"),
        (["serve", "--port", "pty", "--seconds", "nan"], "--seconds"),
        (["bench", "identify", "--seconds", "0"], "--seconds"),
        (["bench", "identify", "--seconds", "-3"], "--seconds"),
        (["bench", "identify", "--seconds", "1e9"], "--seconds"),
        (["identify-synth", "x.csv", "--seconds", "nan"], "--seconds"),
        (["bench", "bus", "--cycles", "0"], "--cycles"),
        # Paths.
        (["bus", "run", "--log", "/nonexistent/x.mcap"], "/nonexistent does not exist"),
        (["main", "-c", "/tmp"], "/tmp: is a directory"),
        # Options a verb does not use are not offered.
        (["config", "presets", "-c", "hydra_linear"],
         "argument -c: not an option of eha-hil config presets"),
        (["bench", "codecs", "--set", "sim.seed=2"],
         "argument --set: not an option of eha-hil bench codecs"),
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


def test_config_file_of_the_wrong_kind(capsys, tmp_path):
    (tmp_path / "empty.csv").write_text("")
    (tmp_path / "empty.toml").write_text("\n")
    for name, fragment in (("empty.csv", "expected NAME.toml"), ("empty.toml", "is empty")):
        code, _, err = run(capsys, "config", "show", "-c", str(tmp_path / name))
        assert code == 2 and fragment in err and err.count("\n") == 1, err


def test_identify_synth_never_overwrites_a_non_csv_file(capsys, tmp_path):
    png = tmp_path / "img.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    disguised = tmp_path / "img.csv"  # a picture under a CSV name
    disguised.write_bytes(png.read_bytes())
    for path, fragment in ((png, "ending .csv"), (disguised, "not a text file")):
        code, _, err = run(capsys, "identify-synth", str(path), "--seconds", "1.5")
        assert code == 2 and fragment in err and err.count("\n") == 1, err
        assert path.read_bytes() == png.read_bytes()


@pytest.mark.slow
def test_main_exits_1_when_an_f2_figure_is_out_of_band(capsys):
    # A stronger motor constant puts the stall force far above the 1600..1800 N band.
    code, out, _ = run(capsys, "main", "--json", "--set", "motor.force_at_rated_n=3000")
    data = json.loads(out)
    assert not data["F2"]["within_band"]["stall_force_n"]
    assert code == 1


def test_version(capsys):
    from importlib.metadata import version

    code, out, _ = run(capsys, "--version")
    assert code == 0 and out.strip() == f"eha-hil {version('eha-hil')}"


def test_help_lists_run_thesis_and_exit_codes(capsys):
    code, out, _ = run(capsys, "--help")
    assert code == 0
    run_line = next(line for line in out.splitlines() if line.strip().startswith("run "))
    assert "thesis" in run_line
    assert "130" in out  # the exit codes are in the epilog


def test_every_option_has_help_and_shows_its_default(capsys):
    import argparse

    from hil.cli.args import walk
    from hil.cli.root import build_parser

    missing = [f"{p.prog} {a.option_strings or a.dest}" for p in walk(build_parser())
               for a in p._actions
               if not a.help and not isinstance(a, argparse._SubParsersAction)]
    assert not missing
    code, out, _ = run(capsys, "bench", "plant", "--help")
    assert code == 0 and "(default: 5.0)" in out and "(0, 600]" in out


def test_identify_takes_c_and_set_and_still_the_old_preset(tmp_path):
    from hil.cli.root import build_parser

    data = tmp_path / "d.csv"
    data.write_text("t\n0\n")
    parser = build_parser()
    args = parser.parse_args(["identify", str(data), "-c", "hydra_linear", "--set", "sim.seed=2"])
    assert args.config == "hydra_linear" and args.set == ["sim.seed=2"]
    assert parser.parse_args(["identify", str(data), "--preset", "x"]).config == "x"
    args = parser.parse_args(["bench", "identify", "-c", "hydra_linear"])
    assert args.config == "hydra_linear"
    sub = next(a for a in parser._actions if a.dest == "command").choices
    assert "--preset" not in sub["identify"].format_help()  # a deprecated alias, not shown
    assert "--config" in sub["identify"].format_help()
