"""The MCU law in lanes (``firmware_model/mcu/c/mcu_law_lanes.c``, the robot engine's batches)
against the per-actuator C law (``mcu_law_step``, itself checked against the Python model in
test_mcu_builds.py): the same program states and output records, byte for byte, for
batches whose lanes differ in everything a lane can differ in."""

from __future__ import annotations

import functools
import shutil
import subprocess

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.mcu.c_abi import INPUT, OUTPUT, STATE_HEAD, config_record
from hil.sim import mcu_builds
from hil.verify.mcu.steps import VARIANTS, random_inputs
from plant.config import load_config

LW = 8  # MCU_LW in mcu_law_lanes.h: the engine's batch width
STEPS = 60


def _need_cc() -> None:
    missing = mcu_builds.missing_tools("host-c")
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (make system-deps)")


@functools.cache
def _law(contract: str = "off") -> mcu_builds.HostLaw:
    return mcu_builds.HostLaw(mcu_builds.build_host(contract))


@functools.cache
def _configs() -> tuple[np.ndarray, ...]:
    """The law's six variants (controller x feedback)."""
    return tuple(config_record(load_config(None, v)) for v in VARIANTS)


@functools.cache
def _inputs(seed: int) -> np.ndarray:
    return random_inputs(STEPS, seed)


def _programs(law, variants, gains):
    """Fresh states of one program per variant; ``gains``: the force gain of each scaled
    (a tunable written per actuator)."""
    states = np.zeros(len(variants) * law.state_size, dtype=np.uint8)
    for j, (v, g) in enumerate(zip(variants, gains, strict=True)):
        config = _configs()[v].copy()
        config["kp"] = np.float32(config["kp"] * g)
        law.init_at(states.ctypes.data + j * law.state_size, config)
    return states


def run_both(law, variants, gains, seeds, rows, steps, holds, build):
    """Every program steps ``steps`` times through its own random inputs (``seeds``) with
    the per-actuator law, and the programs ``rows`` (a batch) in lanes, held for ``holds``
    steps at a time (loaded, stepped, stored, as the engine holds a batch for a cycle).
    After each hold: the output fields of the batch's rows that differ between the two,
    and "state" if their program states do; returns the set of all of them."""
    n = len(variants)
    ref, lane = _programs(law, variants, gains), _programs(law, variants, gains)
    out_ref, out_lane = np.zeros(n, dtype=OUTPUT), np.zeros(n, dtype=OUTPUT)
    inp = np.zeros(n, dtype=INPUT)
    buf = law.lane_buffer()
    size = law.state_size
    before = law.lanes_build()
    law.lanes_build(build)
    differ: set[str] = set()
    try:
        k = 0
        while k < steps:
            law.lanes_load(buf, lane, rows)
            for _ in range(min(holds, steps - k)):
                for j in range(n):
                    inp[j] = _inputs(seeds[j])[k]
                for j in rows:
                    law.step_many(ref[j * size:(j + 1) * size], inp[j:j + 1],
                                  out_ref[j:j + 1])
                law.lanes_step(buf, inp, out_lane, rows)
                k += 1
                # the downstream words reach the outputs at every step
                if out_lane["down"][rows].tobytes() != out_ref["down"][rows].tobytes():
                    differ.add("down")
            law.lanes_store(buf, lane, out_lane, rows)
            differ |= {name for name in OUTPUT.names
                       if out_ref[name][rows].tobytes() != out_lane[name][rows].tobytes()}
            if ref.reshape(n, size)[rows].tobytes() != lane.reshape(n, size)[rows].tobytes():
                differ.add("state")
    finally:
        law.lanes_build(before)
    return differ


_batch = st.integers(1, 11).flatmap(lambda n: st.tuples(
    st.lists(st.integers(0, len(VARIANTS) - 1), min_size=n, max_size=n),
    st.lists(st.sampled_from([1.0, 0.5, 3.0]), min_size=n, max_size=n),
    st.lists(st.integers(0, 30), min_size=n, max_size=n),
    st.permutations(range(n)).flatmap(lambda p: st.integers(1, min(LW, len(p))).map(
        lambda m: np.array(p[:m], dtype=np.int64)))))


@settings(max_examples=25, deadline=None)
@given(batch=_batch, steps=st.integers(1, STEPS), holds=st.integers(1, 7),
       build=st.sampled_from([0, 1]))
