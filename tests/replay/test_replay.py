"""Logged fieldbus runs replayed through the MCU model: bit for bit, and a changed gain is
caught at the first step it changes an output, with the right link and field."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.cli import main
from hil.fieldbus.topology import load_topology
from hil.framelog import FrameLogReader
from hil.replay.record import run_logged, topics
from hil.replay.replay import ReplayError, replay_mcu
from plant.config import load_config


def _pc(step_cycle: int):
    def pc(cycle, m):
        # Off first (the MCU holds its controller in reset), then a force step and a sine.
        if cycle < step_cycle:
            m.set_actuator(0, "off", 0.0)
        else:
            m.set_actuator(0, "force", 200.0 + 100.0 * math.sin(2 * math.pi * cycle / 100))
    return pc


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    cfg = load_config("hydra_default")
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    rec = run_logged(load_topology("bench_one_box"), cfg, 400, _pc(100), path, keep=None)
    return cfg, path, rec


def test_replay_matches_bit_for_bit(logged):
    cfg, path, rec = logged
    res = replay_mcu(path)
    assert res.ok, res.divergence
    # Every logged MCU step and cycle was compared (not an empty pass).
    blk = FrameLogReader(path).blocks(topics(0, 0)["down"])
    assert res.mcu_steps == len(blk.t_ns) > 1500
    assert res.cycles == len(FrameLogReader(path).blocks(topics(0)["inputs"]).t_ns)
    assert rec.master["frames_ok"] == 400


def test_log_inputs_equal_the_masters_record(logged):
    """The logged input records are the bytes the master received, cycle by cycle."""
    _, path, rec = logged
    ins = FrameLogReader(path).blocks(topics(0)["inputs"]).frames
    assert np.array_equal(ins, rec.inputs[1:1 + len(ins)])


def test_logged_run_keeps_only_the_input_images_asked_for(tmp_path):
    """A logged run's record holds the last ``keep`` input images (its memory does not
    grow with the run; the log has them all), joined across the run's parts in order."""
    path = tmp_path / "keep.mcap"
    cycles = 30  # parts of one cycle each: the kept images are joined across parts
    rec = run_logged(load_topology("bench_one_box"), load_config("hydra_default"), cycles,
                     _pc(10), path, keep=5)
    assert rec.inputs.shape[0] == 5 and rec.first_cycle == cycles - 5
    ins = FrameLogReader(path).blocks(topics(0)["inputs"]).frames  # after cycles 1..29
    assert np.array_equal(rec.inputs, ins[cycles - 6:cycles - 1])
    assert run_logged(load_topology("bench_one_box"), load_config("hydra_default"), 3,
                      _pc(10), tmp_path / "default.mcap").inputs.shape[0] == 1


def test_changed_gain_is_caught_at_the_first_step_it_acts(logged):
    """kp_force only acts once the controller runs (cycle 100, t = 0.1 s): the replay must
    name the first MCU step after that, the downstream link and the iq_ref register."""
    cfg, path, _ = logged
    changed = cfg.with_overrides({"mcu.kp_force": cfg.get("mcu.kp_force") * 1.05})
    res = replay_mcu(path, changed)
    d = res.divergence
    assert d is not None
    assert d.link == "/lvds/0.0/down" and d.field == "iq_ref"
    assert d.t_s == pytest.approx(0.1, abs=2e-4)
    assert d.expected != d.got


def test_changed_position_gain_is_not_a_false_alarm(logged):
    """A gain the run never used (position loop; the run is in force mode) changes nothing."""
    cfg, path, _ = logged
    res = replay_mcu(path, cfg.with_overrides({"mcu.position_kp_n_per_m": 2.0e4}))
    assert res.ok, res.divergence


