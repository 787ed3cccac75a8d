"""MCU tunables on the compiled robot engine (hil.sim.robot, hil.sim.robot_tunables): a
write changes that actuator's C program as a calibration with that value would have built
it, bit for bit, and no other actuator; through the boxes' CoE mailbox a write is taken
and a value out of range is refused with its code and changes nothing."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from firmware_model.esc import objects
from firmware_model.esc.objects import Abort
from firmware_model.mcu.c_abi import OUTPUT, STATE_HEAD
from firmware_model.mcu.tunables import TUNABLES
from hil.fieldbus import pdo
from hil.fieldbus.boxes import _IN, box_engine, make_box
from hil.fieldbus.chain import CYCLE_TICKS
from hil.fieldbus.esc.chain import EscChain
from hil.sim.robot import RobotEngine
from tests.fieldbus.test_coe import Client
from tests.fieldbus.test_esc import THREE

#: Per tunable: a value that shows in the run below (a limit that binds, a cutoff far from
#: the calibration's, a timeout shorter than the silence at the end), and the force
#: feedback that uses it.
WRITES = {
    "kp_force": 0.5, "kd_force_s": 0.02, "derivative_filter_hz": 50.0,
    "friction_observer_hz": 5.0, "seal_observer_hz": (200.0, "strain"),
    "complementary_cutoff_hz": (5.0, "complementary"), "position_kp_n_per_m": 40_000.0,
    "force_limit_n": 150.0, "pressure_limit_pa": 1.0e6, "current_limit_a": 2.0,
    "command_timeout_s": 0.002,
}
TUNED = 1  # chain order: box 0's second actuator
FORCES_N = (300.0, -250.0)  # per slot


def test_every_tunable_has_a_write_here():
    assert set(WRITES) == {t.key for t in TUNABLES}


def _engine(cfg) -> tuple[RobotEngine, list]:
    boxes = [make_box("robot", b, cfg) for b in THREE.boxes]
    return RobotEngine(boxes, cfg, workers=1, overlap=False), boxes


def _record(box, cycle: int) -> bytes:
    """Force steps (cycles 0-24), then a position command 1 mm off mid-stroke (25-44)."""
    rec = bytearray(box.out_dtype.itemsize)
    for slot, k in enumerate(box.act):
        if cycle < 25:
            mode, value = 1, round(FORCES_N[slot] / pdo.FORCE_CMD_LSB)
        else:
            mode, value = 2, round(1e-3 / pdo.POSITION_CMD_LSB)
        struct.pack_into("<BBi", rec, box._out_off[k], mode, pdo.FLAG_ENABLE, value)
    return bytes(rec)


def _run(engine: RobotEngine, boxes: list, cycles: int = 55) -> list[np.ndarray]:
    """Per actuator, one row of bytes per cycle: the MCU program's output record (every
    float it holds), the plant's outputs and the box's input record. The last 10 cycles
    send nothing (the command watchdog)."""
    rows: list[list[bytes]] = [[] for _ in range(engine.n)]
    for cycle in range(cycles):
        if cycle < 45:
            for b in boxes:
                if getattr(b, "board", None) is not None:
                    b.apply(_record(b, cycle))
        engine.advance(CYCLE_TICKS)
        out = engine.out.view(np.uint8).reshape(engine.n, OUTPUT.itemsize)
        for j in range(engine.n):
            at = engine._in_at[j]
            rows[j].append(out[j].tobytes() + engine.arrays.plant.y[j].tobytes()
                           + engine.in_image[at:at + _IN.size].tobytes())
    return [np.frombuffer(b"".join(r), dtype=np.uint8).reshape(cycles, -1) for r in rows]


@pytest.mark.parametrize("key", list(WRITES))
def test_a_write_gives_the_engine_built_with_that_value_for_that_actuator_only(cfg, key):
    value, feedback = WRITES[key] if isinstance(WRITES[key], tuple) else (WRITES[key],
                                                                          "pressure")
    cfg = cfg.with_overrides({"mcu.force_feedback": feedback}, feedback)
    untouched = _run(*_engine(cfg))
    written, boxes = _engine(cfg)
    written.tune(boxes[0], TUNED, key, value)
    got = _run(written, boxes)
    calibrated = _run(*_engine(cfg.with_overrides({f"mcu.{key}": value}, key)))
    assert np.array_equal(got[TUNED], calibrated[TUNED])
    assert not np.array_equal(got[TUNED], untouched[TUNED])  # the write shows
    for j in range(written.n):
        if j != TUNED:
            assert np.array_equal(got[j], untouched[j]), f"actuator {j} changed"


def test_a_write_mid_run_equals_the_python_model_path(cfg):
    """Force limit and gain written between two cycles of a running engine: the engine's
    box inputs equal those of the per-actuator boxes (the Python MCU, tuned at its next
    step), bit for bit, before and after."""
    engine, boxes = _engine(cfg)
    ref = [make_box("stack", b, cfg) for b in THREE.boxes]
    for cycle in range(40):
        if cycle == 15:
            engine.tune(boxes[0], TUNED, "force_limit_n", 150.0)
            engine.tune(boxes[2], 0, "kp_force", 0.5)
            ref[0].board.mcu.tune(TUNED, "force_limit_n", 150.0)
            ref[2].board.mcu.tune(0, "kp_force", 0.5)
        for b, r in zip(boxes, ref, strict=True):
            if getattr(b, "board", None) is not None:
                b.apply(_record(b, cycle))
                r.apply(_record(r, cycle))
        engine.advance(CYCLE_TICKS)
        for b, r in zip(boxes, ref, strict=True):
            r.advance(CYCLE_TICKS)
            assert b.inputs() == r.inputs(), f"cycle {cycle}"


def test_the_state_head_is_where_the_c_program_keeps_its_configuration(cfg):
    """The C program's own gains in use after init are the configuration's: read through
    STATE_HEAD's offsets (a layout mismatch reads other bytes)."""
    engine, _ = _engine(cfg)
    size = engine.law.state_size
    head = engine.states[:STATE_HEAD.itemsize].view(STATE_HEAD)[0]
    assert size >= STATE_HEAD.itemsize
    assert head["kp"] == head["cfg"]["kp"] == np.float32(2.0)
    assert head["k_pos"] == head["cfg"]["k_pos"] == np.float32(10_000.0)


