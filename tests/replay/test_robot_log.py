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
from hil.replay.record import run_logged
from hil.replay.replay import replay_mcu as replay
from hil.sim.pc import demo_pc
from hil.sim.robot import RobotEngine
from plant.config import load_config

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
    """Upstream frames (1, n, 33) whose piston words hold ``counts`` (hi, lo)."""
    up = np.zeros((1, len(counts), B.UP_WORDS + 1), np.uint32)
    c = np.asarray(counts, np.int64)
    up[0, :, B.U_PISTON_LO] = c & 0xFFFF
    up[0, :, B.U_PISTON_HI] = (c >> 16) & 0xFFFF
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
    run_logged(topo, load_config(None), 60, demo_pc(400.0, 20.0), path, faults=faults,
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