def test_the_lanes_step_as_the_per_actuator_law(batch, steps, holds, build):
    """Random batches (1 to 8 of up to 11 programs, any rows, any order): each lane its own
    variant, force gain and inputs (random_inputs: every mode, enable/disable/clear-fault
    edges, command pauses past the timeout and safe-off, gain overrides, board status
    bits, saturated CRC counters, strain conversions starting late, positions and
    currents past the limits); both builds of the lane step (1: AVX2, 0: any x86-64)."""
    _need_cc()
    law = _law()
    if build == 1 and law.lanes_build() != 1:
        build = 0  # no AVX2 on this CPU
    variants, gains, seeds, rows = batch
    assert run_both(law, variants, gains, seeds, rows, steps, holds, build) == set()


def test_the_comparison_sees_a_changed_operation_order(tmp_path, monkeypatch):
    """The lane law built with one product regrouped (the velocity integral's ki * (..) *
    dt as ki * ((..) * dt), a different rounding) differs from the per-actuator law in the
    comparison above, where the real lane law does not."""
    _need_cc()
    src = (mcu_builds.SOURCE_DIR / "mcu_law_lanes.c").read_text()
    old = "L->cfg.vel_ki * (L->cfg.force_kp * e + fi - v_pump) * dt"
    assert old in src
    mutant = tmp_path / "c"
    shutil.copytree(mcu_builds.SOURCE_DIR, mutant)
    (mutant / "mcu_law_lanes.c").write_text(
        src.replace(old, "L->cfg.vel_ki * ((L->cfg.force_kp * e + fi - v_pump) * dt)"))
    monkeypatch.setattr(mcu_builds, "SOURCE_DIR", mutant)
    law = mcu_builds.HostLaw(mcu_builds.build_host())
    velocity = [k for k, v in enumerate(VARIANTS) if "mcu.controller=velocity" in v]
    args = (velocity, [1.0] * len(velocity), list(range(len(velocity))),
            np.arange(len(velocity), dtype=np.int64), STEPS, 5, law.lanes_build())
    assert "velocity_integral" in run_both(law, *args)
    assert run_both(_law(), *args) == set()


def test_the_lanes_keep_the_tunables_written_between_holds():
    """The lanes load the configuration from the program states each time a batch is
    claimed (the engine's tunables write the states' heads between cycles) and never
    write it back."""
    _need_cc()
    law = _law()
    states = _programs(law, [0, 1], [1.0, 1.0])
    heads = [states[j * law.state_size:j * law.state_size + STATE_HEAD.itemsize]
             .view(STATE_HEAD) for j in range(2)]
    rows = np.array([1, 0], dtype=np.int64)
    buf, out, inp = law.lane_buffer(), np.zeros(2, dtype=OUTPUT), np.zeros(2, dtype=INPUT)
    inp[:] = _inputs(3)[0]
    law.lanes_load(buf, states, rows)
    law.lanes_step(buf, inp, out, rows)
    heads[1]["cfg"]["kt_eq"] *= 2  # written while the lanes hold the batch: not seen ...
    law.lanes_store(buf, states, out, rows)
    assert heads[1]["cfg"]["kt_eq"] == np.float32(_configs()[1]["kt_eq"] * 2)  # ... kept
    inp[:] = _inputs(3)[1]
    ref = states.copy()
    for j in range(2):
        law.step_many(ref[j * law.state_size:(j + 1) * law.state_size], inp[j:j + 1],
                      np.zeros(1, dtype=OUTPUT))
    law.lanes_load(buf, states, rows)
    law.lanes_step(buf, inp, out, rows)
    law.lanes_store(buf, states, out, rows)
    assert states.tobytes() == ref.tobytes()


def test_the_avx2_build_of_the_lane_step_is_vector_code_without_fma():
    """The step's AVX2 build works on 256-bit registers (the eight lanes at once) and, like
    the per-actuator law, has no fused multiply-add."""
    _need_cc()
    if shutil.which("objdump") is None:
        pytest.skip("objdump not installed")
    asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(mcu_builds.build_host())],
                         capture_output=True, text=True, check=True).stdout
    body = asm[asm.index("<step_avx2>:"):]
    body = body[:body.index("\n\n")]
    assert body.count("%ymm") > 200 and "vdivps" in body and "vmulps" in body
    assert not [line for line in asm.splitlines() if "vfm" in line or "vfnm" in line]
