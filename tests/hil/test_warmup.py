"""``python -m hil.sim.warmup`` reaches the kernels that the commands and the tests call
from Python, with the argument types they pass (numba keys its cache on the types): a
kernel or a type it misses is compiled inside the first run, or inside the suite.

The warm-up runs in a child process, whose dispatchers then hold exactly what it asked
for (loaded from the cache, or compiled): the kernels below must be among them. The
kernels that only other kernels call are not listed (compiled with their caller). After
``make``'s warm-up this loads every kernel (a few seconds); with kernel sources changed
since, the child compiles them into the cache folder the rest of the suite then loads
from, hence ``slow`` (not in ``make test-fast``)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: (module, kernel): each called from Python by a command or a test (the warm-up's step
#: that reaches it says by which).
FROM_PYTHON = [
    ("plant.blocks.hydraulics", "aerated_stiffness"),
    ("plant.blocks.hydraulics", "line_stiffness"),
    ("plant.blocks.motor_dq", "phase_angles"),
    ("plant.lane_outputs", "outputs_lanes"),
    ("firmware_model.esc.compiled", "publish"),
    ("firmware_model.esc.dc_compiled", "_get32"),
    ("firmware_model.fpga.lanes", "board_tick"),
    ("firmware_model.fpga.lanes", "lane"),
    ("firmware_model.fpga.rtl_abi", "timing_ticks_model"),
    ("firmware_model.fpga.rtl_abi", "timing_ticks_rtl"),
    ("firmware_model.lvds.lanes", "sweep_down_lanes"),
    ("firmware_model.lvds.lanes", "sweep_up_lanes"),
    ("firmware_model.lvds.lanes", "word_log"),
    ("firmware_model.pc.kinematics", "cylinder_force"),
    ("firmware_model.pc.kinematics", "cylinder_to_joint"),
    ("firmware_model.pc.kinematics", "joint_torque"),
    ("firmware_model.pc.strain", "piston_force"),
    ("firmware_model.pc.strain", "rod_force"),
    ("hil.identify.rig", "_simulate"),
    ("hil.identify.rig", "_temperature"),
    ("hil.identify.rig", "_lines_on_grid"),
    ("hil.sim.robot", "advance_robot"),
    ("hil.sim.robot", "advance_robot_lanes"),
    ("hil.framelog.planes", "split"),
    ("hil.framelog.planes", "split_columns"),
    ("hil.replay.signal_kernel", "_encode"),
]

_CHILD = r"""
import importlib, io, json, sys
from hil.sim.warmup import warm

failed = warm(io.StringIO())
sigs = {}
for mod, name in json.loads(sys.argv[1]):
    kernel = getattr(importlib.import_module(mod), name)
    sigs[f"{mod}.{name}"] = [[str(t) for t in sig] for sig in kernel.overloads]
print(json.dumps({"failed": failed, "sigs": sigs}))
"""


@pytest.fixture(scope="module")
def warmed() -> dict:
    run = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(FROM_PYTHON)],
                         capture_output=True, text=True, timeout=1800, check=False)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_every_step_runs_and_reaches_the_kernels_called_from_python(warmed):
    assert warmed["failed"] == 0
    missed = [name for name, sigs in warmed["sigs"].items() if not sigs]
    assert not missed, f"not reached by the warm-up: {missed}"


@pytest.mark.slow
def test_the_warm_up_passes_the_types_the_callers_pass(warmed):
    """The specialisations that a first call would otherwise compile: a box's input
    record from bytes (read-only) and the 3-buffer's tests' writable one; one channel's
    log block (C-contiguous planes, a read-only byte trace); the encoder on views of a
    block writing into an array of its own."""
    sigs = warmed["sigs"]
    data = {sig[3] for sig in sigs["firmware_model.esc.compiled.publish"]}
    assert data >= {"readonly array(uint8, 1d, C)", "array(uint8, 1d, C)"}, data
    assert ["array(uint8, 2d, C)"] * 2 in [
        sig[6:8] for sig in sigs["hil.framelog.planes.split_columns"]]
    assert "readonly array(int8, 3d, C)" in {
        sig[0] for sig in sigs["hil.framelog.planes.split"]}
    assert ("array(uint16, 3d, A)", "array(uint8, 2d, C)") in {
        (sig[0], sig[3]) for sig in sigs["hil.replay.signal_kernel._encode"]}
