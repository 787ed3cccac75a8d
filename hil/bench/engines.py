"""Benchmarks: real-time factor of the plant, throughput of the codecs.

Figures are ratios (simulated seconds per wall second) or rates (frames per wall second),
measured with ``time.perf_counter`` over a run long enough to swamp the timer; the first,
compiling call is made before timing starts.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from firmware_model.fpga.params import board_params
from firmware_model.fpga.rtl_abi import timing_ticks_model, timing_ticks_rtl
from hil.bench.robot_cycle import CpuSplit, cpu_split
from hil.sim.scheduler import Scheduler
from plant.config import Config
from plant.model import Plant


class RealTimeFactors:
    """The real-time factors of a run with ``simulated_s``, ``wall_s`` and ``cpu_s``."""

    simulated_s: float
    wall_s: float
    cpu_s: float

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s

    @property
    def cpu_real_time_factor(self) -> float:
        return self.simulated_s / self.cpu_s


@dataclass
class PlantBench(RealTimeFactors):
    """Result of ``bench plant``."""

    simulated_s: float
    wall_s: float
    substeps: int
    mode: str
    tick_s: float
    cpu_s: float = math.nan  # CPU seconds of the process over the run, where measured
    loop: str = ""           # the board's current loop, where there is a choice

    @property
    def ticks_per_s(self) -> float:
        return self.simulated_s / self.tick_s / self.wall_s


def bench_plant(cfg: Config, seconds: float = 5.0, mode: str = "scheduled") -> PlantBench:
    """Time the plant alone with the configured effects at its 50 us tick.

    ``mode`` "scheduled": through the scheduler, with a 1 kHz task (the PC rate) that
    changes the current reference every millisecond and the plant outputs recorded every
    tick — what a plant-only study costs. "kernel": one compiled call for the whole run.
    """
    plant = Plant(cfg)
    plant.set_current(1.0)
    plant.advance(20)  # compile / warm up outside the timing
    if mode == "kernel":
        n = int(round(seconds / plant.tick_s))
        t0 = time.perf_counter()
        plant.advance(n)
        wall = time.perf_counter() - t0
        return PlantBench(n * plant.tick_s, wall, plant.substeps, mode, plant.tick_s)
    if mode != "scheduled":
        raise ValueError(f"unknown bench mode {mode!r}")
    sched = Scheduler(plant, record_every=1)
    tick_s = plant.tick_s

    def pc_task(tick: int) -> None:
        plant.set_current(10.0 * math.sin(2.0 * math.pi * 5.0 * tick * tick_s))

    sched.every(20, pc_task, "pc_current_reference")
    n = sched.ticks(seconds)
    t0 = time.perf_counter()
    sched.run(n)
    wall = time.perf_counter() - t0
    return PlantBench(n * tick_s, wall, plant.substeps, mode, tick_s)


def bench_fpga(cfg: Config, seconds: float = 2.0, bit_level: bool = False) -> PlantBench:
    """Time plant + driver board + LVDS link through the scheduler.

    A 5 kHz task (the MCU's rate) writes a sinusoidal iq reference into the MCU-side link
    memory; plant outputs are recorded every tick. ``bit_level`` runs the sensor links and
    LVDS words as real bits (Python per tick) instead of the compiled value-level path.
    The current loop is the board model's or, with ``fpga.impl = "rtl"``, its Verilated RTL.
    """
    from hil.sim.actuator import FpgaStack

    stack = FpgaStack(cfg, bit_level=bit_level)
    stack.boot()
    sched = Scheduler(stack, record_every=1)
    tick_s = stack.tick_s
    mem = stack.mcu_link

    def mcu_task(tick: int) -> None:
        mem.write("iq_ref", int(8000.0 * math.sin(2.0 * math.pi * 20.0 * tick * tick_s)))

    sched.every(4, mcu_task, "mcu_current_reference")
    n = sched.ticks(seconds)
    t0, c0 = time.perf_counter(), time.process_time()
    sched.run(n)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return PlantBench(n * tick_s, wall, stack.plant.substeps,
                      "bit-level" if bit_level else "value-level", tick_s, cpu,
                      "board model" if stack.rtl is None else "RTL (Verilator)")


def bench_stack(cfg: Config, seconds: float = 2.0) -> PlantBench:
    """Time the full single-actuator stack: plant + driver board + LVDS link (value level)
    + MCU at 5 kHz (float32) + a 1 kHz PC task sending a sinusoidal force command; plant
    outputs recorded every 4th tick and the MCU's signals probed at 5 kHz."""
    from hil.sim.actuator import ActuatorStack

    stack = ActuatorStack(
        cfg, lambda t: ("force", 300.0 * math.sin(2.0 * math.pi * 5.0 * t)), record_every=4)
    stack.run(0.01)  # compile / warm up outside the timing
    n = stack.sched.ticks(seconds)
    t0, c0 = time.perf_counter(), time.process_time()
    stack.sched.run(n)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return PlantBench(n * stack.tick_s, wall, stack.fpga.plant.substeps,
                      f"full stack, MCU {cfg.get('mcu.impl')}", stack.tick_s, cpu)


@dataclass
class TimedRun(RealTimeFactors):
    """Simulated, wall and CPU seconds of a benchmarked run, and its real-time factors."""

    simulated_s: float
    wall_s: float
    cpu_s: float


@dataclass
class RobotBench(TimedRun):
    """Result of ``bench robot`` for one number of workers."""

    workers: int = 1
    actuators: int = 0
    tick_s: float = 50e-6
    engine: str = "lanes"  #: "lanes" or "per-actuator" (hil.sim.robot)
    numerics: int = 3      #: the plant's arithmetic recipe it ran
    #: The run's CPU by thread (:mod:`hil.bench.robot_cycle`).
    split: CpuSplit = field(default_factory=CpuSplit)

    def per_actuator_tick(self, cpu_s: float) -> float:
        """``cpu_s`` over the run in ns per actuator per 50 us tick."""
        return 1e9 * cpu_s / (self.actuators * self.simulated_s / self.tick_s)

    @property
    def ns_per_actuator_tick(self) -> float:
        """CPU time (every thread) per actuator per 50 us tick, ns."""
        return self.per_actuator_tick(self.cpu_s)


def bench_robot(cfg: Config, seconds: float = 10.0, workers: int = 1,
                topology: str = "hydra_full", lanes: bool | None = None) -> RobotBench:
    """Time the whole robot over the fieldbus: every box's MCU board and its stacks
    (plant, sensor chips, driver board, LVDS link) in the robot engine (:mod:`hil.sim.robot`)
    with ``workers`` compute threads, the master and the PC loop (a force sine on every
    actuator) at 1 kHz in lockstep. CPU time is the process's, all threads. ``lanes``: the
    plants in vector lanes or one actuator at a time (None: the engine's default)."""
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import load_topology
    from hil.sim.pc import demo_pc

    topo = load_topology(topology)
    cycles = int(round(seconds * 1000))
    pc = demo_pc()
    with BusSystem(topo, cfg, "inproc", model="robot") as bs:
        eng = bs.chain.engine
        eng.workers = workers
        if lanes is not None:
            eng.lanes = lanes
        used = eng.lanes
        bs.run(20, pc)  # compile / warm up outside the timing
        with cpu_split(eng) as split:
            t0, c0 = time.perf_counter(), time.process_time()
            bs.run(cycles, pc, keep=0)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return RobotBench(cycles * 1e-3, wall, cpu, workers=workers, actuators=topo.n_actuators,
                      tick_s=cfg.get("sim.tick_ns") * 1e-9,
                      engine="lanes" if used else "per-actuator",
                      numerics=cfg.get("sim.plant_numerics"), split=split)


# --- one tick's call of the current loop: RTL under Verilator against the board model ------
@dataclass
class CallCost:
    """CPU and wall nanoseconds per tick of each way of running the loop."""

    ticks: int
    rows: list[tuple[str, float, float]]  # (way, wall ns, CPU ns)


def bench_loop_call(cfg: Config, ticks: int = 1_000_000) -> CallCost:
    from hil.sim.verilator import load

    c = board_params(cfg)
    loop = load(cfg.with_overrides({"fpga.impl": "rtl"}), c)
    timing_ticks_rtl(c, 10)  # compile outside the timing; leaves the inputs in the buffer
    timing_ticks_model(c, 10)
    rows = []
    for way, fn in (("RTL (Verilator), compiled call", timing_ticks_rtl),
                    ("board model's loop, compiled", timing_ticks_model)):
        t0, c0 = time.perf_counter(), time.process_time()
        fn(c, ticks)
        rows.append((way, (time.perf_counter() - t0) / ticks * 1e9,
                     (time.process_time() - c0) / ticks * 1e9))
    tick = loop.tick_function()
    n = max(ticks // 10, 1)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        tick(loop.handle)
    rows.append(("RTL (Verilator), ctypes call from Python", (time.perf_counter() - t0) / n * 1e9,
                 (time.process_time() - c0) / n * 1e9))
    return CallCost(ticks, rows)
