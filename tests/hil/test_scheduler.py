"""The multi-rate scheduler: periods, phases, order, recording and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.sim.scheduler import Scheduler
from plant.model import Plant


def _rig(cfg, record_every: int = 1):
    """FPGA-, MCU- and PC-rate tasks around a plant, logging when each one ran."""
    plant = Plant(cfg)
    sched = Scheduler(plant, record_every=record_every)
    log: list[tuple[int, str]] = []
    sched.every(1, lambda t: log.append((t, "fpga")), "fpga")
    sched.every(4, lambda t: log.append((t, "mcu")), "mcu", phase=1)

    def pc(t: int) -> None:
        log.append((t, "pc"))
        plant.set_current(8.0 * math.sin(2 * math.pi * 10.0 * t * plant.tick_s))

    sched.every(20, pc, "pc")
    return plant, sched, log


def test_periods_phases_and_order(default_cfg):
    plant, sched, log = _rig(default_cfg)
    sched.run(41)
    ticks = {name: [t for t, n in log if n == name] for name in ("fpga", "mcu", "pc")}
    assert ticks["fpga"] == list(range(41))
    assert ticks["mcu"] == list(range(1, 41, 4))
    assert ticks["pc"] == [0, 20, 40]
    # Within a tick, tasks run in registration order.
    at_20 = [n for t, n in log if t == 20]
    assert at_20 == ["fpga", "pc"]
    assert plant.tick == 41


def test_same_seed_is_bit_identical(default_cfg):
    recs = []
    for _ in range(2):
        _, sched, _ = _rig(default_cfg)
        recs.append(sched.run(4000))
    assert recs[0].plant.tobytes() == recs[1].plant.tobytes()
    assert np.array_equal(recs[0].plant_ticks, recs[1].plant_ticks)


def test_other_seed_changes_only_the_noise(default_cfg):
    other = default_cfg.with_overrides({"sim.seed": 99})
    a = _rig(default_cfg)[1].run(2000)
    b = _rig(other)[1].run(2000)
    assert not np.array_equal(a.col("p_pump_a"), b.col("p_pump_a"))
    assert np.array_equal(a.col("tau_q"), b.col("tau_q"))


def test_split_runs_equal_one_run(default_cfg):
    """Stopping and resuming does not change a bit: the plant never sees where runs split."""
    _, whole, _ = _rig(default_cfg)
    r_whole = whole.run(3000)
    _, split, _ = _rig(default_cfg)
    r1 = split.run(1234)
    r2 = split.run(3000 - 1234)
    joined = np.vstack([r1.plant, r2.plant])
    assert joined.tobytes() == r_whole.plant.tobytes()


def test_progress_does_not_change_results(default_cfg, capsys):
    _, a, _ = _rig(default_cfg)
    _, b, _ = _rig(default_cfg)
    ra = a.run(3000)
    rb = b.run(3000, progress=True, label="test")
    assert ra.plant.tobytes() == rb.plant.tobytes()
    assert "test:" in capsys.readouterr().err


def test_record_decimation_and_probes(default_cfg):
    plant, sched, _ = _rig(default_cfg, record_every=10)
    sched.probe("iq_ref", lambda: plant.u[4], period=20)
    rec = sched.run(200)
    assert list(rec.plant_ticks) == list(range(10, 201, 10))
    t, v = rec.probe("iq_ref")
    assert len(t) == 10 and t[1] == pytest.approx(20 * plant.tick_s)
    assert np.all(np.abs(v) <= 8.0) and np.any(v != 0.0)


def test_bad_registrations(default_cfg):
    sched = Scheduler(Plant(default_cfg))
    with pytest.raises(ValueError):
        sched.every(0, lambda t: None)
    with pytest.raises(ValueError):
        sched.every(4, lambda t: None, phase=4)
    sched.probe("x", lambda: 0.0, 1)
    with pytest.raises(ValueError):
        sched.probe("x", lambda: 0.0, 1)