def test_tampered_log_diverges_on_the_inputs_record(tmp_path, logged):
    """A logged input record that the model would not produce is reported by field."""
    cfg, path, _ = logged
    from hil.framelog import FrameLogWriter

    reader = FrameLogReader(path)
    info = reader.info()
    out = tmp_path / "tampered.mcap"
    with FrameLogWriter(out, level="mcu") as w:
        w.add_metadata("eha-hil.replay", info.metadata["eha-hil.replay"])
        for ch in info.channels:
            if ch.framing != "block":
                continue
            b = reader.blocks(ch.topic)
            frames = b.frames.copy()
            if ch.topic == topics(0)["inputs"]:
                frames[150, 4] ^= 0x01  # v_piston, low byte, cycle 150
            cid = w.add_block_channel(ch.topic, ch.encoding, dtype=frames.dtype,
                                      width=frames.shape[1])
            w.write_block(cid, b.t_ns, frames)
    d = replay_mcu(out).divergence
    assert d is not None and d.link == "/mcu/0/inputs" and d.field == "s0.v_piston"
    assert d.t_s == pytest.approx(0.151, abs=1e-9)


def test_replay_cli(logged, capsys):
    _, path, _ = logged
    assert main(["replay", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    assert main(["replay", str(path), "--set", "mcu.kd_force_s=0.006"]) == 1
    assert "iq_ref" in capsys.readouterr().out


def _exit_code(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argument checking may refuse a missing file before the command
        return int(exc.code)


def test_replay_bad_files(tmp_path, capsys):
    assert _exit_code(["replay", str(tmp_path / "missing.mcap")]) == 2
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    assert main(["replay", str(junk)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and "missing.mcap" in err
    assert err.splitlines()[-1].startswith(f"eha-hil replay: {junk}: not an MCAP file")


def test_replay_error_without_metadata(tmp_path):
    from hil.framelog import FrameLogWriter

    p = tmp_path / "plain.mcap"
    with FrameLogWriter(p) as w:
        cid = w.add_channel("/x", "raw", schema_name="raw")
        w.write(cid, 0, b"\x01")
    with pytest.raises(ReplayError, match="no replay metadata"):
        replay_mcu(p)


def test_bus_run_cli_exit_codes(tmp_path, capsys):
    assert main(["bus", "run", "--seconds", "0.05", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["master"]["frames_ok"] == 50
    bad = tmp_path / "topo.toml"
    bad.write_text("[[box]]\nid = 3\nslots = ['a']\n")
    assert main(["bus", "run", "--topology", str(bad)]) == 2
    assert "box #0" in capsys.readouterr().err


@pytest.fixture(scope="module")
def logged_full(tmp_path_factory):
    cfg = load_config("hydra_default")
    path = tmp_path_factory.mktemp("replay_full") / "full.mcap"
    run_logged(load_topology("bench_one_box"), cfg, 150, _pc(50), path, level="full")
    return cfg, path


def test_full_log_replays_the_driver_board_too(logged_full):
    _, path = logged_full
    res = replay_mcu(path)
    assert res.ok, res.divergence
    trace = FrameLogReader(path).blocks(topics(0, 0)["trace"])
    assert res.fpga_ticks == len(trace.t_ns) > 2900  # every tick of 150 cycles compared


def test_changed_board_parameter_is_caught_on_the_board_trace(logged_full):
    """A longer ABI speed window changes the board's speed register first: the FPGA replay
    names that register."""
    from hil.replay.fpga_replay import column_name, replay_board

    cfg, path = logged_full
    trace = FrameLogReader(path).blocks(topics(0, 0)["trace"]).frames
    row, col = replay_board(cfg.with_overrides({"fpga.speed_window_ticks": 64}), trace)
    assert row > 0 and column_name(col) == "speed"
    assert replay_board(cfg, trace) == (-1, -1)


def test_tampered_sensor_word_changes_the_board_outputs(logged_full):
    """Flip a bit of the SSI word of one tick while the loop runs: the board's outputs
    diverge at that very tick, so the logged sensor words really drive the replay."""
    from firmware_model.fpga import layout as B
    from hil.replay.fpga_replay import replay_board
    from hil.sim.actuator import TRACE_RAW

    cfg, path = logged_full
    trace = FrameLogReader(path).blocks(topics(0, 0)["trace"]).frames.copy()
    trace[2000, TRACE_RAW + B.RAW_NAMES.index("ssi_count")] ^= 0x40
    row, _ = replay_board(cfg, trace)
    assert row == 2000


def test_faulty_run_log_loses_no_record_and_still_replays(tmp_path):
    """Fieldbus bit flips both ways, drops, duplicates and an LVDS corruption window: every
    frame the master sent and every reply it got is in the log, every MCU step and cycle
    has its records, and the replay is still bit for bit (the faults are upstream of what
    the MCU logged)."""
    cfg = load_config("hydra_default")
    faults = {"seed": 7, "fault": [
        {"link": "fieldbus.down", "kind": "bitflip", "rate": 0.05, "start_s": 0.05,
         "end_s": 0.25},
        {"link": "fieldbus.up", "kind": "bitflip", "rate": 0.05, "start_s": 0.05,
         "end_s": 0.25},
        {"link": "fieldbus.down", "kind": "drop", "rate": 0.05, "start_s": 0.1, "end_s": 0.2},
        {"link": "fieldbus.up", "kind": "duplicate", "rate": 0.05, "start_s": 0.1,
         "end_s": 0.2},
        {"link": "lvds.up", "kind": "bitflip", "rate": 0.01, "box": 0, "slot": 0,
         "start_s": 0.12, "end_s": 0.18},
    ]}
    path = tmp_path / "faulty.mcap"
    rec = run_logged(load_topology("bench_one_box"), cfg, 300, _pc(20), path, faults=faults)
    m = rec.master
    assert m["bad_frames"] > 0 and m["lost_frames"] > 0  # the faults did happen
    reader = FrameLogReader(path)
    info = reader.info()
    received = m["frames_ok"] + m["wkc_errors"] + m["bad_frames"] + m["stale_frames"]
    assert info.channel("/fieldbus/frames").frame_count == m["frames_sent"] + received
    cycles = info.channel(topics(0)["inputs"]).frame_count
    assert cycles == 299
    for t in ("up", "down"):
        assert info.channel(topics(0, 0)[t]).frame_count == 5 * cycles
    assert info.complete
    res = replay_mcu(path)
    assert res.ok, res.divergence
    assert res.mcu_steps == 5 * cycles


def test_full_log_with_sensor_faults_replays_the_board(tmp_path):
    """Sensor faults step the stack tick by tick; the board trace still covers every tick
    and the FPGA replay (dead encoder: frames rejected) is bit for bit."""
    cfg = load_config("hydra_default")
    faults = [{"link": "sensor", "kind": "dead", "box": 0, "slot": 0, "signal": "theta_m",
               "start_s": 0.06, "end_s": 0.07},
              {"link": "sensor", "kind": "noisy", "box": 0, "slot": 0, "signal": "p_cyl_a",
               "sigma": 5e4, "start_s": 0.05, "end_s": 0.09, "seed": 3}]
    path = tmp_path / "sensors.mcap"
    run_logged(load_topology("bench_one_box"), cfg, 120, _pc(40), path, level="full",
               faults=faults)
    res = replay_mcu(path)
    assert res.ok, res.divergence
    assert res.fpga_ticks == 20 * 119


def test_full_log_has_every_lvds_word_consistent_with_the_mcu_memory(logged_full):
    """Level full logs every upstream line word; the last good word of each address before
    an MCU step is exactly what that step's logged upstream memory holds."""
    from protocols import lvds

    _, path = logged_full
    reader = FrameLogReader(path)
    words = reader.blocks("/lvds/0.0/up_words")
    dec = lvds.decode_words_array(words.frames[:, 0])
    assert dec.valid.all()  # a clean run: every word framed and CRC-correct
    ticks = len(reader.blocks(topics(0, 0)["trace"]).t_ns)
    assert abs(len(words.t_ns) - ticks * 500 / 45) <= 1  # 10 MHz, 45-bit words, 50 us
    up = reader.blocks(topics(0, 0)["up"])
    step = 400
    t_step = int(up.t_ns[step])
    before = words.t_ns < t_step
    addr, data = dec.addr[before], dec.data[before]
    for a in range(31):
        last = data[addr == a][-1]
        assert int(last) == int(up.frames[step][a]), a
