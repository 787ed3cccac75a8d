"""MCU input steps (``mcu_input`` records) to compare the builds on: random within the
ranges the board's words can take, and steps recorded from whole-stack runs with faults.

The law has six variants (current- or velocity-based controller; pressure, strain or
complementary feedback); :data:`VARIANTS` are their configuration overrides, and each
source yields ``(overrides, inputs)`` pairs."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    IN_GAINS,
    INPUT,
)

VARIANTS: tuple[tuple[str, ...], ...] = tuple(
    (f"mcu.controller={c}", f"mcu.force_feedback={f}")
    for c in ("current", "velocity") for f in ("pressure", "strain", "complementary"))

PERIOD_TICKS = 4
PC_EVERY = 5  # MCU steps per PC command (1 kHz)


def _walk(rng: np.random.Generator, n: int, lo: int, hi: int, step: float,
          jump: float = 0.01) -> np.ndarray:
    """A bounded random walk with occasional jumps anywhere in [lo, hi]: filters see both
    smooth signals and steps."""
    x = np.empty(n)
    v = rng.uniform(lo, hi)
    steps = rng.normal(0.0, step, n)
    jumps = rng.random(n) < jump
    targets = rng.uniform(lo, hi, n)
    for k in range(n):
        v = targets[k] if jumps[k] else min(hi, max(lo, v + steps[k]))
        x[k] = v
    return np.rint(x).astype(np.int64)


def random_inputs(n: int, seed: int) -> np.ndarray:
    """``n`` steps of random input within range: ADC codes 0..4095, strain codes over the
    whole 24 bits, speeds, currents and positions past the limits, board status bits and
    CRC counters (changing, saturated), commands of every mode (forces past the limit), PC
    pauses long enough for the command timeout and the safe-off, enable/disable/clear-fault
    edges and gain overrides."""
    rng = np.random.default_rng(seed)
    rec = np.zeros(n, dtype=INPUT)
    rec["tick"] = np.arange(n) * PERIOD_TICKS + rng.integers(0, 2**20)
    up = np.zeros((n, B.UP_WORDS), dtype=np.int64)
    up[:, :] = rng.integers(0, 1 << 16, (n, B.UP_WORDS))  # words the law does not read
    for a in B.ANALOG_INPUTS:
        up[:, a.register] = _walk(rng, n, 0, 4095, 20.0)
    # Segments of operating-point signals (pressure pairs close together, moderate speed
    # and current) between the full-range ones, so the loop runs unsaturated too.
    small = np.repeat(rng.random(n // 250 + 1) < 0.6, 250)[:n]
    for a_reg, b_reg in ((B.U_P_CYL_A, B.U_P_CYL_B), (B.U_P_PUMP_A, B.U_P_PUMP_B)):
        common, diff = _walk(rng, n, 600, 3400, 5.0), _walk(rng, n, -150, 150, 3.0)
        up[small, a_reg] = (common + diff)[small]
        up[small, b_reg] = (common - diff)[small]
    strain = _walk(rng, n, 0, (1 << 24) - 1, 3000.0)
    samples = np.minimum(np.cumsum(rng.random(n) < 0.8), 255)
    samples[: rng.integers(0, 20)] = 0  # no conversion read yet
    up[:, B.U_STRAIN_LO] = strain & 0xFFFF
    up[:, B.U_STRAIN_HI] = (strain >> 16) | (samples << 8)
    speed = np.where(small, _walk(rng, n, -60, 60, 3.0), _walk(rng, n, -32768, 32767, 300.0))
    up[:, B.U_SPEED] = speed & 0xFFFF
    count = _walk(rng, n, (1 << 23) - 8_000_000, (1 << 23) + 8_000_000, 20_000.0)
    count[rng.random(n) < 0.002] = rng.integers(0, 1 << 32)  # any 32-bit count
    up[:, B.U_PISTON_LO] = count & 0xFFFF
    up[:, B.U_PISTON_HI] = (count >> 16) & 0xFFFF
    iq = np.where(small, _walk(rng, n, -3000, 3000, 50.0), _walk(rng, n, -25000, 25000, 500.0))
    up[:, B.U_IQ] = iq & 0xFFFF
    up[:, B.U_SSI] = rng.integers(0, 2048, n)
    status = np.where(rng.random(n) < 0.9, B.ST_ENABLED | B.ST_LINK_OK, 0)
    status |= np.where(rng.random(n) < 0.05, rng.integers(0, 256, n), 0)
    up[:, B.U_STATUS] = status
    crc = np.cumsum(rng.random(n) < 0.01)
    crc = np.where(rng.random(n) < 0.02, 0xFFFF, np.minimum(crc, 0xFFFF))
    up[:, B.U_ERR_LINK_CRC] = crc
    rec["up"] = up
    rec["up_crc_errors"] = np.cumsum(rng.random(n) < 0.01)
    # Commands at the PC rate, with pauses (timeout after 50 steps, safe-off after 300).
    flags = np.zeros(n, dtype=np.uint32)
    pc = np.arange(n) % PC_EVERY == 0
    pause = np.zeros(n, dtype=bool)
    for start in rng.integers(0, n, max(1, n // 2000)):
        pause[start:start + int(rng.integers(40, 400))] = True
    flags[pc & ~pause] |= IN_COMMAND
    mode = np.repeat(rng.choice(3, n // 200 + 1, p=(0.1, 0.6, 0.3)), 200)[:n]
    rec["mode"] = mode
    value = np.where(mode == 2, rng.uniform(-0.03, 0.03, n), rng.uniform(-2000, 2000, n))
    rec["value"] = value
    flags[0] |= IN_ENABLE | IN_COMMAND
    flags[rng.random(n) < 0.001] |= IN_ENABLE
    flags[rng.random(n) < 0.001] |= IN_DISABLE
    flags[rng.random(n) < 0.001] |= IN_CLEAR_FAULT
    gains = rng.random(n) < 0.01
    flags[gains] |= IN_GAINS
    rec["kp_position"] = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(1e3, 3e4, n))
    rec["kp_force"] = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.5, 4.0, n))
    rec["flags"] = flags
    rec["angle_offset"] = rng.integers(0, 1 << 16, n)
    return rec


def random_sets(n: int, seed: int) -> Iterator[tuple[tuple[str, ...], np.ndarray]]:
    """``n`` random steps split over the six variants."""
    parts = np.diff(np.linspace(0, n, len(VARIANTS) + 1).astype(int))
    for k, (overrides, size) in enumerate(zip(VARIANTS, parts, strict=True)):
        if size:
            yield overrides, random_inputs(int(size), seed * 100 + k)
