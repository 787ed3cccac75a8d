"""``python -m hil.sim.warmup``: compile the numba kernels once, right after installing.

numba compiles a ``cache=True`` function on its first call and keeps the machine code in
the cache folder of this version of the kernels' sources (:mod:`firmware_model.jit_cache`).
Without this step the compiling happens in the user's first ``eha-hil main`` /
``eha-hil run thesis`` (tens of seconds on the project's 2-core machine), which then looks
hung; ``make`` runs this module right after each install instead.

Each step is the smallest call that reaches a group of kernels with the argument types the
commands and the tests use (numba keys its cache on the types, not the values). A failing
step is reported and skipped: warming is a convenience, the commands compile whatever is
missing on their first call anyway.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import numpy as np


def _plant(cfg) -> None:
    from plant.model import Plant, stiffness_range

    stiffness_range(cfg)  # k_s(x) called from Python (eha-hil main prints its range)
    plant = Plant(cfg)
    plant.set_current(1.0)
    plant.advance(2)
    plant.advance(2, np.zeros((2, plant.y.size)), 0, 1)


def _plant_blocks(cfg) -> None:
    """The plant's blocks that the kernels inline, called one at a time from Python by
    their tests (tests/plant/test_entrained_air.py, test_numerics.py): the stiffness with
    entrained air and the motor's phase angles."""
    from plant.blocks.hydraulics import aerated_stiffness, line_stiffness
    from plant.blocks.motor_dq import phase_angles
    from plant.model import build_params

    p = build_params(cfg, substeps=1)
    aerated_stiffness(p, 0.0, 0.0)
    line_stiffness(p, 0.0, 0.0)
    phase_angles(0.0, 2.0)


def _fpga_value_level(cfg) -> None:
    """Plant + sensor chips + driver board + LVDS link in one compiled call, with and
    without the board trace (the replay logs)."""
    from hil.sim.actuator import TRACE_WIDTH, FpgaStack

    stack = FpgaStack(cfg)
    stack.boot()
    stack.advance(2, np.zeros((2, stack.y.size)), 0, 1,
                  trace=np.zeros((2, TRACE_WIDTH), dtype=np.int64))


def _fpga_bit_level(cfg) -> None:
    """The bit-level path calls the board's tick and the sensor kernels from Python."""
    from hil.sim.actuator import FpgaStack

    FpgaStack(cfg, bit_level=True).advance(2)


def _replay(cfg) -> None:
    from hil.replay.fpga_replay import warm_up

    warm_up(cfg)


def _fixed_point(cfg) -> None:
    """The FOC blocks and the integer helpers on their own: compiled into the board's tick,
    but also called one by one (``fpga golden``, the reference tests), and the blocks' pure
    Python versions call the helpers as compiled functions."""
    from firmware_model.fpga import fixed, foc

    for f, args in ((foc.sin_cos, (0,)), (foc.clarke, (0, 0)), (foc.park, (0, 0, 0, 0)),
                    (foc.inv_park, (0, 0, 0, 0)), (foc.svpwm, (0, 0, 1)),
                    (foc.pi_step, (0, 0, 1, 0, 1, 0, 0, 1)), (foc.q_limit, (0, 1))):
        f(*args)
        f.py_func(*args)
    for f in (fixed.wrap_s, fixed.wrap_u, fixed.sat_s, fixed.sat_u, fixed.shr_floor,
              fixed.shr_round):
        f(0, 16)
    fixed.mul_shift(0, 1, 1)
    fixed.clamp(0, -1, 1)
    fixed.isqrt(0)


def _rtl(cfg) -> None:
    """The current loop's RTL built with Verilator into its cache (where Verilator is
    installed; ~25 s the first time) and one stack tick on it, and the loop model the
    verification compares it with."""
    from firmware_model.fpga.current_loop import LOOP_INPUT, run_model
    from hil.sim import verilator as rtl_verilator

    run_model(cfg, np.zeros(1, dtype=LOOP_INPUT))
    if rtl_verilator.missing_tools():
        return
    from hil.sim.actuator import FpgaStack

    FpgaStack(cfg.with_overrides({"fpga.impl": "rtl"}, "warmup")).advance(2)


