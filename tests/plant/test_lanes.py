"""The plant in vector lanes (plant.lanes) against the scalar kernel (plant.kernel) under the
arithmetic recipe 3: bit for bit per actuator, over random states, inputs and mixes of
actuators that differ (drive mode, load kind, effects, sub-steps); and recipe 3's own
exp, sin/cos and tanh against libm (they are new functions: accurate, not only
reproducible)."""

from __future__ import annotations

import math
import re

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from plant import kernel, lanes
from plant import layout as L
from plant.blocks.lanemath import exp3, sincos3, tanh3
from plant.config import load_config
from plant.model import build_params

_BASE = {
    kind: build_params(load_config(None, ["sim.plant_numerics=3", f"load.kind={kind}"]))
    for kind in L.LOAD_KINDS
}
_FLAGS = (L.P_TEMP_ON, L.P_PULS_ON, L.P_PC_ON, L.P_SF_ON, L.P_KSX_ON, L.P_AIR_ON)


@st.composite
def actuator(draw):
    """(params, state, inputs) of one actuator: any load kind, any effect on or off, any
    drive mode, 1-3 sub-steps, states over the ranges a run visits (and beyond the end
    stops)."""
    kind = draw(st.sampled_from(L.LOAD_KINDS))
    p = _BASE[kind].copy()
    for f in _FLAGS:
        p[f] = float(draw(st.booleans()))
    p[L.P_AIR_A] = draw(st.floats(0.0, 2e8))
    n_sub = draw(st.integers(1, 3))
    p[L.P_H_SUB] = p[L.P_H_SUB] * p[L.P_N_SUB] / n_sub
    p[L.P_N_SUB] = n_sub
    half = p[L.P_HALF_STROKE]
    f = st.floats
    x = np.zeros(L.N_STATES)
    x[L.S_THP] = draw(f(-2.0, 2.0))
    x[L.S_VP] = draw(f(-0.5, 0.5))
    x[L.S_TQ] = draw(f(-3e4, 3e4))
    x[L.S_THC] = draw(f(-1.2 * half, 1.2 * half))
    x[L.S_VC] = draw(f(-0.5, 0.5))
    x[L.S_XL] = draw(f(-0.05, 0.05))
    x[L.S_VL] = draw(f(-0.5, 0.5))
    x[L.S_ID] = draw(f(-20.0, 20.0))
    x[L.S_IQ] = draw(f(-20.0, 20.0))
    x[L.S_TOIL] = draw(f(-20.0, 120.0))
    x[L.S_TROD] = draw(f(-20.0, 120.0))
    x[L.S_EIN:] = draw(f(-10.0, 10.0))
    u = np.zeros(L.N_INPUTS)
    u[L.IN_MODE] = draw(st.sampled_from([m.value for m in L.DriveMode]))
    for i in (L.IN_DA, L.IN_DB, L.IN_DC):
        u[i] = draw(f(-0.1, 1.1))
    u[L.IN_IQ_REF] = draw(f(-20.0, 20.0))
    u[L.IN_ID_REF] = draw(f(-5.0, 5.0))
    u[L.IN_TAU_REF] = draw(f(-3e3, 3e3))
    u[L.IN_F_EXT] = draw(f(-3e3, 3e3))
    u[L.IN_T_AMB] = draw(f(-20.0, 60.0))
    return p, x, u


def _bits(a):
    return np.ascontiguousarray(a).view(np.int64)


@settings(max_examples=60, deadline=None)
@given(acts=st.lists(actuator(), min_size=1, max_size=lanes.LW), ticks=st.integers(1, 3))
def test_rk4_in_lanes_is_the_scalar_kernel_bit_for_bit(acts, ticks):
    """Up to LW different actuators in one batch, ``ticks`` RK4 ticks: each lane's states
    have the bits the scalar kernel gives that actuator alone."""
    P = np.array([a[0] for a in acts])
    X = np.array([a[1] for a in acts])
    U = np.array([a[2] for a in acts])
    ref = X.copy()
    work = np.zeros((5, L.N_STATES))
    for i in range(len(acts)):
        for _ in range(ticks):
            kernel.rk4_tick(ref[i], P[i], U[i], work)
    buf = lanes.lane_buffer()
    rows = np.arange(len(acts))
    lanes.load_params(buf, P, rows, len(acts))
    for _ in range(ticks):
        lanes.load_states(buf, X, U, rows, len(acts))
        lanes.rk4_lanes(buf, int(P[:, L.P_N_SUB].max()))
        lanes.store_states(buf, X, rows, len(acts))
    np.testing.assert_array_equal(_bits(X), _bits(ref))


