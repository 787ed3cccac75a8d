"""The robot engine (hil.sim.robot) against the per-actuator boxes it replaces: the same bytes on
the fieldbus, the same MCU output words and plant outputs, whatever the number of workers,
with faults on the fieldbus, the LVDS links and the sensors."""

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu.c_abi import IN_COMMAND, IN_ENABLE, INPUT, OUTPUT, config_record
from firmware_model.mcu.mcu import Mcu
from hil.fieldbus.faults import CYCLE_S
from hil.fieldbus.system import BusSystem
from hil.fieldbus.topology import load_topology
from hil.sim.pc import demo_pc
from plant.config import load_config
from plant.layout import Y_TAU_Q

# Every kind of fault the robot engine meets, each window as long as a fault plan's, the
# windows overlapping (two on the same fieldbus direction at once, LVDS and sensor faults on
# different boxes at once) rather than one after the other: the per-actuator reference the
# engine is compared with costs ~9 ms of CPU a cycle, and the comparison needs each fault's
# start, its effect and its end, not a run as long as the windows laid end to end.
FAULTS = [
    {"link": "fieldbus.down", "kind": "drop", "rate": 0.05, "start_s": 0.3, "end_s": 0.5,
     "frame": 1},
    {"link": "fieldbus.down", "kind": "duplicate", "rate": 0.2, "start_s": 0.1, "end_s": 0.8},
    {"link": "fieldbus.down", "kind": "delay", "delay_cycles": 2, "rate": 0.05,
     "start_s": 0.5, "end_s": 0.8},
    {"link": "fieldbus.up", "kind": "drop", "rate": 0.05, "start_s": 0.1, "end_s": 0.4},
    {"link": "lvds.down", "kind": "bitflip", "rate": 0.01, "box": 1, "slot": 0,
     "start_s": 0.3, "end_s": 0.8},
    {"link": "lvds.up", "kind": "dead", "box": 2, "slot": 1, "start_s": 0.6, "end_s": 0.7},
    {"link": "sensor", "kind": "noisy", "box": 3, "slot": 0, "signal": "p_cyl_a",
     "sigma": 2e5, "start_s": 0.2, "end_s": 0.6},
    {"link": "sensor", "kind": "dead", "box": 4, "slot": 0, "signal": "theta_m",
     "start_s": 0.55, "end_s": 0.75},
]


def _stacks(bs):
    return [s for b in bs.chain.boxes for s in getattr(b, "stacks", [])]


def _run(topo, cfg, model, cycles, faults=None, workers=1, overlap=True, sample=False,
         lanes=None, tap=None):
    """(fieldbus input images, per-cycle MCU downstream words and plant outputs or None).
    ``lanes``: the engine's plants in lanes or not (None: its default); ``tap``: a list
    that receives the engine's tap (plant outputs of every tick) of every cycle."""
    numba.set_num_threads(workers)
    with BusSystem(topo, cfg, "inproc", model=model, faults=faults) as bs:
        e = bs.chain.engine
        if e is not None:
            e.overlap = overlap
            e.workers = workers
            if lanes is not None:
                e.lanes = lanes
            if tap is not None:
                e.tap(plant=True, trace=True)
                e.on_cycle = lambda t: tap.append((e.tap_y.copy(), e.tap_trace.copy(),
                                                   e.arrays.plant.y.copy()))
        stacks = _stacks(bs)
        words, plant = [], []
        pc = demo_pc(400.0, 3.0)

        def sampling_pc(cycle, m):
            # Called between cycles: with overlap off nothing is being computed now.
            words.append(np.array([s.mcu_link.down for s in stacks]))
            plant.append(np.array([s.plant.y for s in stacks]))
            pc(cycle, m)

        rec = bs.run(cycles, sampling_pc if sample else pc)
        if bs.chain.engine is not None:
            bs.chain.engine.wait()
    return rec, (np.array(words), np.array(plant)) if sample else None


@pytest.mark.slow
def test_robot_engine_is_the_per_actuator_path_bit_for_bit_with_faults():
    topo, cfg = load_topology("hydra_full"), load_config("hydra_default")
    # Every fault's window, then 200 cycles after the last one ends (recovery): the
    # per-actuator reference costs ~9 ms of CPU a cycle, most of this test's time.
    cycles = round(max(f["end_s"] for f in FAULTS) / CYCLE_S) + 200
    ref, (ref_words, ref_plant) = _run(topo, cfg, "stack", cycles, FAULTS, sample=True)
    one, (words, plant) = _run(topo, cfg, "robot", cycles, FAULTS, 1, overlap=False,
                               sample=True)
    two, _ = _run(topo, cfg, "robot", cycles, FAULTS, 2, overlap=True)
    # The faults did happen: frames lost and stale, link words discarded, status bits set.
    assert ref.master["lost_frames"] > 0 and ref.chain["stale_frames"] > 0
    assert ref_words.shape == words.shape and ref_words.shape[1] == topo.n_actuators
    np.testing.assert_array_equal(words, ref_words)        # MCU outputs
    np.testing.assert_array_equal(plant, ref_plant)        # plant records
    for rec in (one, two):
        assert rec.inputs.tobytes() == ref.inputs.tobytes()  # fieldbus records
        assert rec.master == ref.master and rec.chain == ref.chain


