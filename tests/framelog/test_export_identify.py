"""``eha-hil log export LOG --format identify OUT``: a run's log as identification input.

The log is recorded with the project's own command (``eha-hil bus run --log``); the exported
CSV is read with the identification reader and compared with the upstream registers decoded
independently by the MCU's own float32 conversion (:class:`Measurements`) and by the encoder
relations of the sensor model.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.mcu.measure import Measurements
from hil.cli import main
from hil.cli.args import Parser
from hil.cli.log import configure_log, run_log
from hil.framelog.formats import ENC_LVDS_UP
from hil.framelog.reader import FrameLogReader
from hil.framelog.writer import FrameLogWriter
from hil.identify.csvdata import read_measured
from plant.config import load_config

SECONDS = 0.3
TOPIC = "/lvds/0.0/up"


@pytest.fixture(scope="module")
def run_log_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("export_identify") / "run.mcap"
    assert main(["bus", "run", "--seconds", str(SECONDS), "--log", str(path),
                 "--amplitude", "500"]) == 0
    return path


def _log_cli(capsys, *argv: str) -> tuple[int, str, str]:
    parser = Parser(prog="eha-hil log")
    configure_log(parser)
    try:
        code = run_log(parser.parse_args(list(argv)))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def exported(run_log_path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export_identify_out") / "id.csv"
    parser = argparse.ArgumentParser()
    configure_log(parser)
    assert run_log(parser.parse_args(["export", str(run_log_path), "--format", "identify",
                                      str(out)])) == 0
    return out


def test_export_reads_as_identification_input(exported, run_log_path):
    d = read_measured(exported)
    assert d.load == "fixed_piston"  # load.kind = fixed, the default configuration
    cfg = load_config(None)
    period_s = cfg.get("mcu.period_ticks") * cfg.get("sim.tick_ns") * 1e-9
    assert d.sample_rate_hz == pytest.approx(1.0 / period_s, rel=1e-12)
    assert not d.notes and d.ignored == []
    assert set(d.columns) == {"iq", "theta_m", "p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b",
                              "p_acc", "x_piston", "f_strain", "temp_c"}
    t_ns, _ = FrameLogReader(run_log_path).blocks(TOPIC)
    # the first frame is the MCU's memory before the board's first upstream sweep
    assert d.n == len(t_ns) - 1
    np.testing.assert_array_equal(np.round(d.t * 1e9).astype(np.int64), t_ns[1:])


def test_columns_match_the_mcus_own_decoding(exported, run_log_path):
    d = read_measured(exported)
    t_ns, frames = FrameLogReader(run_log_path).blocks(TOPIC)
    cfg = load_config(None)
    m = Measurements(cfg)
    names = {"iq": "iq", "p_pump_a": "p_pump_a", "p_pump_b": "p_pump_b", "p_cyl_a": "p_cyl_a",
             "p_cyl_b": "p_cyl_b", "p_acc": "p_acc", "x_piston": "x_piston",
             "f_strain": "f_strain_raw", "temp_c": "temperature_c"}
    ref: dict[str, list[float]] = {k: [] for k in names}
    for row in frames[1:]:
        m.update(row[:B.UP_WORDS])
        for col, attr in names.items():
            ref[col].append(float(getattr(m, attr)))
    for col in names:  # Measurements works in float32
        scale = max(np.abs(ref[col]).max(), 1e-3)
        np.testing.assert_allclose(d.col(col), ref[col], rtol=2e-6, atol=2e-6 * scale,
                                   err_msg=col)
    # the run moved something: a pump pressure and the current are not constant
    assert np.ptp(d.col("iq")) > 0.5 and np.ptp(d.col("p_pump_a")) > 1e5
    # theta_m is the ABI count, unwrapped: modulo a turn it stays the SSI's mount offset
    # from the absolute SSI angle, within a count for the two floors and one for the SSI
    # frame's latency while the motor turns (a wrong sign or scale would wander off)
    n = 1 << cfg.get("sensors.ssi_bits")
    counts = np.round(d.col("theta_m") * cfg.get("firmware.abi_counts_per_rev") / (2 * math.pi))
    offset = (frames[1:, B.U_SSI].astype(np.int64) - counts.astype(np.int64)) % n
    mount = cfg.get("sensors.ssi_mount_rad") * n / (2 * math.pi)
    assert np.all(np.abs(offset - mount) <= 2.5), (offset.min(), offset.max(), mount)
    assert np.ptp(d.col("theta_m")) > 0.5  # the motor turned


def test_export_to_stdout_and_exit_codes(capsys, run_log_path, exported):
    code, out, err = _log_cli(capsys, "export", str(run_log_path), "-", "--format", "identify")
    assert code == 0 and err == ""
    assert out == exported.read_text()
    code, out, err = _log_cli(capsys, "export", str(run_log_path), "-", "--format", "identify",
                              "--board", "1.0")
    assert code == 2 and err.count("\n") == 1 and "no board '1.0' (boards: 0.0)" in err
    code, out, err = _log_cli(capsys, "export", str(run_log_path), "-", "--format", "identify",
                              "--topic", TOPIC)
    assert code == 2 and err.count("\n") == 1 and "--topic: only with --format frames" in err
    code, out, err = _log_cli(capsys, "export", str(run_log_path), "-", "--board", "0.0")
    assert code == 2 and "--board: only with --format identify" in err


def test_truncated_log_exports_what_is_readable_exit_1(capsys, tmp_path, run_log_path):
    cut = tmp_path / "cut.mcap"
    data = run_log_path.read_bytes()
    cut.write_bytes(data[:len(data) * 2 // 3])
    out = tmp_path / "cut.csv"
    code, _, err = _log_cli(capsys, "export", str(cut), str(out), "--format", "identify")
    assert code == 1 and "truncated" in err and err.count("\n") == 1
    d = read_measured(out)
    assert 10 <= d.n < SECONDS * d.sample_rate_hz


def _synthetic_log(path: Path, kind: str | None, boards: tuple[str, ...] = ("0",)) -> Path:
    """A log with upstream snapshots (eha-hil/lvds-up) of ``boards`` and, unless ``kind`` is
    None, the configuration with ``load.kind = kind`` in its metadata; the firmware's strain
    scale (2000 N) differs from the gauge's (3000 N)."""
    meta = {}
    if kind is not None:
        cfg = load_config(None, [f"load.kind={kind}", "firmware.strain_full_scale_n=2000"])
        meta = {"config": json.dumps(cfg.data)}
    regs = np.zeros((20, len(B.UP_REGISTERS)), np.uint16)
    regs[:, B.U_TICK] = np.arange(1, 21) * 4
    regs[:, B.U_IQ] = (np.arange(20) * 100) & 0xFFFF
    regs[:, B.U_PISTON_HI] = 128
    regs[:, B.U_ABI] = (np.arange(20) * 7000 - 3) & 0xFFFF  # wraps at 2^16 twice
    regs[:, B.U_STRAIN_HI] = 0xC0  # code 0xC00000 = 3/2 midscale: half the full scale
    with FrameLogWriter(path, level="mcu", metadata=meta) as w:
        for b in boards:
            ch = w.add_block_channel(f"/lvds/{b}/up", ENC_LVDS_UP, dtype=np.uint16,
                                     width=len(B.UP_REGISTERS))
            w.write_block(ch, np.arange(20) * 200_000, regs)
    return path


