"""The driver board's current loop: the model's loop as the RTL sees it (the same words as
:func:`control_tick`), and the Verilog under Icarus/cocotb against it. Tests that need an
absent tool skip and say which."""

from __future__ import annotations

import json
import math
import re
import shutil

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.fpga.current_loop import (
    INPUT_WIDTHS,
    LOOP_INPUT,
    OUTPUT_PORTS,
    OUTPUT_WIDTHS,
    run_model,
)
from firmware_model.fpga.driver_board import DriverBoard
from hil.cli import main
from hil.verify.compare import compare
from hil.verify.current_loop import rtl as rtl_run
from hil.verify.current_loop.records import pack_inputs, unpack_outputs
from hil.verify.current_loop.vectors import loop_sets, random_inputs
from hil.verify.current_loop.verify import verify_current_loop


def _need_rtl() -> None:
    missing = rtl_run.missing_tools()
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (make system-deps)")


def test_sine_rom_holds_the_rounded_quarter_wave():
    text = (rtl_run.RTL_DIR / "sine_rom.v").read_text()
    rom = {int(a): int(v) for a, v in re.findall(r"9'd(\d+): data = 16'd(\d+);", text)}
    assert sorted(rom) == list(range(257))
    for k, v in rom.items():
        assert v == min(32767, round(32768 * math.sin(2 * math.pi * k / 1024))), k


def test_the_loop_model_is_the_board_tick(default_cfg):
    """Words the board's own tick computes in current mode equal the loop model's on the
    same inputs, so the RTL is compared with the board model, not with a copy of it."""
    board = DriverBoard(default_cfg)
    rng = np.random.default_rng(4)
    raw = np.zeros(len(B.RAW_NAMES), dtype=np.int64)
    raw[B.R_SSI_OK] = raw[B.R_BISS_OK] = 1
    board.down[B.D_MODE] = B.BoardMode.CURRENT
    board.down[B.D_CONTROL] = B.CTRL_ENABLE
    n = 1200
    x = np.zeros(n, dtype=LOOP_INPUT)
    got = {k: np.zeros(n, dtype=np.int64) for k in ("i_d", "i_q", "v_d", "v_q", "count_a",
                                                    "count_b", "count_c", "integ_d_next",
                                                    "integ_q_next")}
    for k in range(n):
        raw[B.R_SSI] = (k * 7) % 2048
        raw[B.R_IA], raw[B.R_IB] = 2048 + rng.integers(-150, 151, 2)
        if k % 50 == 0:
            board.down[B.D_IQ_REF] = int(rng.integers(-8000, 8001)) & 0xFFFF
            board.down[B.D_ID_REF] = int(rng.integers(-500, 501)) & 0xFFFF
            board.down[B.D_VQ_FF] = int(rng.integers(-20000, 20001)) & 0xFFFF
        board.state[B.F_SINCE_VALID] = 0  # a fresh downstream word every tick
        board.tick(raw)
        st = board.state
        x[k] = (int(st[B.F_STATE] == B.STATE_ENABLED), raw[B.R_IA], raw[B.R_IB],
                st[B.F_THETA_E], *(board.down[a] for a in (B.D_IQ_REF, B.D_ID_REF,
                B.D_VQ_FF, B.D_CURRENT_LIMIT, B.D_KP, B.D_KI)))
        for name, field in (("i_d", B.F_ID), ("i_q", B.F_IQ), ("v_d", B.F_VD),
                            ("v_q", B.F_VQ), ("count_a", B.F_DUTY_A), ("count_b", B.F_DUTY_B),
                            ("count_c", B.F_DUTY_C), ("integ_d_next", B.F_INTEG_D),
                            ("integ_q_next", B.F_INTEG_Q)):
            got[name][k] = st[field]
    assert x["enable"].mean() > 0.95
    model = run_model(default_cfg, x)
    for name, values in got.items():
        np.testing.assert_array_equal(model[name], values, err_msg=name)
    assert np.abs(got["v_q"]).max() > 100  # the loop did something


