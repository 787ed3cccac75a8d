"""The frame log of the whole-robot engine (``bus run --model robot --log``): the same
channels and frames as the per-actuator path's log of the same run, replayed bit for bit;
and the log's content: signals that are not measured are left out, torn piston reads are
flagged, a box of sensors that are not simulated has no empty channels."""

from __future__ import annotations

import contextlib
import csv
import math

import numpy as np
import pytest

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from hil.fieldbus.topology import load_topology
from hil.framelog import FrameLogReader
from hil.replay import signals as SG
from hil.replay.record import flush_cycles, run_logged
from hil.replay.replay import replay_mcu as replay
from hil.sim.pc import demo_pc
from hil.sim.robot import RobotEngine
from plant.config import load_config
from tests.framelog.stock_blocks import block_rows

#: Two actuators in box 0, an IMU box (inputs only, not simulated), one actuator in box 2.
TOPOLOGY = """
[[box]]
id = 0
slots = ["a", "b"]
[[box]]
id = 1
slots = [{ name = "imu", kind = "imu" }]
[[box]]
id = 2
slots = ["c"]
"""


@pytest.fixture(scope="module")
def topo(tmp_path_factory):
    path = tmp_path_factory.mktemp("robot_log") / "three.toml"
    path.write_text(TOPOLOGY)
    return load_topology(str(path))


@pytest.fixture(scope="module")
def logs(topo, tmp_path_factory) -> dict[tuple[str, str], object]:
    """(model, level) -> log of the same run: 0.2 s at mcu, 0.02 s at full. Models:
    ``stack`` (per actuator), ``robot`` (the engine's default kernel, the plants in lanes)
    and ``robot-scalar`` (its kernel that runs one actuator at a time)."""
    d = tmp_path_factory.mktemp("robot_logs")
    cfg = load_config(None)
    out = {}
    for level, cycles in (("mcu", 200), ("full", 20)):
        for model in ("stack", "robot", "robot-scalar"):
            path = d / f"{model}-{level}.mcap"
            with _kernel(lanes=model == "robot") as engines:
                run_logged(topo, cfg, cycles, demo_pc(400.0, 20.0), path, level=level,
                           model=model.split("-")[0])
            # the recorder kept the kernel the run was given
            assert [e.lanes for e in engines] == ([] if model == "stack"
                                                  else [model == "robot"])
            out[model, level] = path
    return out


@contextlib.contextmanager
def _kernel(lanes: bool):
    """Robot engines made meanwhile run the plants in lanes or not; yields them."""
    made = []
    init = RobotEngine.__init__

    def make(self, *args, **kwargs):
        init(self, *args, **{**kwargs, "lanes": lanes})
        made.append(self)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RobotEngine, "__init__", make)
        yield made