def _run_both(P, X, U, ticks, n_sub_max):
    """``ticks`` RK4 ticks of the actuators (P, X, U) in one batch and, each alone, in the
    scalar kernel: (lanes' states, scalar states)."""
    ref = X.copy()
    work = np.zeros((5, L.N_STATES))
    for i in range(len(P)):
        for _ in range(ticks):
            kernel.rk4_tick(ref[i], P[i], U[i], work)
    X = X.copy()
    buf = lanes.lane_buffer()
    rows = np.arange(len(P))
    lanes.load_params(buf, P, rows, len(P))
    for _ in range(ticks):
        lanes.load_states(buf, X, U, rows, len(P))
        lanes.rk4_lanes(buf, n_sub_max)
        lanes.store_states(buf, X, rows, len(P))
    return X, ref


def test_an_effect_on_in_one_lane_only_is_computed_for_it():
    """A batch skips an effect no lane has on (its row holds the value each lane would
    select): one lane with seal and pump Coulomb friction, entrained air, oil temperature,
    a moving load against its end stop and two sub-steps among seven without any of them
    (fixed loads, one sub-step) gets its scalar states, and so do the seven; and a batch
    with none of them is unchanged by a larger ``n_sub_max`` (no lane takes the extra
    sub-steps)."""
    p = _BASE["fixed"].copy()
    for f in _FLAGS:
        p[f] = 0.0
    P = np.array([p] * lanes.LW)
    odd = _BASE["conrod"].copy()
    for f in (L.P_TEMP_ON, L.P_PC_ON, L.P_SF_ON, L.P_AIR_ON, L.P_KSX_ON):
        odd[f] = 1.0
    odd[L.P_AIR_A] = 1e7
    odd[L.P_H_SUB] = odd[L.P_H_SUB] * odd[L.P_N_SUB] / 2
    odd[L.P_N_SUB] = 2
    P[5] = odd
    rng = np.random.default_rng(5)
    X = np.zeros((lanes.LW, L.N_STATES))
    X[:, L.S_VP] = rng.uniform(-0.2, 0.2, lanes.LW)
    X[:, L.S_TQ] = rng.uniform(-2e4, 2e4, lanes.LW)
    X[:, L.S_VC] = rng.uniform(-0.2, 0.2, lanes.LW)
    X[:, L.S_ID] = rng.uniform(-10.0, 10.0, lanes.LW)
    X[:, L.S_IQ] = rng.uniform(-10.0, 10.0, lanes.LW)
    X[:, L.S_TOIL] = 40.0
    odd[L.P_X_ANCHOR] = odd[L.P_HALF_STROKE]  # the rod lets the pressure hold the stop
    P[5] = odd
    X[5, L.S_THC] = odd[L.P_HALF_STROKE]
    X[5, L.S_VC] = 0.3
    X[5, L.S_VP] = 0.1
    X[5, L.S_TQ] = 2e4
    U = np.zeros((lanes.LW, L.N_INPUTS))
    U[:, L.IN_DA:L.IN_DC + 1] = rng.uniform(0.2, 0.8, (lanes.LW, 3))
    U[:, L.IN_T_AMB] = 25.0
    got, ref = _run_both(P, X, U, 3, 2)
    np.testing.assert_array_equal(_bits(got), _bits(ref))
    assert got[5, L.S_THC] == odd[L.P_HALF_STROKE]  # the lane met its end stop
    got, ref = _run_both(P[:4], X[:4], U[:4], 2, 3)
    np.testing.assert_array_equal(_bits(got), _bits(ref))


@njit(cache=True, error_model="numpy")
def _lane_loop(x, out):
    """The recipe's functions in a loop the compiler vectorises."""
    for i in range(x.shape[0]):
        s, c = sincos3(x[i])
        out[0, i] = exp3(x[i])
        out[1, i] = s
        out[2, i] = c
        out[3, i] = tanh3(x[i])


@njit(cache=True)
def _scalar(v):
    s, c = sincos3(v)
    return exp3(v), s, c, tanh3(v)


