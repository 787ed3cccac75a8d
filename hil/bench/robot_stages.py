"""Where the robot engine's time goes: each stage of the per-tick work (plant RK4, plant
outputs with noise, sensor chips, driver board, LVDS link, MCU law) timed on its own over
every actuator of a warmed-up ``hydra_full`` robot, in CPU ns per actuator tick.

Each stage runs from a snapshot of the robot's arrays, alone, ``ticks`` times over all
actuators, in the order the engine would visit them (the per-actuator layout: every
actuator's whole stage, one after the other; or, for the lane-wise engine, each stage over
all actuators at once). A stage alone keeps its working set in cache as it would inside the
engine, and its inputs are those the engine left (a running robot), so the figures add up
to the compiled call's cost to within the calls' overhead (``total`` row: the engine's
compiled call itself over the same cycles). The last row is the per-cycle Python around that
call (:mod:`hil.bench.robot_cycle`), per actuator tick for comparison."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga.tick import control_tick
from firmware_model.lvds import lanes as link_lanes
from firmware_model.lvds import link as LK
from hil.bench.robot_cycle import python_per_cycle
from hil.sim.actuator import drive_lanes
from hil.sim.robot import _IN_FLAGS as IN_FLAGS
from hil.sim.robot import _IN_TICK as IN_TICK
from hil.sim.robot import _mcu_lanes_load as mcu_lanes_load
from hil.sim.robot import _mcu_lanes_step as mcu_lanes_step
from hil.sim.robot import _mcu_lanes_store as mcu_lanes_store
from hil.sim.robot import _mcu_law_step_many as mcu_law_step_many
from plant import kernel, lanes
from plant import layout as L
from plant.config import Config
from plant.lane_outputs import load_outputs, outputs_in_lanes, store_outputs
from plant.sensors import lanes as sensor_lanes
from plant.sensors.harness import digitise

#: Stage names, in the order of one tick.
STAGES = ("plant RK4 + effects", "plant outputs + noise", "sensor chips", "driver board",
          "LVDS link", "MCU law (C build), one actuator at a time",
          "plant RK4 + effects, in lanes", "sensor chips, in lanes", "LVDS link, in lanes",
          "plant outputs + noise, in lanes", "driver board + inverter, in lanes",
          "MCU law, in lanes")


@njit(cache=True, nogil=True)
def _stage(which, n_ticks, tick0, x, p, u, y, rng, work, k, raw, c, st, down, up, mdown,
           mup, lk):
    """``n_ticks`` ticks of one stage for every actuator (rows), actuator by actuator."""
    for i in range(x.shape[0]):
        for j in range(n_ticks):
            if which == 0:
                kernel.rk4_tick(x[i], p[i], u[i], work[i])
            elif which == 1:
                kernel.outputs(x[i], p[i], u[i], rng[i], y[i])
            elif which == 2:
                digitise(y[i], k[i], tick0 + j, raw[i])
            elif which == 3:
                control_tick(c[i], st[i], down[i], up[i], raw[i])
            else:
                LK.sweep_down(lk[i], mdown[i], st[i], down[i])
                LK.sweep_up(lk[i], up[i], mup[i])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _rk4_in_lanes(n_ticks, x, p, u, blocks, sizes, n_sub_max, buf):
    """``n_ticks`` RK4 ticks of every actuator, batch by batch in lanes: states and inputs
    loaded when the batch is claimed and stored at its end, as the engine does. (The lane
    harnesses compile as the engine's kernel: numpy's error model, so that the stages they
    inline get no division-by-zero check per lane, and no reference counting, so that
    their row views count no references.)"""
    for b in range(blocks.shape[0]):
        lanes.load_params(buf, p, blocks[b], sizes[b])
        lanes.load_states(buf, x, u, blocks[b], sizes[b])
        for _ in range(n_ticks):
            lanes.rk4_lanes(buf, n_sub_max)
        lanes.store_states(buf, x, blocks[b], sizes[b])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _sensors_in_lanes(n_ticks, tick0, blocks, sizes, y, rng, k, raw, c, st, down, sb, buf, fb):
    """``n_ticks`` ticks of the sensor chips of every actuator, batch by batch in lanes,
    with the loads at each batch's claim and the stores at its end, as the engine makes
    them (the chips read the plant outputs in the plant lanes and write the raw words into
    the board lanes)."""
    for b in range(blocks.shape[0]):
        rows, m = blocks[b], sizes[b]
        fpl.load_board(fb, c, st, raw, down, rows, m)
        load_outputs(buf, y, rng, rows, m)
        sensor_lanes.load_chips(sb, k, rows, m)
        for j in range(n_ticks):
            sensor_lanes.digitise_lanes(sb, buf, fb, k, rows, m, tick0 + j, y, raw)
        fpl.store_board(fb, st, raw, down, rows, m)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _link_in_lanes(n_ticks, blocks, sizes, raw, c, st, down, up, mdown, mup, lk, lb, fb):
    """``n_ticks`` ticks of both LVDS sweeps of every actuator, batch by batch in lanes,
    with the loads at each batch's claim and the stores at its end, as the engine makes
    them (the downstream sweep writes the board lanes)."""
    for b in range(blocks.shape[0]):
        rows, m = blocks[b], sizes[b]
        fpl.load_board(fb, c, st, raw, down, rows, m)
        link_lanes.load_link(lb, lk, rows, m)
        for _ in range(n_ticks):
            link_lanes.sweep_down_lanes(lb, lk, mdown, fb, st, down, rows, m)
            link_lanes.sweep_up_lanes(lb, lk, up, mup, rows, m)
        link_lanes.store_link(lb, lk, rows, m)
        fpl.store_board(fb, st, raw, down, rows, m)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _outputs_in_lanes(n_ticks, x, p, u, y, rng, blocks, sizes, buf):
    """``n_ticks`` ticks of every actuator's outputs and noise, batch by batch in lanes,
    from the states in the lane buffer (the engine computes them right after the RK4 step,
    with no move in), outputs and noise streams stored at the batch's end."""
    for b in range(blocks.shape[0]):
        lanes.load_params(buf, p, blocks[b], sizes[b])
        lanes.load_states(buf, x, u, blocks[b], sizes[b])
        load_outputs(buf, y, rng, blocks[b], sizes[b])
        for _ in range(n_ticks):
            outputs_in_lanes(buf, rng, blocks[b], sizes[b])
        store_outputs(buf, y, rng, blocks[b], sizes[b])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _board_in_lanes(n_ticks, c, st, down, up, raw, blocks, sizes, fb, buf):
    """``n_ticks`` board ticks and inverter moves of every actuator, batch by batch in
    lanes: state and exchange words loaded when the batch is claimed and stored at its end,
    the upstream words scattered into the boards' rows every tick, the inverter into the
    plant lanes, as the engine does."""
    for b in range(blocks.shape[0]):
        fpl.load_board(fb, c, st, raw, down, blocks[b], sizes[b])
        for _ in range(n_ticks):
            fpl.board_tick(fb, blocks[b], sizes[b], raw, down, st, up, c)
            drive_lanes(fb, buf, blocks[b])
        fpl.store_board(fb, st, raw, down, blocks[b], sizes[b])