def _frames(path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    reader = FrameLogReader(path)
    topics = [c.topic for c in reader.info().channels]
    return {t: (b.t_ns, b.frames) for t, b in zip(topics, map(reader.blocks, topics),
                                                  strict=True)}


@pytest.mark.parametrize("model", ["robot", "robot-scalar"])
@pytest.mark.parametrize("level", ["mcu", "full"])
def test_the_robot_engine_logs_what_the_per_actuator_path_logs(logs, level, model):
    """Every channel of the engine's log (either kernel) holds the per-actuator path's
    frames, bit for bit (the raw words, the traces at level full, and the decoded
    signals)."""
    robot, stack = _frames(logs[model, level]), _frames(logs["stack", level])
    assert set(robot) == set(stack)
    assert {"/lvds/0.1/up", "/lvds/2.0/down", "/signals/actuator/2.0"} <= set(robot)
    if level == "full":
        assert {"/fpga/0.1/trace", "/sensors/2.0/raw", "/lvds/0.0/up_words"} <= set(robot)
    for topic, (t, f) in stack.items():
        rt, rf = robot[topic]
        assert np.array_equal(t, rt), topic
        assert np.array_equal(f, rf), topic


def test_the_robot_engine_cuts_the_raw_channels_into_the_per_actuator_paths_blocks(logs):
    """At level mcu both paths write a raw channel's frames in the same blocks
    (``flush_cycles``: one message per channel per block), so that a reader holds the
    same span of each channel between blocks whichever path wrote the log."""
    from mcap.reader import make_reader

    def block_times(path) -> dict[str, list[int]]:
        with open(path, "rb") as f:
            out: dict[str, list[int]] = {}
            for _, ch, m in make_reader(f).iter_messages(log_time_order=False):
                if not ch.topic.startswith(("/signals/", "/fieldbus/")):
                    out.setdefault(ch.topic, []).append(m.log_time)
            return out

    robot, stack = block_times(logs["robot", "mcu"]), block_times(logs["stack", "mcu"])
    assert robot == stack
    n_blocks = -(-200 // flush_cycles("mcu"))  # the fixture's 200 cycles
    assert {len(t) for t in robot.values()} == {n_blocks}


@pytest.mark.parametrize("level", ["mcu", "full"])
def test_every_channel_has_the_per_actuator_paths_encoding_schema_and_metadata(logs, level):
    """The engine's recorder makes each record layout and message once per slot kinds:
    every box still gets the schema of its own slots (box 0 has two actuators, box 2
    one, box 1 an IMU), as the per-actuator path gives it."""
    from mcap.reader import make_reader

    def channels(path) -> dict[str, tuple]:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return {c.topic: (c.message_encoding, c.metadata, summary.schemas[c.schema_id].name,
                          summary.schemas[c.schema_id].encoding,
                          bytes(summary.schemas[c.schema_id].data))
                for c in summary.channels.values()}

    robot, stack = channels(logs["robot", level]), channels(logs["stack", level])
    assert robot == stack
    assert robot["/mcu/0/inputs"][1] != robot["/mcu/2/inputs"][1]  # (the layout)
    assert robot["/signals/box/0/inputs"][2] != robot["/signals/box/2/inputs"][2]


def test_a_robot_engine_log_replays_bit_for_bit(logs):
    r = replay(logs["robot", "mcu"])
    assert r.ok, r.divergence
    assert r.boxes == 3 and r.mcu_steps == 2 * 995 and r.cycles == 3 * 199  # the IMU box: none


def test_the_imu_box_has_no_empty_channels(logs):
    """The IMU box has no outputs record: no outputs channels; its inputs are not
    simulated (zeros on the bus): the raw record is logged, no decoded signals of it."""
    info = FrameLogReader(logs["robot", "mcu"]).info()
    topics = {c.topic for c in info.channels}
    assert "/mcu/1/inputs" in topics
    assert not {t for t in topics if t.startswith(("/mcu/1/outputs", "/signals/box/1/"))}
    assert {"/mcu/0/outputs", "/signals/box/0/outputs", "/signals/box/2/inputs"} <= topics
    for c in info.channels:
        assert c.message_count > 0, c.topic


def _decoded(path, topic: str) -> list:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m for _, _, _, m in reader.iter_decoded_messages(topics=[topic])]


def test_an_unfitted_rod_sensor_is_left_out_not_read_as_minus_20_degc(logs, topo, tmp_path):
    """Default configuration: no rod temperature sensor; its 0 V would read -20.5 degC
    through the MCU's formula. The actuator channel has no such field. Fitted, the field
    is there and reads the rod's temperature (the plant starts at the oil's)."""
    msgs = _decoded(logs["robot", "mcu"], "/signals/actuator/0.0")
    assert msgs and all(not hasattr(m, "rod_temperature_c") for m in msgs)
    assert all(math.isfinite(m.temperature_c) for m in msgs)
    cfg = load_config(None, ["sensors.rod_temperature_fitted=true"])
    path = tmp_path / "rod.mcap"
    run_logged(topo, cfg, 20, demo_pc(), path, model="robot")
    msgs = _decoded(path, "/signals/actuator/2.0")
    t0 = cfg.get("effects.oil_temperature.initial_c")
    assert msgs and all(abs(m.rod_temperature_c - t0) < 3.0 for m in msgs)


def test_the_validity_flags_reach_the_csv_export(logs, tmp_path):
    from hil.cli import main

    out = tmp_path / "run.csv"
    assert main(["log", "export", str(logs["robot", "mcu"]), str(out)]) == 0
    with open(out, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["topic"] == "/signals/actuator/0.0"]
    assert rows and all(r["x_piston_valid"] in ("1", "True", "true") for r in rows)
    assert "rod_temperature_c [degC]" not in rows[0] and "rod_temperature_c" not in rows[0]


def _up_rows(counts: list[int]) -> np.ndarray:
    """Upstream frames (1, n, 33) whose piston words hold ``counts`` (hi, lo), each after
    an upstream sweep of the board (its tick counter non-zero)."""
    up = np.zeros((1, len(counts), B.UP_WORDS + 1), np.uint32)
    c = np.asarray(counts, np.int64)
    up[0, :, B.U_PISTON_LO] = c & 0xFFFF
    up[0, :, B.U_PISTON_HI] = (c >> 16) & 0xFFFF
    up[0, :, B.U_TICK] = np.arange(1, len(counts) + 1)  # the board's sweeps have arrived
    return up


def test_a_torn_piston_read_is_flagged_and_its_neighbours_are_not():
    """The count crosses a 16-bit carry (0x2FFE0 -> 0x30000) while the MCU reads its two
    words: the high word before the carry with the low word after it reads 65536 counts
    (0.33 mm) low, a speed of -1.6 m/s over one MCU step between neighbours of 0.02 m/s.
    That read and the speeds it enters are flagged; a later block carries the state."""
    cal = calibration(load_config(None))
    step = 0x20  # counts per MCU step: 160 nm in 200 us, 0.8 mm/s
    true = [0x2FF60 + step * i for i in range(10)]
    torn = list(true)
    torn[5] = (true[4] & ~0xFFFF) | (true[5] & 0xFFFF)  # hi of before, lo of after
    assert torn[5] == true[5] - 0x10000
    up = _up_rows(torn)
    down = np.zeros((1, 10, B.DOWN_WORDS), np.uint16)
    carry = SG.PistonCarry.start(1)
    keep, cols = SG.actuator_block(cal, up[:, :7], down[:, :7], 1, 200e-6, carry)
    assert cols["x_piston_valid"].tolist() == [True] * 5 + [False, True]
    assert cols["v_piston_valid"].tolist() == [False] + [True] * 4 + [False, False]
    assert cols["v_piston_m_s"][5] < -1.5 and abs(cols["v_piston_m_s"][4]) < 0.01
    keep, cols = SG.actuator_block(cal, up[:, 7:], down[:, 7:], 1, 200e-6, carry)
    assert cols["x_piston_valid"].all() and cols["v_piston_valid"].all()
    # the same steps kept every fifth (a fieldbus cycle): the speed into step 5 is flagged
    carry = SG.PistonCarry.start(1)
    keep, cols = SG.actuator_block(cal, up, down, 5, 200e-6, carry)
    assert keep.tolist() == [4, 9] and cols["v_piston_valid"].tolist() == [True, True]
    assert cols["x_piston_valid"].tolist() == [True, True]


def test_a_real_carry_without_a_tear_is_valid():
    cal = calibration(load_config(None))
    # up across the carry, then back down across it: every read whole
    counts = [0x1FFF0 + 0x8 * i for i in range(6)] + [0x20018 - 0x8 * i for i in range(1, 7)]
    carry = SG.PistonCarry.start(1)
    _, cols = SG.actuator_block(cal, _up_rows(counts), np.zeros((1, 12, 16), np.uint16), 1,
                                200e-6, carry)
    assert cols["x_piston_valid"].all()


def test_a_jump_of_many_carries_is_a_real_jump_not_a_tear():
    """The first words of the link read 0; then the piston's count arrives (2^23 counts
    later): the reads after it are whole."""
    cal = calibration(load_config(None))
    counts = [0, 0x800000, 0x800004, 0x800008]
    _, cols = SG.actuator_block(cal, _up_rows(counts), np.zeros((1, 4, 16), np.uint16), 1,
                                200e-6, SG.PistonCarry.start(1))
    assert cols["x_piston_valid"].all()


def test_a_robot_engine_log_of_a_faulty_bus_replays_bit_for_bit(topo, tmp_path):
    """Dropped, duplicated and delayed output frames: the engine applies what arrived, the
    log holds what it applied, and the replay reproduces every MCU step from it."""
    faults = {"seed": 7, "fault": [
        {"link": "fieldbus.down", "kind": "duplicate", "rate": 0.1},
        {"link": "fieldbus.down", "kind": "drop", "rate": 0.05},
        {"link": "fieldbus.down", "kind": "delay", "rate": 0.05}]}
    path = tmp_path / "faulty.mcap"
    run_logged(topo, load_config(None), 200, demo_pc(400.0, 20.0), path, faults=faults,
               model="robot")
    r = replay(path)
    assert r.ok, r.divergence
    t, _ = FrameLogReader(path).blocks("/mcu/0/outputs")
    assert 150 < len(t) < 200  # some cycles' outputs were lost


def _stock(path) -> dict[str, list[tuple[int, object]]]:
    """Every message of every channel, decoded by the mcap library's stock protobuf
    decoder (no project code), in file order: topic -> [(log time, message)]."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, msg, dec in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(ch.topic, []).append((msg.log_time, dec))
    return out


def _frames_of(msgs) -> tuple[np.ndarray, np.ndarray]:
    """Times and (n, width) frames of a raw block channel's stock-decoded messages."""
    rows = [block_rows(m) for _, m in msgs]
    return np.concatenate([r[0] for r in rows]), np.concatenate([r[1] for r in rows])


def test_the_export_of_a_robot_log_holds_what_the_stock_decoder_reads(logs, tmp_path,
                                                                     monkeypatch):
    """``log export`` of the engine's log, streamed in many small batches and windows (as
    a long log is), read back with pandas from Parquet and CSV, against the mcap library's
    stock protobuf decoding of the same file: one row per frame in time order, every
    field of an actuator's and a box's signal messages, a board's upstream words."""
    import pandas as pd

    from hil.framelog import export as E
    from hil.framelog import export_plan as P

    monkeypatch.setattr(P, "WINDOW_ROWS", 3000)
    monkeypatch.setattr(P, "BATCH_BYTES", 1 << 16)
    path = logs["robot", "mcu"]
    E.export_parquet(path, tmp_path / "x.parquet")
    E.export_csv(path, tmp_path / "x.csv")
    df = pd.read_parquet(tmp_path / "x.parquet")
    dc = pd.read_csv(tmp_path / "x.csv")
    dc.columns = [c.split(" [")[0] for c in dc.columns]
    stock = _stock(path)

    frames = {t: (sum(m.count for _, m in ms) if hasattr(ms[0][1], "count") else len(ms))
              for t, ms in stock.items()}
    assert len(df) == len(dc) == sum(frames.values())
    assert df["topic"].astype(str).value_counts().to_dict() == frames
    assert (np.diff(df["t_ns"].to_numpy()) >= 0).all()
    assert (dc["t_s"].to_numpy() == df["t_ns"].to_numpy() / 1e9).all()
    assert (dc["topic"] == df["topic"].astype(str)).all()

    for topic in ("/signals/actuator/0.1", "/signals/box/2/inputs", "/signals/bus"):
        msgs = stock[topic]
        rows = df[df["topic"] == topic]
        assert rows["t_ns"].tolist() == [t for t, _ in msgs]
        for fd in msgs[0][1].DESCRIPTOR.fields:
            # a float field: the CSV holds the float32's shortest text, exact as float32
            dt = np.float32 if fd.type == fd.TYPE_FLOAT else np.float64
            want = np.array([float(getattr(m, fd.name)) for _, m in msgs]).astype(dt)
            for got in (rows[fd.name], dc.loc[rows.index, fd.name]):
                np.testing.assert_array_equal(got.to_numpy(dt), want, topic + fd.name)

    t, up = _frames_of(stock["/lvds/2.0/up"])
    rows = df[df["topic"] == "/lvds/2.0/up"]
    assert rows["t_ns"].tolist() == t.tolist()
    for addr, name, kind, *_ in B.UP_REGISTERS:
        word = up[:, addr].astype(np.int64) & 0xFFFF
        if kind == "s16":
            word -= (word & 0x8000) << 1
        np.testing.assert_array_equal(rows[name].to_numpy(np.int64), word, name)
        np.testing.assert_array_equal(dc.loc[rows.index, name].to_numpy(np.int64), word)


def test_steps_before_the_first_upstream_sweep_read_nothing():
    """Until the board's first upstream sweep reaches the MCU its memory reads 0: 0 V
    through the MCU's formulas (-3 MPa, the piston 42 mm off) and a speed of ~200 m/s
    into the first real read. Those steps are marked and their board values NaN; the
    speed into the first real read is not valid; from then on all is valid."""
    cal = calibration(load_config(None))
    up = _up_rows([0, 0, 0x800000, 0x800004, 0x800008])
    up[0, :2, B.U_TICK] = 0  # steps 0 and 1: nothing arrived yet
    carry = SG.PistonCarry.start(1)
    _, cols = SG.actuator_block(cal, up, np.zeros((1, 5, 16), np.uint16), 1, 200e-6, carry)
    assert cols["upstream_valid"].tolist() == [False, False, True, True, True]
    assert cols["x_piston_valid"].tolist() == [False, False, True, True, True]
    assert cols["v_piston_valid"].tolist() == [False, False, False, True, True]
    for name in ("p_cyl_a_pa", "x_piston_m", "v_piston_m_s", "iq_a"):
        assert np.isnan(cols[name][:2]).all() and np.isfinite(cols[name][3:]).all(), name
    assert abs(cols["v_piston_m_s"][3]) < 0.001  # 4 counts in 200 us: 0.1 mm/s


def test_the_first_step_of_a_full_level_log_is_marked(logs):
    """At level ``full`` the actuator channel has every MCU step, the first one read
    before any upstream sweep arrived."""
    msgs = _decoded(logs["robot", "full"], "/signals/actuator/0.0")
    assert not msgs[0].upstream_valid and math.isnan(msgs[0].p_cyl_a_pa)
    assert all(m.upstream_valid and math.isfinite(m.p_cyl_a_pa) for m in msgs[1:])
    assert all(m.x_piston_valid for m in msgs[1:]) and not msgs[1].v_piston_valid
def test_the_upstream_crc_count_is_a_u32_at_byte_64(topo, tmp_path):
    """An LVDS link that corrupts upstream words: the MCU's CRC-error count, logged in the
    last two 16-bit words of each upstream frame, reads as the layout states it (a
    little-endian u32 at byte 64, as any reader of eha-hil.layout takes it), counting up
    from 0; the log replays bit for bit."""
    import json
    import struct

    faults = {"fault": [{"link": "lvds.up", "kind": "bitflip", "rate": 0.02, "box": 0,
                         "slot": 0}]}
    path = tmp_path / "crc.mcap"
    run_logged(topo, load_config(None), 30, demo_pc(400.0, 20.0), path, faults=faults,
               model="robot")
    reader = FrameLogReader(path)
    info = reader.info().channel("/lvds/0.0/up")
    lay = json.loads(info.metadata["eha-hil.layout"])
    crc_field = next(f for f in lay["fields"] if f["name"] == "up_crc_errors")
    assert (lay["size"], crc_field["offset"], crc_field["type"]) == (68, 64, "u32")
    _, frames = reader.blocks("/lvds/0.0/up")
    assert frames.dtype == np.uint16 and frames.shape[1] == 34
    counts = [struct.unpack_from("<I", f.tobytes(), 64)[0] for f in frames]
    assert counts[0] == 0 and 10 < counts[-1] < len(counts)  # words lost to the CRC
    assert all(b - a in (0, 1, 2) for a, b in zip(counts, counts[1:], strict=False))
    _, other = reader.blocks("/lvds/0.1/up")
    assert not other[:, 32:].any()  # the healthy link counts nothing
    r = replay(path)
    assert r.ok, r.divergence


def test_pc_commands_of_many_actuators_at_once_equal_one_at_a_time():
    """SG.pc_command_block (what the robot recorder uses) gives each actuator slot the
    columns SG.pc_command_columns gives it alone: output records at shared and at own
    times, and a box with none yet."""
    from hil.fieldbus import pdo

    topo = load_topology("hydra_full")
    boxes = [b for b in topo.boxes if b.actuators][:3]
    rng = np.random.default_rng(4)
    steps = np.arange(5, 500, 5)
    shared = np.arange(0, 480, 20)
    parts = []
    for n_box, box in enumerate(boxes):
        width = sum(s.sizes[0] for s in box.slots)
        t = shared if n_box != 1 else np.arange(13, 480, 20)
        if n_box == 2:
            t = t[:0]
        rec = rng.integers(0, 256, (len(t), width), dtype=np.uint8)
        for slot, s in enumerate(box.slots):
            if s.kind == "actuator":
                rec[:, sum(x.sizes[0] for x in box.slots[:slot])] = rng.integers(0, 3, len(t))
                parts.append((t, rec, box, slot))
    assert len({id(p[0]) for p in parts}) == 3 and pdo.ACTUATOR_OUT_DTYPE.itemsize
    got = SG.pc_command_block(parts, steps)
    one = [SG.pc_command_columns(*p, steps) for p in parts]
    for name in one[0]:
        np.testing.assert_array_equal(got[name], np.concatenate([o[name] for o in one]))
    assert np.isfinite(got["force_command_n"]).any() and got["pc_enable"].any()


def test_a_torn_read_flags_the_box_record_that_reports_it():
    """The box's input record reports the position of each cycle's last MCU step and the
    speed over the cycle: a tear in that step flags the record's position and the speeds
    into and out of it; the first record's speed has no record before it."""
    cal = calibration(load_config(None))
    step = 0x20
    true = [0x2FEE0 + step * i for i in range(15)]  # crosses a carry at step 9
    torn = list(true)
    torn[9] = (true[8] & ~0xFFFF) | (true[9] & 0xFFFF)  # the second cycle's last read
    assert torn[9] != true[9]
    up = _up_rows(torn)
    down = np.zeros((1, 15, 16), np.uint16)
    t_steps = np.arange(15) * 20  # MCU steps every 20 ticks, cycles of 100 ticks
    carry = SG.PistonCarry.start(1)
    SG.actuator_block(cal, up[:, :10], down[:, :10], 5, 200e-6, carry)
    x_ok, v_ok = SG.report_flags(carry, t_steps[:10], np.array([100, 200]))
    assert x_ok.tolist() == [[True, False]] and v_ok.tolist() == [[False, False]]
    SG.actuator_block(cal, up[:, 10:], down[:, 10:], 5, 200e-6, carry)
    x_ok, v_ok = SG.report_flags(carry, t_steps[10:], np.array([300]))
    assert x_ok.tolist() == [[True]] and v_ok.tolist() == [[False]]  # from the torn one


def test_the_box_records_carry_piston_flags(logs):
    for model in ("robot", "stack"):
        msgs = _decoded(logs[model, "mcu"], "/signals/box/0/inputs")
        for k in (0, 1):
            assert all(getattr(m, f"s{k}_x_piston_valid") for m in msgs)
            assert [getattr(m, f"s{k}_v_piston_valid") for m in msgs[:3]] == [False, True, True]


def test_a_logged_run_keeps_the_engines_path(topo, tmp_path, monkeypatch):
    """Logging changes no choice of the engine (lanes, compute threads, overlap, batches):
    the compiled calls are made once per run, only with the log's rows, and not again per
    block (which would restart the helper threads every 100 cycles)."""
    from hil.fieldbus.system import BusSystem

    made = []
    calls = RobotEngine._calls

    def counting(engine, ticks):
        if engine._stale:
            made.append((engine.lanes, engine._workers(), engine.overlap,
                         engine._blocks.tobytes(), engine.log_rows.up.shape[1] > 0))
        return calls(engine, ticks)

    monkeypatch.setattr(RobotEngine, "_calls", counting)
    cfg = load_config(None)
    with BusSystem(topo, cfg, "inproc", model="robot") as bs:
        bs.run(5, demo_pc(), keep=1)
    run_logged(topo, cfg, 120, demo_pc(), tmp_path / "path.mcap", model="robot")
    assert len(made) == 2  # the bare run's and the logged run's, each once
    assert made[0][:4] == made[1][:4] and (made[0][4], made[1][4]) == (False, True)


def test_the_engine_copies_each_cycles_images_until_the_log_rows_are_full(topo):
    """At each cycle's end the engine's compiled call (give_inputs) copies the images of the
    cycle (the input image it gave, the outputs and received flags it took) and its ticks
    into the log's next row and moves the tap's row on by the cycle's MCU steps; once the
    rows are full it copies nothing (the recorder flushes before that)."""
    from hil.fieldbus.system import BusSystem
    from hil.sim.stack_rows import ImageRows

    with BusSystem(topo, load_config(None), "inproc", model="robot") as bs:
        e = bs.chain.engine
        rows = 2
        images = ImageRows(np.zeros((rows, len(e.out_image)), np.uint8),
                           np.zeros((rows, e.n), bool),
                           np.zeros((rows, len(e.in_image)), np.uint8),
                           np.zeros(rows, np.int64), np.zeros(rows, np.int64),
                           np.zeros(1, np.int64))
        e.log_images = images
        seen = []
        give = e._give_inputs

        def spy(ticks: int) -> None:  # what the engine holds at each cycle's end
            give(ticks)
            seen.append((e.in_image.copy(), e.out_image.copy(), e._got.copy(), e.tick, ticks))

        e._give_inputs = spy
        bs.run(5, demo_pc(400.0, 20.0))
        e.wait()
        tap_row = int(e.log_rows.row[0])
    assert len(seen) > rows  # cycles ended after the rows were full
    assert int(images.at[0]) == rows
    for j in range(rows):
        inp, out, got, tick, ticks = seen[j]
        assert np.array_equal(images.inp[j], inp)
        assert np.array_equal(images.out[j], out)
        assert np.array_equal(images.got[j], got)
        assert (images.t_in[j], images.t_out[j]) == (tick, tick - ticks)
    assert tap_row == sum(ticks // e.period for *_, ticks in seen[:rows])
    assert images.got[0].any() and images.inp[1].any()  # (real images, not the zeros)
