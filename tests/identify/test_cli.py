"""The identify verbs through a throwaway argparse built with the configure_* functions."""

from __future__ import annotations

import argparse
import json

import pytest

from hil.cli import identify as cli


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="eha-hil")
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("identify")
    cli.configure_identify(a)
    a.set_defaults(func=cli.run_identify)
    s = sub.add_parser("identify-synth")
    cli.configure_synth(s)
    s.set_defaults(func=cli.run_synth)
    b = sub.add_parser("bench-identify")
    cli.configure_bench(b)
    b.set_defaults(func=cli.run_bench)
    return p


def run(capsys, *argv: str) -> tuple[int, str, str]:
    try:  # a bad number or path is refused by its argument type, before the verb runs
        args = _parser().parse_args(list(argv))
        code = args.func(args)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def coulomb_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("id") / "coulomb.csv"
    args = _parser().parse_args(["identify-synth", str(path), "--effect",
                                 "pump_coulomb_friction", "--seconds", "4",
                                 "--magnitude", "pump_coulomb_friction.force_n=60"])
    assert args.func(args) == 0
    return path


#: The identification's stderr, one item per write() call (filled by report_run).
STDERR_WRITES: list[str] = []


@pytest.fixture(scope="module")
def report_run(coulomb_csv, tmp_path_factory):
    """One identification through the command line with ``--report`` (the whole tool: a
    few seconds), shared by the tests of its text, its files and its JSON summary."""
    import contextlib
    import io

    class Writes(io.StringIO):
        """stderr that also keeps each write() call's text."""

        def __init__(self) -> None:
            super().__init__()
            self.calls: list[str] = []

        def write(self, text: str) -> int:
            self.calls.append(text)
            return super().write(text)

    rdir = tmp_path_factory.mktemp("rep") / "rep"
    args = _parser().parse_args(["identify", str(coulomb_csv), "--report", str(rdir)])
    out, err = io.StringIO(), Writes()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = args.func(args)
    STDERR_WRITES[:] = err.calls
    return code, out.getvalue(), err.getvalue(), rdir


@pytest.mark.slow
def test_each_progress_line_is_one_write(report_run):
    """A line written in two pieces (text, then newline) lets an interrupt's line land
    between them, glued to the progress line: every write is whole lines."""
    calls = STDERR_WRITES
    assert calls and any("round 0" in c for c in calls)
    torn = [c for c in calls if not c.endswith("\n")]
    assert not torn, torn[:3]


@pytest.mark.slow
def test_identify_text_and_report_dir(report_run):
    code, out, err, rdir = report_run
    assert code == 0
    assert "effects added" in out and "pump_coulomb_friction" in out and "NRMSE" in out
    assert "round 0" in err  # progress on stderr
    for name in ("summary.json", "channels.csv", "candidates.csv", "effects.csv",
                 "overlay.png", "residual_before.png", "residual_after.png",
                 "order_spectrum_acf.png"):
        assert (rdir / name).stat().st_size > 100, name


@pytest.mark.slow
def test_json_summary(report_run):
    """``--json`` prints what ``summary.json`` holds (report.to_json of the same report)."""
    rdir = report_run[3]
    data = json.loads((rdir / "summary.json").read_text())
    for key in ("effects_added", "candidates", "channels", "residual_white_before",
                "residual_white_after", "unexplained", "intersample", "input_noise",
                "refused"):
        assert key in data
    assert [e["name"] for e in data["effects_added"]] == ["pump_coulomb_friction"]
    force = data["effects_added"][0]["params"]["force_n"]["value"]
    assert abs(force - 60.0) < 6.0
    assert all({"nrmse_before", "nrmse_after"} <= set(c) for c in data["channels"])
    assert any(c["selected"] and "statistic" in c for c in data["candidates"])
    assert data["residual_white_after"] and not data["residual_white_before"]
    assert data["unexplained"] is False and data["refused"] is None