def _loop_timing(cfg) -> None:
    """``bench fpga --set fpga.impl=rtl``'s loops of timed ticks (the RTL's and the board
    model's: the loop model and its PI steps on the timing's constant words). No tick is
    run (0 ticks): the RTL's address is only known once Verilator has built it."""
    from firmware_model.fpga.params import board_params
    from firmware_model.fpga.rtl_abi import timing_ticks_model, timing_ticks_rtl

    c = board_params(cfg)
    timing_ticks_rtl(c, 0)
    timing_ticks_model(c, 0)


def _identify_model(cfg) -> None:
    """The identification model's simulation (``eha-hil identify``), on a short synthetic
    record."""
    from hil.identify.experiment import prepare
    from hil.identify.model import FastModel
    from hil.identify.synth import generate

    model = FastModel(prepare(generate(seconds=0.2, noise=False).data, cfg))
    theta = model.start_vector()
    model.outputs(theta)
    # and the fits' tangent-linear simulation (hil.identify.tangent): two columns, the
    # applied force's and the linear part's
    from hil.identify.model import IDX
    from hil.identify.tangent import state_sensitivities

    plus, minus = [], []
    for name in ("gain_n_per_a", "ks"):
        step = 1e-6 * theta[IDX[name]]
        plus.append(theta.copy())
        plus[-1][IDX[name]] += step
        minus.append(theta.copy())
        minus[-1][IDX[name]] -= step
    steps = np.array([1e-6 * theta[IDX[n]] for n in ("gain_n_per_a", "ks")])
    state_sensitivities(model, theta, plus, minus, steps, None)
    # and a linear model's difference-recursion columns (hil.identify.linear_columns, off
    # in the fits by default; its tests call it)
    from hil.identify.linear_columns import state_differences

    state_differences(model, theta, model.states(theta), plus, steps, None)


def _identify_rig(cfg) -> None:  # noqa: ARG001 - the rig draws from its own preset
    """The identification's independent rig (``eha-hil identify-check``, the
    identification's tests), on a short record."""
    from hil.identify.rig import generate_rig

    generate_rig("free_piston", seconds=0.05, seed=1)


def _joint_kinematics(cfg) -> None:  # noqa: ARG001 - the geometry is the hip's own
    """The universal joint's conversions and the rod's strain force, called from Python by
    the PC's joint loop (the hip scenarios) and their tests: a pose, the pistons back to
    the pose, torques and forces there."""
    from firmware_model.pc.geometry import hip_geometry
    from firmware_model.pc.kinematics import UJointKinematics
    from firmware_model.pc.strain import piston_force, rod_force

    geom = hip_geometry()
    kin = UJointKinematics(geom)
    z = kin.inverse(0.5 * sum(geom.pitch_range_rad), 0.0)
    kin.forward(z[0], z[1])
    kin.torque(1.0, 1.0)
    kin.forces(1.0, 1.0)
    piston_force(kin.cos_alpha[0], 1.0)
    rod_force(kin.cos_alpha[0], 1.0)


def _robot(cfg) -> None:
    # The robot engine's kernels on one box (needs the MCU law's C build: a C compiler).
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc

    with BusSystem(load_topology("bench_one_box"), cfg, "inproc", model="robot") as bs:
        bs.run(2, demo_pc())
        bs.chain.engine.wait()


def _robot_per_actuator(cfg) -> None:
    """The robot engine with one actuator at a time instead of lanes (a plant recipe
    below 3, ``bench robot --engine``, the engine's tests with ``lanes`` off): its own
    kernel, which calls the whole stack's tick (``advance_stack``) with other types."""
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc

    with BusSystem(load_topology("bench_one_box"), cfg, "inproc", model="robot") as bs:
        bs.chain.engine.lanes = False
        bs.run(2, demo_pc())
        bs.chain.engine.wait()


def _hip_box(cfg) -> None:
    """The hip box's loop: two stacks and the thigh coupled tick by tick (``bus run`` on the
    hip topology), with the joint's pose and anchors placed from Python."""
    from hil.fieldbus.hip_box import HipBox
    from hil.fieldbus.topology import load_topology
    from hil.sim.hip_stack import hip_config

    HipBox(load_topology("hip_one_box").boxes[0], hip_config(cfg, reinforced=True)).advance(2)