def test_workers_and_overlap_do_not_change_results():
    topo, cfg = load_topology("hydra_full"), load_config("hydra_default")
    ref, _ = _run(topo, cfg, "stack", 40)
    assert np.unique(ref.inputs[20:], axis=0).shape[0] == 20  # the actuators move
    for workers, overlap, lanes in ((1, False, True), (1, True, True), (2, False, True),
                                    (2, True, True), (1, False, False), (2, True, False)):
        rec, _ = _run(topo, cfg, "robot", 40, workers=workers, overlap=overlap, lanes=lanes)
        assert rec.inputs.tobytes() == ref.inputs.tobytes(), (workers, overlap, lanes)


def test_the_helper_threads_live_from_the_first_cycle_to_the_bus_systems_end():
    """One worker: no helper thread at all; two: one helper (hil.sim.compute_threads),
    made at the first cycle, kept from cycle to cycle, ended when the bus system closes."""
    topo, cfg = load_topology("bench_one_box"), load_config("hydra_default")
    with BusSystem(topo, cfg, "inproc", model="robot") as bs:
        e = bs.chain.engine
        e.workers = 1
        bs.run(3, demo_pc())
        assert e._threads is None
        e.workers = 2
        bs.run(3, demo_pc())
        threads = list(e._threads.threads)
        assert len(threads) == 1 and threads[0].is_alive()
        bs.run(3, demo_pc())
        assert list(e._threads.threads) == threads
    assert not threads[0].is_alive()


def test_the_tap_gives_every_tick_and_changes_nothing():
    """The engine's tap (plant outputs and board trace of every tick of a cycle): a run
    with it gives the same bytes as one without; each cycle's last row is the plant's
    state after the cycle; the rows move from tick to tick; the trace's PWM columns are
    the board's compare counts, the duties the plant was driven with."""
    from hil.sim.actuator import TRACE_DUTY, TRACE_ON

    topo, cfg = load_topology("hydra_full"), load_config("hydra_default")
    plain, _ = _run(topo, cfg, "robot", 30, lanes=True)
    taps = []
    tapped, _ = _run(topo, cfg, "robot", 30, lanes=True, tap=taps)
    assert tapped.inputs.tobytes() == plain.inputs.tobytes()
    assert len(taps) >= 29
    for ys, _, y_after in taps:
        np.testing.assert_array_equal(ys[:, -1], y_after)
    ys, trace, _ = taps[-1]
    assert ys.shape == (topo.n_actuators, 20, y_after.shape[1])
    moving = np.all(np.diff(ys[:, :, Y_TAU_Q], axis=1) != 0, axis=1)
    assert moving.sum() > topo.n_actuators // 2
    on = trace[:, :, TRACE_ON] != 0
    assert on.any() and np.all(trace[:, :, TRACE_DUTY][on] > 0)


def test_bus_records_keep_the_last_cycles_in_order():
    topo, cfg = load_topology("hydra_full"), load_config("hydra_default")
    runs = {}
    for keep in (None, 7, 0):
        with BusSystem(topo, cfg, "inproc", model="echo") as bs:
            runs[keep] = bs.run(30, demo_pc(), keep=keep)
    assert np.unique(runs[None].inputs, axis=0).shape[0] == 30
    assert runs[7].first_cycle == 23
    np.testing.assert_array_equal(runs[7].inputs, runs[None].inputs[23:])
    assert runs[0].inputs.shape == (0, runs[None].inputs.shape[1])


_WORD = st.integers(0, 0xFFFF)


@settings(max_examples=40, deadline=None)
@given(ups=st.lists(st.lists(_WORD, min_size=B.UP_WORDS, max_size=B.UP_WORDS),
                    min_size=3, max_size=3),
       forces=st.lists(st.floats(-5e3, 5e3, allow_nan=False), min_size=3, max_size=3),
       steps=st.integers(1, 6))