def test_malformed_csv_exit_2(capsys, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("# load: fixed_piston\n# sample_rate_hz: 5000\nt,iq,p_pump_a,p_pump_b\n"
                   + "".join(f"{k * 2e-4},1,2,3\n" for k in range(5))
                   + "0.001,1,x,3\n" + "".join(f"{k * 2e-4},1,2,3\n" for k in range(6, 20)))
    code, out, err = run(capsys, "identify", str(bad))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("eha-hil identify: ")
    assert "bad.csv:9: column 'p_pump_a'" in err and "Traceback" not in err


def test_unknown_preset_and_bad_report(capsys, coulomb_csv, tmp_path):
    for flag in ("-c", "--preset"):  # --preset: the old name of -c, still accepted
        code, _, err = run(capsys, "identify", str(coulomb_csv), flag, "nope")
        assert code == 2 and err.startswith("eha-hil identify: nope: no such file")
    f = tmp_path / "file"
    f.write_text("x")
    code, _, err = run(capsys, "identify", str(coulomb_csv), "--report", str(f))
    assert code == 2 and "not a directory" in err


def test_synth_bad_magnitude(capsys, tmp_path):
    code, _, err = run(capsys, "identify-synth", str(tmp_path / "x.csv"), "--effect",
                       "input_delay", "--magnitude", "input_delay.speed=3")
    assert code == 2 and err.startswith("eha-hil identify-synth: ") and "unknown key" in err


@pytest.mark.parametrize("realism,key,value", [
    ("plant", "hydraulics.ks_n_per_m", "3.1e7"),
    ("rig", "hydraulics.kc_m2", "2.2e-4"),
])
def test_synth_takes_config_and_set_like_every_verb(capsys, tmp_path, realism, key, value):
    """``-c``/``--set`` make the actuator the record comes from; the rig draws its true
    parameters about the configured values, so a changed k_c shows in the printed truth and
    a changed k_s changes the record."""
    out = tmp_path / "a.csv"
    base = ["identify-synth", str(out), "--realism", realism, "--seconds", "1.5"]
    assert run(capsys, *base)[0] == 0
    plain = out.read_text()
    code, text, err = run(capsys, *base, "--set", f"{key}={value}")
    assert code == 0, err
    assert out.read_text() != plain
    code, _, err = run(capsys, *base, "--set", "hydraulics.nope=1")
    assert code == 2 and err.count("\n") == 1 and "hydraulics.nope" in err


@pytest.mark.parametrize("opt,value", [("--spread", "nan"), ("--spread", "0.9"),
                                       ("--current-noise-lsb", "-1"),
                                       ("--current-noise-lsb", "inf")])
def test_rig_options_refuse_bad_numbers(capsys, tmp_path, opt, value):
    code, _, err = run(capsys, "identify-synth", str(tmp_path / "x.csv"), "--realism", "rig",
                       opt, value)
    # (a plain argparse here: the project's parser makes the usage one line, tested in
    # tests/hil/test_cli_robust.py)
    assert code == 2 and opt in err.splitlines()[-1]
    assert not (tmp_path / "x.csv").exists()


def test_bench_identify_times_the_three_two_effect_records(capsys, monkeypatch):
    """Without --load or --effect the benchmark times one two-effect record per load and
    reports CPU beside wall for each (the identification itself is stubbed: its timing is
    the benchmark's business, not a test's)."""
    seen = []

    def fake(args, cfg, load, effects, profile):
        seen.append((load, tuple(effects), profile))
        return {"samples": 8000, "sample_rate_hz": 5000.0, "load": load, "profile": profile,
                "effects_in_data": effects, "effects_added": list(effects),
                "unexplained": False, "wall_s": 2.0, "cpu_s": 3.0 + len(seen),
                "cpu_ratio_to_budget": (3.0 + len(seen)) / cli.CPU_BUDGET_S,
                "cpu_per_wall": (3.0 + len(seen)) / 2.0}

    monkeypatch.setattr(cli, "_bench_record", fake)
    code, out, _ = run(capsys, "bench-identify", "--seconds", "1.5")
    assert code in (0, None)
    assert seen == list(cli.BENCH_RECORDS)
    assert {load for load, _, _ in seen} == {"fixed_piston", "conrod_fixed", "free_piston"}
    assert all(len(effects) == 2 for _, effects, _ in seen)
    rows = [ln for ln in out.splitlines() if ln.startswith("  ")]
    assert len(rows) == 3 and all("CPU" in r and "wall" in r for r in rows), out
    code, out, _ = run(capsys, "bench-identify", "--seconds", "1.5", "--json")
    data = json.loads(out)
    assert [r["load"] for r in data["records"]] == [r[0] for r in cli.BENCH_RECORDS]
    assert data["cpu_s_max"] == max(r["cpu_s"] for r in data["records"])
    seen.clear()
    run(capsys, "bench-identify", "--load", "free_piston", "--effect", "seal_friction",
        "--profile", "slide")
    assert seen == [("free_piston", ("seal_friction",), "slide")]


def test_bench_identify_refuses_a_profile_the_load_has_not(capsys):
    code, _, err = run(capsys, "bench-identify", "--load", "fixed_piston", "--profile", "slide")
    assert code == 2 and "--profile slide" in err and "free_piston" in err


@pytest.mark.slow
def test_bench_identify_one_short_record(capsys):
    """A real (short) identification timed: CPU and wall both reported, both effects found."""
    code, out, _ = run(capsys, "bench-identify", "--load", "fixed_piston", "--seconds", "2",
                       "--json")
    assert code in (0, None)
    rec = json.loads(out)["records"][0]
    assert rec["cpu_s"] > 0 and rec["wall_s"] > 0
    assert rec["cpu_per_wall"] == pytest.approx(rec["cpu_s"] / rec["wall_s"])
    assert sorted(e.split("[")[0] for e in rec["effects_added"]) == [
        "pump_coulomb_friction", "pump_pulsation"]