def test_lvds_up_channel_and_load_kinds(capsys, tmp_path):
    for kind, case in (("free", "free_piston"), ("conrod", "conrod_fixed")):
        log = _synthetic_log(tmp_path / f"{kind}.mcap", kind)
        out = tmp_path / f"{kind}.csv"
        code, stdout, err = _log_cli(capsys, "export", str(log), str(out), "--format",
                                     "identify")
        assert code == 0, err
        d = read_measured(out)
        assert d.load == case and d.n == 20 and d.sample_rate_hz == 5000
        np.testing.assert_allclose(d.col("iq"), np.arange(20) * 0.1)
        np.testing.assert_allclose(d.col("x_piston"), 0.0)
        np.testing.assert_allclose(d.col("f_strain"), 1000.0)  # the firmware's scale
        # unwrapped across both wraps; the first count -3 read as signed
        np.testing.assert_allclose(d.col("theta_m"), (np.arange(20) * 7000 - 3) * 2 * math.pi
                                   / 2048)


@pytest.mark.parametrize("kind,boards,extra,words", [
    ("cart", ("0",), [], "load.kind = 'cart': identification has no load case"),
    (None, ("0",), [], "no run configuration in the log's metadata"),
    ("fixed", ("0", "1"), [], "2 boards (0, 1): choose one with --board"),
])
def test_logs_without_what_identification_needs(capsys, tmp_path, kind, boards, extra, words):
    log = _synthetic_log(tmp_path / "x.mcap", kind, boards)
    out = tmp_path / "x.csv"
    code, stdout, err = _log_cli(capsys, "export", str(log), str(out), "--format", "identify",
                                 *extra)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"eha-hil log: {log}: ") and words in err, err
    assert not out.exists()