_WIDE = st.floats(-800.0, 800.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(xs=st.lists(st.one_of(_WIDE, st.floats(-1e-6, 1e-6), st.floats(-1e5, 1e5)),
                   min_size=1, max_size=40))
def test_recipe_functions_in_a_vector_loop_equal_the_scalar_calls(xs):
    x = np.array(xs)
    out = np.empty((4, len(x)))
    _lane_loop(x, out)
    for i, v in enumerate(x):
        assert _bits(out[:, i]).tolist() == _bits(np.array(_scalar(v))).tolist(), v


def _ulps(a, b):
    return abs(a - b) / math.ulp(abs(b)) if b != 0.0 else abs(a) / math.ulp(1e-300)


@settings(max_examples=300, deadline=None)
@given(v=st.floats(-700.0, 700.0))
def test_exp3_is_within_two_ulps_of_libm(v):
    assert _ulps(_scalar(v)[0], math.exp(v)) <= 2.0


@settings(max_examples=300, deadline=None)
@given(v=st.floats(-1e5, 1e5))
def test_sincos3_is_within_an_absolute_2e_16_of_libm(v):
    _, s, c, _ = _scalar(v)
    # Absolute: near a zero of sin or cos the reduced argument's last bits decide.
    assert abs(s - math.sin(v)) <= 2e-16 * max(1.0, abs(v) / 1e3)
    assert abs(c - math.cos(v)) <= 2e-16 * max(1.0, abs(v) / 1e3)


@settings(max_examples=300, deadline=None)
@given(v=st.one_of(st.floats(-30.0, 30.0), st.floats(-1e-3, 1e-3)))
def test_tanh3_is_within_1e_15_relative_of_libm(v):
    t = _scalar(v)[3]
    assert abs(t - math.tanh(v)) <= 1e-15 * max(abs(math.tanh(v)), 1e-300) + 5e-17


def test_exp3_at_its_limits():
    assert _scalar(-1000.0)[0] == 0.0 and _scalar(1000.0)[0] == math.inf
    assert _scalar(0.0)[0] == 1.0 and _scalar(0.0)[3] == 0.0
    assert _scalar(0.0)[1:3] == (0.0, 1.0)


def _cached_kernel_asm() -> str | None:
    """The machine code of ``rk4_lanes`` as the runs use it: the object code numba's cache
    holds (compiled once by ``hil.sim.warmup``), disassembled by objdump. None when there is
    no objdump or the kernel is not in the cache."""
    import shutil
    import subprocess
    import tempfile

    from numba.core import codegen

    if shutil.which("objdump") is None:
        return None
    objects = []
    keep = codegen.CodeLibrary._set_compiled_object

    def spy(self, value):  # noqa: ANN001, ANN202 - numba's own signature
        objects.append(value)
        return keep(self, value)

    # A dispatcher of its own over the same function reads the same cache entry (the one
    # the engines load) and hands its object code to the library being rebuilt.
    f = numba.njit(**lanes.LANES)(lanes.rk4_lanes.py_func)
    codegen.CodeLibrary._set_compiled_object = spy
    try:
        f(lanes.lane_buffer(), 1)
    finally:
        codegen.CodeLibrary._set_compiled_object = keep
    if not f.stats.cache_hits or len(objects) != 1:
        return None
    with tempfile.NamedTemporaryFile(suffix=".o") as obj:
        obj.write(objects[0])
        obj.flush()
        return subprocess.run(["objdump", "-d", "--no-show-raw-insn", obj.name],
                              capture_output=True, text=True, check=True).stdout


def _one_stage_asm() -> str:
    """One RK4 stage of the lane kernel compiled here (the effects' loops, the derivatives
    and the intermediate states, the code ``rk4_lanes`` inlines four times): the same
    statements, a quarter of the kernel's compile time (~7 s against ~47 s idle)."""
    opts = {k: v for k, v in lanes.LANES.items() if k != "cache"}

    def one_stage(B):
        lanes.rk4_stage(B, lanes.X, lanes.K1, lanes.batch_effects(B), 0.5)

    f = numba.njit(**opts)(one_stage)
    f(lanes.lane_buffer())
    return next(iter(f.inspect_asm().values()))


def _check_vector_asm(asm: str) -> None:
    wide = re.findall(r"\bv(?:mul|add|sub|div)pd\s+[^\n]*%[yz]mm", asm)
    assert len(wide) > 200
    # A loop of its own over the states (or a conditional expression LLVM keeps as a
    # branch) is unrolled into scalar code: one vmulsd/vdivsd per lane.
    assert not re.findall(r"\bv(?:mul|add|sub|div)sd\b", asm)
    assert not re.findall(r"vfn?m(?:add|sub)", asm)


@pytest.mark.slow  # ~1 s: loads the whole kernel from the cache
def test_rk4_lanes_compiles_to_vector_instructions_without_contraction():
    """The machine code of the lane kernel: its arithmetic is on full vector registers
    (ymm with AVX2, zmm with AVX-512), none of it scalar, and no multiply-add is fused.
    Read from the kernel the runs load (numba's cache, disassembled by objdump: no compile
    here); without objdump or a cached kernel, one RK4 stage compiled here."""
    import llvmlite.binding as llvm

    if "+avx2" not in llvm.get_host_cpu_features().flatten():
        pytest.skip("no AVX2 on this CPU: nothing to check the lanes against")
    _check_vector_asm(_cached_kernel_asm() or _one_stage_asm())