def _log_signals(cfg) -> None:
    """The decoded actuator signals of a frame log (``bus run --model robot --log``)."""
    from firmware_model.calibration import calibration
    from hil.replay import robot_record
    from hil.replay.signal_kernel import warm_up

    cal = calibration(cfg)
    warm_up(cal)
    robot_record.warm_up(cfg)  # the array layouts a logged run passes
    # and steps that are a view of a longer block with the messages into an array of their
    # own (the encoder's tests; an actuator-major block of several actuators)
    from firmware_model.fpga import layout as B
    from hil.fieldbus.pdo import ACTUATOR_OUT_DTYPE
    from hil.replay import signals as SG
    from hil.replay.signal_kernel import ActuatorEncoder

    size = ACTUATOR_OUT_DTYPE.itemsize
    enc = ActuatorEncoder(cal, SG.ACTUATOR, 200e-6, 1, [0, 0], [0, 0], [(0, size)], size)
    up = np.zeros((2, 3, B.UP_WORDS + 2), np.uint16)[:, :2]
    down = np.zeros((2, 3, B.DOWN_WORDS), np.uint16)[:, :2]
    enc.encode(up, down, SG.PistonCarry.start(2), np.arange(2, dtype=np.int64),
               np.zeros(1, np.int64), np.zeros((1, size), np.uint8), np.ones((1, 1), bool))


def _log_planes(cfg) -> None:
    """The byte planes of a frame log's raw blocks and its batches' record heads (every
    ``--log``)."""
    from hil.framelog import heads
    from hil.framelog.rawpb import warm_up

    warm_up()
    heads.warm_up()
    _log_one_channel()


def _log_one_channel() -> None:
    """A block of one channel (``rawpb.pack_block``: the writer's channels written one by
    one; the log tests), whose arrays are C-contiguous where a batch's are strided: the
    noisy low bits' split for the elements of 2, 4 and 8 bytes, the byte planes of frames
    of one byte read from a buffer (read-only)."""
    from hil.framelog import rawpb

    t = np.arange(512, dtype=np.int64) * 200_000
    for size in (1, 2, 4, 8):
        frames = np.zeros((512, 8), f"<i{size}")
        frames[:, 0] = np.arange(512) % 3  # some noise: low bits to split off
        if size == 1:
            frames = np.frombuffer(frames.tobytes(), np.int8).reshape(512, 8)  # read-only
        rawpb.pack_block(t, frames, frames.dtype)


def _esc_frames(cfg) -> None:
    """The EtherCAT frame path of ``serve --transport ethercat`` (every slave's datagram
    processing, the 3-buffers, the frame loop)."""
    from hil.fieldbus.esc.frames import warm_up

    warm_up()
    _esc_from_python()


def _esc_from_python() -> None:
    """What Python calls of the compiled slaves: a box publishing its input record (bytes:
    a read-only array; the 3-buffer's tests a writable one) and the run's report of each
    slave's clock."""
    from firmware_model.esc import compiled as cc
    from firmware_model.esc import dc_compiled as dcc
    from firmware_model.esc.sii import SlaveDescription, SyncManager, build_image

    d = SlaveDescription(0, 0, 0, 0, "warm-up", "warm-up", (), (),
                         (SyncManager(0x1000, 0, 0x64, False),
                          SyncManager(0x1100, 0, 0x20, False)))
    arrays = cc.EscArrays([(d, build_image(d))])
    arrays.set_inputs(0, bytes(4))
    cc.publish(arrays.ibuf[0], arrays.ilen[0], arrays.iidx[0], np.zeros(4, np.uint8), 4)
    dcc.slave_report(arrays.mem[0], arrays.st[0])