@njit(cache=True, nogil=True)
def _mcu_law(in_lanes, n_cycles, per_cycle, tick0, period, blocks, sizes, bases, sizes_b,
             in32, lanes_at):
    """``n_cycles`` cycles of ``per_cycle`` MCU steps of every actuator, batch by batch as
    the engine's kernels make them: each actuator's C law on its own
    (``mcu_law_step_many`` for one, :func:`hil.sim.robot.advance_robot`), or the batch in
    lanes (``in_lanes``: ``mcu_lanes_*``, buffer at ``lanes_at``, loaded at each claim and
    stored at the cycle's end, :func:`hil.sim.robot.advance_robot_lanes`), with the tick and
    flags the engine writes into the input records at each step. ``bases``: the states',
    inputs' and outputs' addresses, ``sizes_b`` their records' sizes."""
    for c in range(n_cycles):
        for b in range(blocks.shape[0]):
            rows, m = blocks[b], np.uint32(sizes[b])
            if in_lanes:
                mcu_lanes_load(lanes_at, bases[0], rows.ctypes.data, m)
            for n in range(per_cycle):
                t = tick0 + (c * per_cycle + n) * period
                for j in range(m):
                    in32[rows[j], IN_TICK] = t
                if in_lanes:
                    mcu_lanes_step(lanes_at, bases[1], bases[2], rows.ctypes.data, m)
                else:
                    for j in range(m):
                        i = rows[j]
                        mcu_law_step_many(bases[0] + i * sizes_b[0], bases[1] + i * sizes_b[1],
                                          1, bases[2] + i * sizes_b[2])
                for j in range(m):
                    in32[rows[j], IN_FLAGS] = 0
            if in_lanes:
                mcu_lanes_store(lanes_at, bases[0], bases[2], rows.ctypes.data, m)