def test_testbench_buses_match_the_record_widths():
    """The bit slices tb_current_loop.v connects are the ones pack/unpack use."""
    text = rtl_run.TESTBENCH.read_text()
    slices = re.findall(r"\.(\w+)\((in|out)_bus\[(\d+):(\d+)\]\)", text)
    for bus, widths in (("in", INPUT_WIDTHS), ("out", OUTPUT_WIDTHS)):
        got = [(name, int(lo), int(hi) - int(lo) + 1) for name, b, hi, lo in slices if b == bus]
        expect, pos = [], 0
        for name, width in widths.items():
            expect.append((name, pos, width))
            pos += width
        assert got == expect, bus


def test_pack_and_unpack_place_each_port():
    x = random_inputs(200, 2)
    words = pack_inputs(x)
    assert words[7] & 1 == x["enable"][7]
    assert (words[7] >> 1) & 0xFFF == x["ia_code"][7]
    values = {name: (-5 if OUTPUT_PORTS[name] else 5) * (k + 1)
              for k, name in enumerate(OUTPUT_PORTS)}
    word, pos = 0, 0
    for name, width in OUTPUT_WIDTHS.items():
        word |= (values[name] & ((1 << width) - 1)) << pos
        pos += width
    back = unpack_outputs([word])
    assert {name: int(back[name][0]) for name in OUTPUT_PORTS} == values


def test_vector_sets_cover_the_edges():
    sets = dict(loop_sets(3000, 1))
    assert sum(len(x) for x in sets.values()) == 3000
    edges = sets["edges"]
    assert {0, 4095} <= set(edges["ia_code"].tolist())
    assert {0x8000, 0x7FFF} <= set(edges["iq_ref"].tolist())
    assert {0, 65535} <= set(edges["kp"].tolist())


@pytest.mark.slow
def test_rtl_is_bit_identical_to_the_board_model(default_cfg):
    """At least 10^4 cycles under Icarus: golden, edges and random, every output port."""
    _need_rtl()
    rep = verify_current_loop(default_cfg, 10_000, seed=5, simulator="icarus")
    assert rep.vectors >= 10_000
    assert rep.mismatches == 0, rep.as_dict()["first_mismatch"]


@pytest.mark.slow
def test_a_flipped_rounding_in_the_rtl_is_caught(tmp_path, capsys):
    """A copy of the RTL whose proportional term floors instead of rounding half up (under
    Icarus; Verilator: tests/verify/test_rtl_in_the_loop.py)."""
    _need_rtl()
    rtl = tmp_path / "rtl"
    shutil.copytree(rtl_run.RTL_DIR, rtl)
    pi = rtl / "pi_step.v"
    text = pi.read_text()
    changed = text.replace("(kp_e + (34'sd1 <<< (KP_SHIFT - 1))) >>> KP_SHIFT",
                           "kp_e >>> KP_SHIFT")
    assert changed != text
    pi.write_text(changed)
    assert main(["verify", "current-loop", "--against", "rtl", "--vectors", "1500",
                 "--rtl", str(rtl), "--simulator", "icarus", "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["mismatches"] > 0 and data["first_mismatch"]["field"] in (
        "v_d", "v_q", "integ_d_next", "integ_q_next")


def test_compare_reports_a_changed_word(default_cfg):
    x = random_inputs(100, 3)
    model = run_model(default_cfg, x)
    built = model.copy()
    built["count_b"][42] += 1
    c = compare("random", model, built)
    assert (c.mismatches, c.first.step, c.first.field) == (1, 42, "count_b")


@pytest.mark.parametrize("argv", [["--against", "verilator"], ["--against", "rtl",
                                                                 "--vectors", "many"]])
def test_cli_current_loop_bad_input_is_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["verify", "current-loop", *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_cli_current_loop_rtl_dir_must_hold_verilog(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for where, why in ((tmp_path / "none", "not a directory"),
                       (tmp_path / "empty", "no Verilog")):
        with pytest.raises(SystemExit) as exc:
            main(["verify", "current-loop", "--against", "rtl", "--rtl", str(where)])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and why in err