def test_the_batched_mcu_law_steps_as_the_python_model(ups, forces, steps):
    """``mcu_law_step_many`` (what the engine calls, one program per actuator) against the
    Python MCU over random upstream memories and force commands."""
    from hil.sim.mcu_builds import HostLaw, build_host

    cfg = load_config("hydra_default")
    law = HostLaw(build_host())
    n = len(ups)
    states = np.zeros(n * law.state_size, dtype=np.uint8)
    for j in range(n):
        law.init_at(states.ctypes.data + j * law.state_size, config_record(cfg))
    inp, out = np.zeros(n, dtype=INPUT), np.zeros(n, dtype=OUTPUT)
    links = [LinkMemory(cfg) for _ in range(n)]
    mcu = Mcu(cfg, links)
    for j in range(n):
        mcu.command(j, "force", forces[j], 0)
        mcu.enable(j, 123)
        inp[j]["flags"], inp[j]["mode"], inp[j]["value"] = IN_COMMAND | IN_ENABLE, 1, forces[j]
        inp[j]["angle_offset"] = 123
    for k in range(steps):
        tick = 4 * k
        for j in range(n):
            links[j].up[:] = np.roll(ups[j], k)
            inp[j]["up"] = links[j].up
        inp["tick"] = tick
        mcu.step(tick)
        law.step_many(states, inp, out)
        inp["flags"] = 0
        for j in range(n):
            np.testing.assert_array_equal(out[j]["down"], links[j].down)
            assert int(out[j]["status"]) == mcu.status[j]
            assert out[j]["i_ref"].tobytes() == np.float32(mcu.iq_ref[j]).tobytes()


@pytest.mark.slow
def test_a_capture_of_a_robot_run_replays_bit_for_bit_on_both_paths(tmp_path, capsys):
    from hil.cli import main

    cap = tmp_path / "robot.pcapng"
    assert main(["bus", "run", "--topology", "hydra_full", "--model", "robot", "--seconds",
                 "0.1", "--capture", str(cap)]) == 0
    for model in ("robot", "stack"):
        assert main(["replay", str(cap), "--model", model, "--json"]) == 0
        assert '"ok": true' in capsys.readouterr().out


def test_the_law_the_engine_links_has_no_fused_multiply_add():
    """The engine calls the host build by name: its machine code must round every product
    on its own, as the Python model does (no vfmadd/vfmsub of any width)."""
    import shutil
    import subprocess

    from hil.sim.mcu_builds import build_host

    if shutil.which("objdump") is None:
        pytest.skip("objdump not installed")
    asm = subprocess.run(["objdump", "-d", str(build_host())], capture_output=True, text=True,
                         check=True).stdout
    assert "mcu_law_step_many" in asm and "mulss" in asm
    assert not [line for line in asm.splitlines() if "vfm" in line or "vfnm" in line]


def _increfs(with_runtime: bool) -> int:
    """The reference counts in the body of the engine's kernel compiled afresh (~3 s of
    CPU) for the engine's bundles, with its own options or with numba's runtime on."""
    from hil.sim import robot

    cfg = load_config()
    with BusSystem(load_topology("bench_one_box"), cfg, "inproc", model="robot") as bs:
        e = bs.chain.engine
        args = (e._counter, 1, e.period, e.tick, e._batched, e.arrays, e.mcu, e._no_rec,
                e.log_rows)
    opts = {k: v for k, v in robot.advance_robot.targetoptions.items()
            if k not in ("cache", "nopython")}
    if with_runtime:
        opts = {k: v for k, v in opts.items() if k != "_nrt"}
    kernel = numba.njit(**opts)(robot.advance_robot.py_func)
    kernel.compile(tuple(numba.typeof(a) for a in args))
    return _body(next(iter(kernel.inspect_llvm().values())), "advance_robot").count(
        "NRT_incref")


def test_the_kernel_counts_no_references_through_its_bundles():
    """Each row view of a bundle's array would bump the parent's reference count (an atomic
    on a line the compute threads share): the kernel, compiled with its own options for
    the engine's bundles, has no count in its body."""
    assert _increfs(with_runtime=False) == 0


@pytest.mark.slow
def test_the_reference_count_check_sees_counts_where_there_are_some():
    """With numba's runtime the same kernel's body has counts: the check above can fail
    (a second compile of the kernel, so only in the whole suite)."""
    assert _increfs(with_runtime=True) > 0


def _body(ir, name):
    """The LLVM IR of the compiled function ``name`` itself (not the functions it calls,
    which the module holds when they were compiled in this process, nor its wrappers)."""
    lines = ir.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("define")
                 and name in line and "cpython" not in line and "cfunc" not in line)
    end = next(i for i in range(start, len(lines)) if lines[i] == "}")
    return "\n".join(lines[start:end])
