"""The current loop's RTL in the loop (``fpga.impl = "rtl"``): Verilated, stepped once per
tick by the compiled stack, it drives the motor word for word as the board model does; a
changed RTL is caught in closed loop and named; bad RTL is one line and exit 2. Tests that
need Verilator skip where it is missing."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.fpga.current_loop import INPUT_WIDTHS, OUTPUT_PORTS, OUTPUT_WIDTHS
from firmware_model.fpga.driver_board import DriverBoard
from firmware_model.fpga.rtl_abi import IO_MISMATCHES
from hil.cli import main
from hil.scenarios import get
from hil.sim import verilator as V
from hil.sim.actuator import TRACE_WIDTH, FpgaStack
from hil.sim.verilator import RTL_DIR, RtlError
from hil.verify.current_loop.verify import verify_current_loop
from plant import layout as L


def _need_verilator() -> None:
    missing = V.missing_tools()
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (make system-deps installs "
                    "Verilator)")


@pytest.fixture(scope="module")
def rtl_lib(default_cfg):
    _need_verilator()
    return V.build(RTL_DIR, DriverBoard(default_cfg).params)


def _mutant(tmp_path, old: str, new: str, name: str = "mutant"):
    rtl = tmp_path / name
    shutil.copytree(RTL_DIR, rtl)
    for path in rtl.glob("*.v"):
        text = path.read_text()
        if old in text:
            path.write_text(text.replace(old, new))
            return rtl
    raise AssertionError(f"{old!r} is in no file of the RTL")


#: The proportional term floored instead of rounded half up.
FLOOR_P = ("(kp_e + (34'sd1 <<< (KP_SHIFT - 1))) >>> KP_SHIFT", "kp_e >>> KP_SHIFT")


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint64)


# --- the board, tick by tick -------------------------------------------------------------------
def test_the_board_on_the_rtl_is_the_board_model_through_every_state(default_cfg, rtl_lib):
    """Current mode, a switch to voltage mode and back while enabled (the RTL holds its
    integrators), disabling, an over-current trip and its clearing: every state word,
    upstream register and compare count equal on every tick."""
    boards = [DriverBoard(default_cfg), DriverBoard(default_cfg)]
    loop = V.RtlLoop(rtl_lib)
    loop.attach(boards[1].params)
    rng = np.random.default_rng(7)
    raw = np.zeros(len(B.RAW_NAMES), dtype=np.int64)
    raw[B.R_SSI_OK] = raw[B.R_BISS_OK] = 1
    states = set()
    for k in range(1400):
        down = {B.D_MODE: B.BoardMode.VOLTAGE if 300 <= k < 400 else B.BoardMode.CURRENT,
                B.D_CONTROL: 0 if 600 <= k < 650 or 905 <= k < 910 else B.CTRL_ENABLE,
                B.D_IQ_REF: (6000 if k < 500 else -3000) & 0xFFFF, B.D_ID_REF: 200,
                B.D_VD_REF: 1500, B.D_VQ_REF: (-2500) & 0xFFFF,
                B.D_VQ_FF: int(rng.integers(-3000, 3001)) & 0xFFFF}
        if 908 <= k < 910:
            down[B.D_CONTROL] = B.CTRL_CLEAR_FAULT
        raw[B.R_SSI] = (k * 11) % 2048
        raw[B.R_IA], raw[B.R_IB] = 2048 + rng.integers(-120, 121, 2)
        if k == 900:
            raw[B.R_IA] = 4095  # over the trip level: fault
        for board in boards:
            for addr, value in down.items():
                board.down[addr] = value
            board.state[B.F_SINCE_VALID] = 0
            board.tick(raw)
        py, hw = boards
        assert np.array_equal(py.state, hw.state), (k, np.flatnonzero(py.state != hw.state))
        assert np.array_equal(py.up, hw.up), (k, np.flatnonzero(py.up != hw.up))
        states.add((py.fsm_state, int(py.down[B.D_MODE])))
    assert {("enabled", B.BoardMode.CURRENT), ("enabled", B.BoardMode.VOLTAGE), ("fault", 1),
            ("disabled", B.BoardMode.CURRENT)} <= states
    assert loop.io[IO_MISMATCHES] == 0
    assert boards[1].state[B.F_INTEG_Q] != 0  # the integrators came through the RTL


# --- closed loop: the scenarios --------------------------------------------------------------
def _step_trace(cfg) -> tuple[np.ndarray, np.ndarray]:
    """Plant outputs and the board trace (raw words in, upstream memory, compare counts out)
    of a 10 A step from boot, 440 ticks."""
    stack = FpgaStack(cfg.with_overrides({"load.kind": "fixed"}))
    stack.boot()
    stack.mcu_link.write("iq_ref", 10_000)
    rec = np.zeros((440, L.N_OUTPUTS))
    trace = np.zeros((440, TRACE_WIDTH), dtype=np.int64)
    stack.advance(440, rec, 0, 1, trace)
    return rec, trace


def test_current_step_on_the_rtl_is_bit_for_bit(default_cfg, rtl_lib):
    rtl_cfg = default_cfg.with_overrides({"fpga.impl": "rtl"})
    rec_py, tr_py = _step_trace(default_cfg)
    rec_hw, tr_hw = _step_trace(rtl_cfg)
    assert np.array_equal(bits(rec_py), bits(rec_hw))  # currents, every plant output
    np.testing.assert_array_equal(tr_py, tr_hw)        # compare counts, upstream words
    assert rec_hw[:, L.Y_IQ].max() > 9.0               # the step happened
    a = get("current-step").run(default_cfg, None)
    b = get("current-step").run(rtl_cfg, None)
    assert [m.value for m in a.metrics] == [m.value for m in b.metrics]
    assert V.take_divergences() == []


def _same_result(name: str, cfg) -> None:
    a = get(name).run(cfg, None)
    b = get(name).run(cfg.with_overrides({"fpga.impl": "rtl"}), None)
    assert [(m.name, m.value) for m in a.metrics] == [(m.name, m.value) for m in b.metrics]
    assert a.series.keys() == b.series.keys()
    for key, value in a.series.items():
        assert np.array_equal(bits(np.atleast_1d(np.asarray(value, dtype=float))),
                              bits(np.atleast_1d(np.asarray(b.series[key], dtype=float)))), key
    assert V.take_divergences() == []


def test_current_bode_on_the_rtl_is_bit_for_bit(default_cfg, rtl_lib):
    _same_result("current-bode", default_cfg)


def test_f3_on_the_rtl_is_bit_for_bit(rtl_lib):
    from plant.config import load_config

    _same_result("f3", load_config("hydra_thesis", ()))


# --- a changed RTL ---------------------------------------------------------------------------
def test_a_floored_proportional_term_is_caught_in_closed_loop(default_cfg, tmp_path, capsys):
    """The run names the tick and signal; the stack's words are the board model's up to that
    tick and differ from it on (the RTL drove the motor)."""
    _need_verilator()
    rtl = _mutant(tmp_path, *FLOOR_P)
    V.take_divergences()
    assert main(["run", "current-step", "--rtl", str(rtl)]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"the RTL in {rtl} differs from the board model first at tick" in err
    assert "signal v_d: model 3, RTL 2" in err  # p = round(1287 * 10 / 4096) = 3, floor 2
    assert V.take_divergences() == []  # reported once
    mutant_cfg = default_cfg.with_overrides({"fpga.impl": "rtl", "fpga.rtl_dir": str(rtl)})
    _, tr_py = _step_trace(default_cfg)
    _, tr_hw = _step_trace(mutant_cfg)
    (found,) = V.take_divergences()
    boot = 40  # FpgaStack.boot's ticks before the trace starts
    first = found.tick - boot
    assert 0 <= first < len(tr_py)
    np.testing.assert_array_equal(tr_py[:first], tr_hw[:first])
    assert not np.array_equal(tr_py[first], tr_hw[first])


def test_verify_on_verilator_agrees_and_catches_the_floor(default_cfg, rtl_lib, tmp_path):
    rep = verify_current_loop(default_cfg, 20_000, seed=3, simulator="verilator")
    assert (rep.vectors, rep.mismatches) == (20_000, 0)
    bad = verify_current_loop(default_cfg, 3000, seed=3, rtl_dir=_mutant(tmp_path, *FLOOR_P),
                              simulator="verilator")
    assert bad.mismatches > 0 and bad.first.first.field in ("v_d", "v_q", "integ_d_next",
                                                             "integ_q_next")


# --- bad RTL ---------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["no top", "port width", "syntax"])
def test_a_bad_rtl_is_one_line_and_exit_2(case, tmp_path, capsys):
    _need_verilator()
    if case == "no top":
        rtl = _mutant(tmp_path, "module current_loop #(", "module current_loop_v2 #(")
        why = "no file declares module current_loop"
    elif case == "port width":
        rtl = _mutant(tmp_path, "[15:0] kp,", "[11:0] kp,")
        why = "current_loop.v: port kp is an input of 12 bit, expected an input of 16 bit"
    else:
        rtl = _mutant(tmp_path, "assign v_d = enable", "assign v_d = enabl e")
        why = "current_loop.v:"
    for argv in (["verify", "current-loop", "--against", "rtl", "--rtl", str(rtl)],
                 ["run", "current-step", "--rtl", str(rtl)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and why in err, err
        if case == "syntax":
            assert "%Error" in err


def test_the_port_check_names_what_differs(tmp_path):
    ports = V.expected_ports()
    V.check_ports(ports, tmp_path)
    for changed, message in (
            ({k: v for k, v in ports.items() if k != "ki"}, "no input port ki (16 bit)"),
            (ports | {"count_b": ("output", 12)}, "port count_b is an output of 12 bit"),
            (ports | {"enable": ("output", 1)}, "port enable is an output of 1 bit"),
            (ports | {"debug": ("output", 3)}, "ports the loop does not drive: debug")):
        with pytest.raises(RtlError, match=re.escape(message)):
            V.check_ports(changed, tmp_path)


def test_the_header_parser_reads_kinds_and_widths(tmp_path):
    header = tmp_path / "Vcurrent_loop.h"
    header.write_text("    VL_IN8(&clk,0,0);\n    VL_IN16(&ia_code,11,0);\n"
                      "    VL_OUT16(&count_a,10,0);\n    VL_OUT(&integ_d_next,31,0);\n"
                      "    VL_OUT64(&wide,40,0);\n")
    assert V.declared_ports(header) == {"clk": ("input", 1), "ia_code": ("input", 12),
                                        "count_a": ("output", 11),
                                        "integ_d_next": ("output", 32),
                                        "wide": ("output", 41)}


def test_the_wrapper_moves_every_port_at_its_width():
    code = V.port_code()
    for k, (name, width) in enumerate(INPUT_WIDTHS.items()):
        assert f"t->{name} = static_cast<uint64_t>(in[{k}]) & 0x{(1 << width) - 1:x}ULL;" in code
    for k, (name, signed) in enumerate(OUTPUT_PORTS.items()):
        width = OUTPUT_WIDTHS[name]
        read = f"sign_extend(t->{name}, {width})" if signed else f"static_cast<int64_t>(t->{name})"
        assert f"out[{k}] = {read};" in code


def test_rtl_runs_in_the_single_actuator_stack_only(default_cfg):
    from hil.fieldbus.boxes import StackBox
    from plant.config import ConfigError

    with pytest.raises(ConfigError, match="single-actuator stack only"):
        StackBox.__init__(object.__new__(StackBox), None,
                          default_cfg.with_overrides({"fpga.impl": "rtl"}))


def test_bench_fpga_puts_the_board_models_figure_beside_the_rtls(rtl_lib, capsys, monkeypatch):
    import functools
    import json

    from hil.bench import engines

    # The per-tick call cost is timed over a million ticks whatever --seconds says (~4 s of
    # CPU); the table's rows and their order do not depend on how many ticks are timed.
    monkeypatch.setattr(engines, "bench_loop_call",
                        functools.partial(engines.bench_loop_call, ticks=10_000))
    assert main(["bench", "fpga", "--set", "fpga.impl=rtl", "--seconds", "0.05",
                 "--bit-seconds", "0.002", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [(r["path"], r["current_loop"]) for r in data["results"]] == [
        ("value-level", "board model"), ("value-level", "RTL (Verilator)"),
        ("bit-level", "RTL (Verilator)")]
    assert all(r["cpu_s"] > 0 and r["wall_s"] > 0 for r in data["results"])
    assert len(data["load_average"]) == 3
    assert [c["way"] for c in data["loop_call_ns"]] == [
        "RTL (Verilator), compiled call", "board model's loop, compiled",
        "RTL (Verilator), ctypes call from Python"]
