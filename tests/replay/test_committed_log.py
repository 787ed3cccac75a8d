"""A log recorded before the code was reorganised replays bit for bit, and the same run
recorded today writes the same frames.

``tests/data/replay/before_layout.mcap`` was written by ``run_logged`` at level "full"
(bench_one_box, hydra_default, 40 cycles, :func:`_pc`) with the code as it stood before the
hardware parts got their own modules. It must stay as it is: if a change makes these tests
fail, the change altered the behaviour of the plant, the sensors, the board, the link or the
MCU, which a reorganisation must not do.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil.framelog import FrameLogReader
from hil.framelog.formats import MCU_UP_WIDTH_U32, split_mcu_up
from hil.replay.fpga_replay import current_trace
from hil.replay.record import run_logged, topics
from hil.replay.replay import _metadata, replay_mcu

LOG = Path(__file__).resolve().parent.parent / "data" / "replay" / "before_layout.mcap"
CYCLES = 40


def _pc(cycle, m):
    """The PC side of the committed run: off, then a force step with a sine on top."""
    if cycle < 15:
        m.set_actuator(0, "off", 0.0)
    else:
        m.set_actuator(0, "force", 200.0 + 100.0 * math.sin(2 * math.pi * cycle / 25))


def test_committed_log_replays_bit_for_bit():
    res = replay_mcu(LOG)
    assert res.ok, res.divergence
    assert res.cycles == CYCLES - 1 and res.mcu_steps == 5 * (CYCLES - 1)
    assert res.fpga_ticks == 20 * (CYCLES - 1)  # the board trace was replayed too


def test_committed_log_catches_a_changed_firmware():
    """The replay is not vacuous: a changed force gain diverges on the log."""
    reader = FrameLogReader(LOG)
    cfg, _, _ = _metadata(LOG, reader.info())
    res = replay_mcu(LOG, cfg.with_overrides({"mcu.kp_force": cfg.get("mcu.kp_force") * 1.05}))
    assert not res.ok and res.divergence.field == "iq_ref"


def test_same_run_today_writes_the_same_frames(tmp_path):
    """Plant, sensors, board, link and MCU together: every block channel of the committed
    log (sensor words, line words, board traces, link memories, fieldbus records) equals
    the one the current code writes for the same run."""
    from hil.fieldbus.topology import load_topology

    old = FrameLogReader(LOG)
    cfg, _, _ = _metadata(LOG, old.info())
    path = tmp_path / "today.mcap"
    run_logged(load_topology("bench_one_box"), cfg, CYCLES, _pc, path, level="full")
    new = FrameLogReader(path)
    block_topics = [c.topic for c in old.info().channels if c.framing == "block"]
    assert topics(0, 0)["trace"] in block_topics and "/sensors/0.0/raw" in block_topics
    for topic in block_topics:
        a, b = old.blocks(topic), new.blocks(topic)
        assert np.array_equal(a.t_ns, b.t_ns), topic
        assert np.array_equal(_today(topic, a.frames, b.frames.shape[1]), b.frames), topic
    assert old.blocks("/fieldbus/frames").frames.tobytes() == \
        new.blocks("/fieldbus/frames").frames.tobytes()


def _today(topic, frames, width):
    """Old frames in today's layout: raw words appended since (sensors added, none fitted
    on this actuator) read 0, in the sensor frames and in the board trace; the upstream
    words in 16 bits."""
    if topic.endswith("/trace"):
        return current_trace(frames)
    if topic.endswith("/up") and frames.shape[1] == MCU_UP_WIDTH_U32:
        # upstream words: uint32 x 33 then, uint16 x 34 now (the count in two halves)
        words, crc = split_mcu_up(frames)
        return np.column_stack([words, crc & 0xFFFF, crc >> 16]).astype(np.uint16)
    if topic.endswith("/raw") and frames.shape[1] < width:
        return np.pad(frames, ((0, 0), (0, width - frames.shape[1])))
    return frames
