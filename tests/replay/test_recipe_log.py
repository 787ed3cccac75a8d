"""A log recorded under plant recipe 3 replays under recipe 3 after recipe 4 came.

``tests/data/replay/recipe3_robot.mcap`` was written by ``run_logged`` at level "mcu"
(hip_one_box, the robot engine with its plants in lanes, ``sim.plant_numerics = 3``, sensor
noise on, 40 cycles of :func:`_pc`) by the code as it stood before recipe 4. A run "today"
with the log's configuration must write the same frames: the log keeps its recipe, and
recipe 3's noise (the polar method) and physics are unchanged, also where the robot engine
now computes the plants' outputs in lanes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil.fieldbus.topology import load_topology
from hil.framelog import FrameLogReader
from hil.replay.record import run_logged
from hil.replay.replay import _metadata, replay_mcu

LOG = Path(__file__).resolve().parent.parent / "data" / "replay" / "recipe3_robot.mcap"
CYCLES = 40


def _pc(cycle, m):
    """Both hip actuators off, then force steps with a sine on top."""
    for a in (0, 1):
        if cycle < 10:
            m.set_actuator(a, "off", 0.0)
        else:
            m.set_actuator(a, "force", 150.0 * (a + 1) + 100.0 * math.sin(
                2 * math.pi * cycle / 25))


def _frames(path) -> dict[str, bytes]:
    reader = FrameLogReader(path)
    return {c.topic: _canonical(reader.blocks(c.topic).frames)
            for c in reader.info().channels if c.framing == "block"}


def _canonical(frames: np.ndarray) -> bytes:
    """A block's frames; the MCU's upstream records as (32 words, CRC count) whichever
    width the log stores them in (uint32 x 33, or uint16 x 34 with the count in two
    halves)."""
    if frames.ndim == 2 and frames.dtype == np.uint16 and frames.shape[1] == 34:
        crc = frames[:, 32].astype(np.int64) | (frames[:, 33].astype(np.int64) << 16)
        frames = np.column_stack([frames[:, :32].astype(np.int64), crc])
    elif frames.ndim == 2 and frames.dtype == np.uint32 and frames.shape[1] == 33:
        frames = frames.astype(np.int64)
    return frames.tobytes()


def test_the_recipe_three_log_replays_bit_for_bit():
    res = replay_mcu(LOG)
    assert res.ok, res.divergence
    assert res.boxes == 1 and res.mcu_steps == 5 * (CYCLES - 1)


def test_the_same_run_today_under_the_logs_recipe_writes_the_same_frames(tmp_path):
    """Every block channel (the MCU's upstream and downstream words, the fieldbus records)
    equals today's run with the log's configuration; under recipe 4 (another noise
    realisation) the sensor words differ, so the log's recipe is what makes them equal."""
    cfg, _, _ = _metadata(LOG, FrameLogReader(LOG).info())
    assert cfg.get("sim.plant_numerics") == 3
    assert cfg.get("effects.sensor_noise.enabled")
    old = _frames(LOG)
    assert any("/up" in t for t in old)
    runs = {}
    for recipe in (3, 4):
        path = tmp_path / f"today{recipe}.mcap"
        run_logged(load_topology("hip_one_box"), cfg.with_overrides(
            {"sim.plant_numerics": recipe}), CYCLES, _pc, path, level="mcu", model="robot")
        runs[recipe] = _frames(path)
    assert runs[3].keys() == old.keys()
    for topic, frames in old.items():
        assert runs[3][topic] == frames, topic
    assert any(runs[4][t] != f for t, f in old.items() if "/up" in t)