def _lanes_one_by_one(cfg) -> None:
    """The lanes' stages called one at a time from Python (``bench robot --stages`` and the
    lanes' tests), where the robot engine calls them inside its own kernel: the sensor
    chips, the plant's outputs and the board's buffers loaded and stored, one tick."""
    from firmware_model.fpga import lanes as fpl
    from firmware_model.fpga import layout as B
    from firmware_model.lvds import lanes as LL
    from firmware_model.lvds import link as LK
    from plant import lanes
    from plant import layout as L
    from plant.lane_outputs import load_outputs, outputs_lanes
    from plant.model import build_params
    from plant.sensors import chips as K
    from plant.sensors import lanes as SL
    from plant.sensors.harness import digitise

    n, m = 2, 1
    k = np.tile(K.chip_params(cfg), (n, 1))
    raw = np.zeros((n, B.N_RAW), np.int64)
    block = np.zeros(lanes.LW, dtype=np.int64)
    sb, pb, fb = SL.sensor_lane_buffer(), lanes.lane_buffer(), fpl.board_buffer()
    SL.load_chips(sb, k, block, m)
    params, state = np.zeros((n, B.N_PARAMS), np.int64), np.zeros((n, B.N_STATE), np.int64)
    down = np.zeros((n, B.DOWN_WORDS), np.int64)
    fpl.load_board(fb, params, state, raw, down, block, m)
    y = np.zeros((n, L.N_OUTPUTS))
    load_outputs(pb, y, np.zeros((n, 1), np.uint64), block, m)
    SL.digitise_lanes(sb, pb, fb, k, block, m, 0, y, raw)
    fpl.store_board(fb, state, raw, down, block, m)
    digitise(y[0], k[0], 0, raw[0].copy())
    # the lanes' tests call the rest of the engine's stages one by one too: the boards' tick
    # and a lane's field, the plant's outputs, the link's sweeps and its word log
    rows = np.arange(n)
    up = np.zeros((n, B.UP_WORDS), np.int64)
    fpl.board_tick(fb, rows, n, raw, down, state, up, params)
    fpl.lane(fb, fpl.SO, B.F_PWM_ON, 0)
    lanes.load_params(pb, np.tile(build_params(cfg, substeps=1), (n, 1)), rows, n)
    outputs_lanes(pb, y, np.zeros((n, 1), np.uint64), rows, n)
    lb, lk = LL.link_lane_buffer(), np.zeros((n, LK.N_LINK_STATE), np.int64)
    mdown, mup = np.zeros((n, B.DOWN_WORDS), np.int64), np.zeros((n, B.UP_WORDS), np.int64)
    LL.load_link(lb, lk, block, m)
    LL.sweep_down_lanes(lb, lk, mdown, fb, state, down, block, m)
    LL.sweep_up_lanes(lb, lk, up, mup, block, m)
    LL.word_log(np.zeros((1, 2 * LK.WORDS_W), np.int64), 0, 0, lb, 0)


STEPS: list[tuple[str, Callable]] = [
    ("plant", _plant),
    ("plant blocks one by one", _plant_blocks),
    ("driver board + link", _fpga_value_level),
    ("bit-level sensors and link", _fpga_bit_level),
    ("board replay", _replay),
    ("fixed-point blocks", _fixed_point),
    ("current loop RTL (Verilator)", _rtl),
    ("current loop timing", _loop_timing),
    ("identification model", _identify_model),
    ("identification rig", _identify_rig),
    ("joint kinematics", _joint_kinematics),
    ("robot engine", _robot),
    ("robot engine, one actuator at a time", _robot_per_actuator),
    ("hip box", _hip_box),
    ("frame log signals", _log_signals),
    ("frame log byte planes", _log_planes),
    ("EtherCAT frame path", _esc_frames),
    ("lanes' stages one by one", _lanes_one_by_one),
]


def warm(out=sys.stderr) -> int:
    """Run every step; the number that failed (each is reported on one line)."""
    t_all = time.perf_counter()
    failed = 0
    try:
        from plant.config import load_config

        cfg = load_config(None)
    except Exception as exc:  # nothing to warm without a configuration
        print(f"eha-hil warmup: skipped ({type(exc).__name__}: {exc})", file=out)
        return len(STEPS)
    print("eha-hil warmup: compiling the numba kernels once (about 3 min on a fresh "
          "install of an idle 2-core machine, a second when they are cached) ...",
          file=out, flush=True)
    for name, step in STEPS:
        try:
            step(cfg)
        except Exception as exc:  # a convenience step: report it, go on
            failed += 1
            print(f"eha-hil warmup: {name}: skipped ({type(exc).__name__}: {exc})", file=out)
    print(f"eha-hil warmup: done in {time.perf_counter() - t_all:.1f} s", file=out)
    return failed


if __name__ == "__main__":
    warm()  # exit 0 even if a step failed: an install must not fail on a convenience step