@dataclass
class StageCosts:
    """CPU ns per actuator tick of each stage (``rows``: (stage, ns)), over ``ticks``."""

    actuators: int
    ticks: int
    rows: list[tuple[str, float]]


def _snapshot(arrays) -> list[np.ndarray]:
    s = arrays
    return [a.copy() for a in (s.plant.x, s.plant.params, s.plant.u, s.plant.y, s.plant.rng,
                                s.plant.work, s.sensors.chips, s.sensors.raw, s.board.params,
                                s.board.state, s.board.down, s.board.up, s.link.mcu_down,
                                s.link.mcu_up, s.link.state)]


def stage_costs(cfg: Config, ticks: int = 2000, warm_s: float = 0.2,
                topology: str = "hydra_full") -> StageCosts:
    """Run ``warm_s`` of the robot (force sines from the demo PC), then time each stage
    alone over ``ticks`` ticks from that state (best of three)."""
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc

    topo = load_topology(topology)
    pc = demo_pc()
    with BusSystem(topo, cfg, "inproc", model="robot") as bs:
        eng = bs.chain.engine
        eng.workers = 1
        bs.run(int(round(warm_s * 1000)), pc, keep=0)
        eng.wait()
        snap = _snapshot(eng.arrays)
        n = eng.n
        rows = []
        for which, name in enumerate(STAGES[:5]):
            _stage(which, 1, 0, *_snapshot(eng.arrays))  # compile outside the timing
            best = np.inf
            for _ in range(3):
                arrays = [a.copy() for a in snap]
                c0 = time.thread_time()
                _stage(which, ticks, eng.tick, *arrays)
                best = min(best, time.thread_time() - c0)
            rows.append((name, best * 1e9 / (n * ticks)))
        # The MCU law, one actuator at a time and in lanes, from copies of the records, as
        # the kernels call it (an engine cycle's MCU periods per claim).
        eng._make_blocks()
        per_cycle = eng.cycle_ticks // eng.period
        lane_buf = eng.law.lane_buffer()
        sizes_b = np.array([eng.law.state_size, eng.inp.itemsize, eng.out.itemsize])
        for stage, in_lanes in ((5, False), (11, True)):
            best = np.inf
            for k in range(4):  # (the first compiles)
                states, inp, out = eng.states.copy(), eng.inp.copy(), eng.out.copy()
                bases = np.array([states.ctypes.data, inp.ctypes.data, out.ctypes.data])
                c0 = time.thread_time()
                _mcu_law(in_lanes, max(1, ticks // eng.cycle_ticks) if k else 1, per_cycle,
                         eng.tick, eng.period, eng._blocks, eng._sizes, bases, sizes_b,
                         inp.view(np.uint32).reshape(n, -1), lane_buf.ctypes.data)
                if k:
                    best = min(best, time.thread_time() - c0)
            rows.append((STAGES[stage], best * 1e9 / (n * ticks)))
        if eng.lanes:
            eng._make_blocks()
            buf = lanes.lane_buffer()
            n_sub = int(snap[1][:, L.P_N_SUB].max())
            _rk4_in_lanes(1, snap[0].copy(), snap[1], snap[2], eng._blocks, eng._sizes, n_sub,
                          buf)
            best = np.inf
            for _ in range(3):
                x = snap[0].copy()
                c0 = time.thread_time()
                _rk4_in_lanes(ticks, x, snap[1], snap[2], eng._blocks, eng._sizes, n_sub, buf)
                best = min(best, time.thread_time() - c0)
            rows.append((STAGES[6], best * 1e9 / (n * ticks)))
            lb, sb = link_lanes.link_lane_buffer(), sensor_lanes.sensor_lane_buffer()
            fb = fpl.board_buffer()
            for which in (0, 1):
                def run(n_ticks, arrays, which=which):
                    (_, _, _, y, rng, _, k, raw, c, st, down, up, mdown, mup, lk) = arrays
                    if which == 0:
                        _sensors_in_lanes(n_ticks, eng.tick, eng._blocks, eng._sizes, y, rng,
                                          k, raw, c, st, down, sb, buf, fb)
                    else:
                        _link_in_lanes(n_ticks, eng._blocks, eng._sizes, raw, c, st, down,
                                       up, mdown, mup, lk, lb, fb)

                run(1, [a.copy() for a in snap])  # compile outside the timing
                best = np.inf
                for _ in range(3):
                    arrays = [a.copy() for a in snap]
                    c0 = time.thread_time()
                    run(ticks, arrays)
                    best = min(best, time.thread_time() - c0)
                rows.append((STAGES[7 + which], best * 1e9 / (n * ticks)))
            x, p, u, y, rng = (a.copy() for a in snap[:5])
            _outputs_in_lanes(1, x, p, u, y, rng, eng._blocks, eng._sizes, buf)
            best = np.inf
            for _ in range(3):
                c0 = time.thread_time()
                _outputs_in_lanes(ticks, x, p, u, y, rng, eng._blocks, eng._sizes, buf)
                best = min(best, time.thread_time() - c0)
            rows.append((STAGES[9], best * 1e9 / (n * ticks)))
            board = (snap[8], snap[9].copy(), snap[10].copy(), snap[11].copy(), snap[7].copy())
            _board_in_lanes(1, *board, eng._blocks, eng._sizes, fb, buf)
            best = np.inf
            for _ in range(3):
                board = (snap[8], snap[9].copy(), snap[10].copy(), snap[11].copy(),
                         snap[7].copy())
                c0 = time.thread_time()
                _board_in_lanes(ticks, *board, eng._blocks, eng._sizes, fb, buf)
                best = min(best, time.thread_time() - c0)
            rows.append((STAGES[10], best * 1e9 / (n * ticks)))
        # The engine's compiled call as a whole (every stage, 1 thread), same ticks, with
        # the plants one actuator at a time and (where the recipe allows) in lanes.
        cycles = max(1, ticks // eng.cycle_ticks)
        eng.overlap = False
        for use_lanes in (False, True) if eng.lanes else (False,):
            eng.lanes = use_lanes
            eng._counter[0] = 0
            eng._compute(eng.cycle_ticks)  # compile outside the timing
            c0 = time.thread_time()
            for _ in range(cycles):
                eng._counter[0] = 0
                eng._compute(eng.cycle_ticks)
            rows.append((f"total: the engine's compiled call, "
                         f"{'plants in lanes' if use_lanes else 'one actuator at a time'}",
                         (time.thread_time() - c0) * 1e9 / (n * cycles * eng.cycle_ticks)))
        rows.append(("outside the compiled call: master, PC loop, chain frames, hand-offs",
                     python_per_cycle(bs, pc, 2 * cycles) * 1e9 / (n * eng.cycle_ticks)))
    return StageCosts(n, ticks, rows)


__all__ = ["STAGES", "StageCosts", "stage_costs"]