class RobotEscChain(EscChain):
    """The readable ESC chain with the robot engine behind its boxes (as ``serve --model
    robot`` runs it: outputs taken, the engine one cycle on, the mailboxes served)."""

    def __init__(self, topo, cfg) -> None:  # noqa: ANN001
        super().__init__(topo, cfg, "robot")
        self.engine = box_engine("robot", self.boxes, cfg, overlap=False)

    def advance_boxes(self) -> None:
        self.engine.advance(CYCLE_TICKS)
        self.mailboxes.step()
        self.stats.cycles += 1


def test_the_mailbox_takes_a_tunable_on_the_robot_engine_and_refuses_out_of_range(cfg):
    chain = RobotEscChain(THREE, cfg)
    c = Client(chain)
    c.m.bring_up(to_op=False)
    engine = chain.engine
    heads = [engine.states[j * engine.law.state_size:][:STATE_HEAD.itemsize]
             .view(STATE_HEAD)[0] for j in range(engine.n)]
    kp0 = float(heads[0]["kp"])
    start = [h.tobytes() for h in heads]
    assert c.download(0x2000, 2, struct.pack("<f", 0.5)) == 0
    assert c.upload(0x2000, 2) == struct.pack("<f", 0.5)
    chain.cycle()  # the engine's next step
    assert [float(h["kp"]) for h in heads] == [kp0, 0.5, kp0]
    before = [h.tobytes() for h in heads]
    assert c.download(0x2000, 2, struct.pack("<f", 25.0)) == Abort.VALUE_HIGH
    assert c.download(0x2007, 1, struct.pack("<f", -1.0)) == Abort.VALUE_LOW
    chain.cycle()
    assert [h.tobytes() for h in heads] == before
    assert c.upload(0x2000, 2) == struct.pack("<f", 0.5)
    assert c.download(0x2100, 0, struct.pack("<I", objects.RESTORE_SIGNATURE)) == 0
    chain.cycle()
    assert [h.tobytes() for h in heads] == start  # every tunable the calibration's again
