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


def _robot(cfg) -> None:
    # The robot engine's kernels on one box (needs the MCU law's C build: a C compiler).
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc

    with BusSystem(load_topology("bench_one_box"), cfg, "inproc", model="robot") as bs:
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

    warm_up(calibration(cfg))
    robot_record.warm_up(cfg)  # the array layouts a logged run passes


def _log_planes(cfg) -> None:
    """The byte planes of a frame log's raw blocks and its batches' record heads (every
    ``--log``)."""
    from hil.framelog import heads
    from hil.framelog.rawpb import warm_up

    warm_up()
    heads.warm_up()


def _esc_frames(cfg) -> None:
    """The EtherCAT frame path of ``serve --transport ethercat`` (every slave's datagram
    processing, the 3-buffers, the frame loop)."""
    from hil.fieldbus.esc.frames import warm_up

    warm_up()


def _lanes_one_by_one(cfg) -> None:
    """The lanes' stages called one at a time from Python (``bench robot --stages`` and the
    lanes' tests), where the robot engine calls them inside its own kernel: the sensor
    chips, the plant's outputs and the board's buffers loaded and stored, one tick."""
    from firmware_model.fpga import lanes as fpl
    from firmware_model.fpga import layout as B
    from plant import lanes
    from plant import layout as L
    from plant.lane_outputs import load_outputs
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


STEPS: list[tuple[str, Callable]] = [
    ("plant", _plant),
    ("driver board + link", _fpga_value_level),
    ("bit-level sensors and link", _fpga_bit_level),
    ("board replay", _replay),
    ("fixed-point blocks", _fixed_point),
    ("current loop RTL (Verilator)", _rtl),
    ("identification model", _identify_model),
    ("robot engine", _robot),
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