def test_log_without_upstream_channel(capsys, tmp_path):
    log = tmp_path / "bus.mcap"
    with FrameLogWriter(log, level="bus", metadata={"config": "{}"}) as w:
        ch = w.add_json_channel("/signals/x", {"x": "number"})
        w.write_json(ch, 0, {"x": 1.0})
    code, _, err = _log_cli(capsys, "export", str(log), str(tmp_path / "o.csv"), "--format",
                            "identify")
    assert code == 2 and err.count("\n") == 1 and "no upstream register channel" in err


@pytest.mark.slow
def test_bus_run_log_through_identify(tmp_path, capsys):
    """The whole chain with the project's commands: bus run --log, log export --format
    identify, identify (a 2 s run of the default force sine; a report or a refusal that
    says why, never a CSV error)."""
    log, csv_path = tmp_path / "run.mcap", tmp_path / "run.csv"
    assert main(["bus", "run", "--seconds", "2", "--log", str(log), "--amplitude", "600",
                 "--frequency", "7"]) == 0
    assert main(["log", "export", str(log), "--format", "identify", str(csv_path)]) == 0
    capsys.readouterr()
    code = main(["identify", str(csv_path), "--json", "--quiet", "--max-effects", "1"])
    out, err = capsys.readouterr()
    assert code == 0, err
    rep = json.loads(out)
    assert rep["load"] == "fixed_piston" and rep["samples"] > 5000
    assert {c["channel"] for c in rep["channels"]} >= {"p_pump_a", "p_pump_b", "f_strain"}


def test_log_with_32_bit_upstream_words_still_exports(capsys, tmp_path):
    """A log written before the upstream words went to 16 bits (uint32 x 33 per MCU step,
    the committed replay log) exports as identification input from the same words."""
    from hil.framelog.formats import split_mcu_up
    from hil.framelog.identify_export import COLUMNS, _config, signals

    old = Path(__file__).resolve().parents[1] / "data" / "replay" / "before_layout.mcap"
    t_ns, frames = FrameLogReader(old).blocks("/lvds/0.0/up")
    assert frames.dtype == np.uint32 and frames.shape[1] == 33
    out = tmp_path / "old.csv"
    code, _, err = _log_cli(capsys, "export", str(old), str(out), "--format", "identify")
    assert code == 0, err
    d = read_measured(out)
    words, _ = split_mcu_up(frames)
    first = int(np.flatnonzero(words[:, B.U_TICK] != 0)[0])  # the board's first sweep
    assert d.n == len(words) - first > 0
    cfg = _config(str(old), FrameLogReader(old).info())
    # every column as the decoder computed it, bit for bit (the text is exact, not 12 digits)
    ref = signals(words[first:], cfg)
    for col in COLUMNS[1:]:
        np.testing.assert_array_equal(d.col(col), ref[col], err_msg=col)
