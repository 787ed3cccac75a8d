"""Current-loop input vectors: the golden vectors' inputs (``firmware_model.fpga.golden``)
laid onto the loop's ports, random words within range (operating-point runs and full-range
words), and saturation edges."""

from __future__ import annotations

import numpy as np

from firmware_model.fpga import golden
from firmware_model.fpga.current_loop import LOOP_INPUT

KP_BOARD, KI_BOARD = golden.KP_BOARD, golden.KI_BOARD


def _code(i_q15: int) -> int:
    """The ADC code whose current is nearest ``i_q15`` (codes step 16 LSB)."""
    return int(min(4095, max(0, (i_q15 >> 4) + 2048)))


def golden_inputs() -> np.ndarray:
    """One cycle per golden case of the angle, Clarke and PI tables, each combined with the
    next case of the others, so every golden input word reaches its block in the loop."""
    cases = golden.input_cases()
    thetas = [c[0] for c in cases["sin_cos"]]
    currents = [(_code(a), _code(b)) for a, b in cases["clarke"]]
    gains = [(c[2], c[4]) for c in cases["pi_step"]]
    n = max(len(thetas), len(currents), len(gains))
    x = np.zeros(n, dtype=LOOP_INPUT)
    x["enable"] = 1
    x["theta_e"] = [thetas[k % len(thetas)] for k in range(n)]
    x["ia_code"] = [currents[k % len(currents)][0] for k in range(n)]
    x["ib_code"] = [currents[k % len(currents)][1] for k in range(n)]
    x["kp"] = [gains[k % len(gains)][0] & 0xFFFF for k in range(n)]
    x["ki"] = [gains[k % len(gains)][1] & 0xFFFF for k in range(n)]
    x["iq_ref"] = np.linspace(-20000, 20000, n).astype(np.int64) & 0xFFFF
    x["current_limit"] = 18000
    return x


def random_inputs(n: int, seed: int) -> np.ndarray:
    """``n`` cycles: runs of an operating point (board gains, currents near zero, a turning
    rotor, references within the limit, the integrators building up) between runs of
    arbitrary words on every port."""
    rng = np.random.default_rng(seed)
    x = np.zeros(n, dtype=LOOP_INPUT)
    wild = np.repeat(rng.random(n // 200 + 1) < 0.4, 200)[:n]
    x["enable"] = np.where(rng.random(n) < 0.003, 0, 1)
    x["theta_e"] = np.where(wild, rng.integers(0, 1 << 16, n),
                            np.cumsum(rng.integers(0, 700, n)) & 0xFFFF)
    for port in ("ia_code", "ib_code"):
        walk = np.clip(2048 + np.cumsum(rng.integers(-20, 21, n)), 0, 4095)
        x[port] = np.where(wild, rng.integers(0, 4096, n), walk)
    for port, span in (("iq_ref", 2000), ("id_ref", 500), ("vq_ff", 3000)):
        steady = np.repeat(rng.integers(-span, span + 1, n // 50 + 1), 50)[:n]
        x[port] = np.where(wild, rng.integers(0, 1 << 16, n), steady & 0xFFFF)
    x["current_limit"] = np.where(wild, rng.integers(0, 1 << 16, n), 18000)
    x["kp"] = np.where(wild, rng.integers(0, 1 << 16, n), KP_BOARD)
    x["ki"] = np.where(wild, rng.integers(0, 1 << 16, n), KI_BOARD)
    return x


def edge_inputs(seed: int) -> np.ndarray:
    """Every combination of extreme words: codes 0/2048/4095, references and feed-forward at
    the s16 ends, limits 0 and 65535, gains 0 and 65535, angles at the table's wrap and
    quadrant edges; each held for a few cycles so the integrators reach their clamps."""
    rng = np.random.default_rng(seed)
    codes = (0, 1, 2048, 4094, 4095)
    words = (0x8000, 0x8001, 0xFFFF, 0, 1, 0x7FFF)
    thetas = (0, 31, 32, 65503, 65504, 65535, 16383, 16384, 32767, 32768, 49151, 49152)
    rows = []
    for ia in codes:
        for ib in codes:
            for _ in range(12):
                rows.append((1, ia, ib, int(rng.choice(thetas)), int(rng.choice(words)),
                             int(rng.choice(words)), int(rng.choice(words)),
                             int(rng.choice((0, 1, 18000, 40000, 65535))),
                             int(rng.choice((0, 1, KP_BOARD, 65535))),
                             int(rng.choice((0, 1, KI_BOARD, 65535)))))
    base = np.array(rows, dtype=np.int64)
    x = np.zeros(len(base) * 4, dtype=LOOP_INPUT)
    for j, name in enumerate(LOOP_INPUT.names):
        x[name] = np.repeat(base[:, j], 4)
    return x


def loop_sets(n: int, seed: int) -> list[tuple[str, np.ndarray]]:
    """(label, inputs): golden, edges, then random to make up ``n`` vectors in all (the
    first two sets are always whole)."""
    sets = [("golden", golden_inputs()), ("edges", edge_inputs(seed))]
    rest = n - sum(len(x) for _, x in sets)
    if rest > 0:
        sets.append(("random", random_inputs(rest, seed)))
    return sets
