"""Golden vectors of the fixed-point FOC chain: fixed inputs and the model's exact outputs.

The vectors pin the integer arithmetic of :mod:`firmware_model.fpga.foc` (and the
:func:`~firmware_model.fpga.fixed.isqrt` it uses) bit for bit: an HDL test bench can replay
them against the FPGA, and ``tests/fpga/test_golden.py`` replays them against this model,
both compiled and as ``fn.py_func`` on Python ints. Inputs are hand-picked extremes (zeros,
full-scale words, table-quadrant angles, saturating and wind-up PI cases) plus words drawn
from a fixed-seed :class:`numpy.random.Generator`.

Units are the model's (``docs/fpga.md``): currents s16 Q1.15 of I_FS (40 A), voltages s16
Q1.15 of V_dc (48 V), angle u16 (2**16 per electrical turn), sin/cos Q1.15, PWM compare
counts 0..top. The file is JSON::

    {"header": {...field order per function...},
     "sin_cos": [[theta_e, sin, cos], ...], ...}

Regenerate with ``python -m firmware_model.fpga.golden --write PATH`` (the project's copy is
``tests/fpga/golden_vectors.json``); ``--check PATH`` compares instead of writing. The model
does not know where a checkout keeps its tests: the path is always given.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from firmware_model.fpga.fixed import isqrt
from firmware_model.fpga.foc import (
    V_LIMIT_Q15,
    clarke,
    inv_park,
    park,
    pi_step,
    q_limit,
    sin_cos,
    svpwm,
)

#: Seed of the Generator that draws the random part of the inputs.
SEED = 20240611
#: Format version of the file; bump when the layout (not the numbers) changes.
VERSION = 1
#: Repository-relative default location of the vector file.
#: PWM top of the board: 50 MHz / (2 * 20 kHz) compare counts.
TOP = 1250
#: PI gain multipliers of the shipped configuration (``board.gain_registers``): kp, ki.
KP_BOARD = 1287
KI_BOARD = 6433
#: Shifts of the PI gain multipliers (``board.KP_SHIFT``, ``board.KI_SHIFT``).
KP_SHIFT = 12
KI_SHIFT = 16
#: Random cases drawn per function (hand-picked extremes come on top).
N_RANDOM = 120

S16_MIN, S16_MAX = -(1 << 15), (1 << 15) - 1

#: Field order of each row: (input names, output names). A row is inputs + outputs.
FIELDS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "sin_cos": (("theta_e",), ("sin", "cos")),
    "clarke": (("i_a", "i_b"), ("i_alpha", "i_beta")),
    "park": (("i_alpha", "i_beta", "sin", "cos"), ("i_d", "i_q")),
    "inv_park": (("v_d", "v_q", "sin", "cos"), ("v_alpha", "v_beta")),
    "svpwm": (("v_alpha", "v_beta", "top"), ("count_a", "count_b", "count_c")),
    "pi_step": (
        ("error", "integ", "kp", "kp_shift", "ki", "ki_shift", "ff", "limit"),
        ("output", "integ_new"),
    ),
    "q_limit": (("v_d", "v_max"), ("v_q_max",)),
    "isqrt": (("n",), ("root",)),
}

#: The model functions, compiled (numba dispatchers; ``.py_func`` is the Python original).
FUNCTIONS: dict[str, Callable[..., Any]] = {
    "sin_cos": sin_cos,
    "clarke": clarke,
    "park": park,
    "inv_park": inv_park,
    "svpwm": svpwm,
    "pi_step": pi_step,
    "q_limit": q_limit,
    "isqrt": isqrt,
}

Case = tuple[int, ...]


def _ints(rng: np.random.Generator, lo: int, hi: int, n: int) -> list[int]:
    """``n`` Python ints uniform in ``lo .. hi`` inclusive."""
    return [int(x) for x in rng.integers(lo, hi, size=n, endpoint=True, dtype=np.int64)]


def _dedup(cases: list[Case]) -> list[Case]:
    """Cases in first-seen order without repeats."""
    return list(dict.fromkeys(cases))


def _sin_cos_cases(rng: np.random.Generator) -> list[Case]:
    """Angles (u16): quadrant edges, table-rounding edges (x*64 +- 32), wrap, random."""
    picked = [0, 1, 31, 32, 33, 63, 64, 95, 96, 8191, 8192, 16351, 16352, 16383, 16384,
              16385, 16415, 16416, 24576, 32767, 32768, 32769, 40960, 49151, 49152, 49153,
              57344, 65471, 65472, 65503, 65504, 65505, 65535]
    sweep = list(range(0, 1 << 16, 1 << 10))  # 64 evenly spaced angles
    return _dedup([(t,) for t in picked + sweep + _ints(rng, 0, 0xFFFF, N_RANDOM)])


def _clarke_cases(rng: np.random.Generator) -> list[Case]:
    """Phase currents (s16): extreme pairs (i_beta saturates), ADC-range pairs, random."""
    ext = [S16_MIN, -28378, -16384, -1, 0, 1, 16384, 28377, 28378, S16_MAX]
    cases = [(a, b) for a in ext for b in ext]
    adc = [((x - 2048) << 4) for x in _ints(rng, 0, 4095, 2 * 20)]  # 12-bit ADC codes
    cases += list(zip(adc[0::2], adc[1::2], strict=True))
    r = _ints(rng, S16_MIN, S16_MAX, 2 * N_RANDOM)
    cases += list(zip(r[0::2], r[1::2], strict=True))
    return _dedup(cases)


def _rotation_cases(rng: np.random.Generator) -> list[Case]:
    """(x, y, sin, cos) for park/inv_park: extreme vectors at table and raw angles, random."""
    angles = [0, 8192, 16384, 24576, 32768, 49152, 65535, 5461]
    trig = [tuple(int(v) for v in sin_cos(t)) for t in angles]
    trig += [(S16_MAX, S16_MAX), (S16_MIN, S16_MIN), (S16_MIN, S16_MAX)]  # not on the circle
    ext = [(S16_MAX, S16_MAX), (S16_MIN, S16_MIN), (S16_MAX, S16_MIN), (S16_MIN, 0),
           (0, S16_MAX), (0, 0), (18918, 0), (-1, 1)]
    cases = [(x, y, s, c) for (x, y) in ext for (s, c) in trig]
    r = _ints(rng, S16_MIN, S16_MAX, 2 * N_RANDOM)
    th = _ints(rng, 0, 0xFFFF, N_RANDOM)
    for k in range(N_RANDOM):
        s, c = sin_cos(th[k])
        cases.append((r[2 * k], r[2 * k + 1], int(s), int(c)))
    return _dedup(cases)


def _svpwm_cases(rng: np.random.Generator) -> list[Case]:
    """(v_alpha, v_beta, top): extremes (clamping), the V_dc/sqrt3 circle, other tops, random."""
    ext = [S16_MIN, -V_LIMIT_Q15, -1, 0, 1, V_LIMIT_Q15, S16_MAX]
    cases = [(a, b, TOP) for a in ext for b in ext]
    for t in range(0, 1 << 16, 1 << 11):  # 32 points on the largest linear circle
        va, vb = inv_park(V_LIMIT_Q15, 0, *sin_cos(t))
        cases.append((int(va), int(vb), TOP))
    for top in (0, 1, 1000, 1251, 4095):
        cases += [(S16_MAX, 0, top), (-12345, 6789, top), (0, 0, top)]
    r = _ints(rng, S16_MIN, S16_MAX, 2 * N_RANDOM)
    cases += [(r[2 * k], r[2 * k + 1], TOP) for k in range(N_RANDOM)]
    return _dedup(cases)


def _pi_cases(rng: np.random.Generator) -> list[Case]:
    """PI steps: saturating outputs, integrator at/over its clamp, wind-up trajectories,
    random words. Row = (error, integ, kp, kp_shift, ki, ki_shift, ff, limit)."""
    lim = V_LIMIT_Q15
    i_lim = lim << KI_SHIFT
    g = (KP_BOARD, KP_SHIFT, KI_BOARD, KI_SHIFT)
    cases: list[Case] = [
        (0, 0, *g, 0, lim),
        (1, 0, *g, 0, lim),
        (-1, 0, *g, 0, lim),
        (65535, 0, *g, 0, lim),           # proportional path alone saturates
        (-65535, 0, *g, 0, lim),
        (-65536, 0, *g, 0, lim),          # s17 minimum
        (65535, 0, 0xFFFF, KP_SHIFT, 0xFFFF, KI_SHIFT, 0, lim),
        (-65536, 0, 0xFFFF, KP_SHIFT, 0xFFFF, KI_SHIFT, 0, lim),
        (100, i_lim, *g, 0, lim),          # integrator at its clamp, error pushes further
        (-100, -i_lim, *g, 0, lim),
        (-100, i_lim, *g, 0, lim),         # at the clamp, error reverses
        (100, -i_lim, *g, 0, lim),
        (100, i_lim + 12345, *g, 0, lim),  # integrator above a (shrunk) limit
        (-100, -i_lim - 12345, *g, 0, lim),
        (100, -i_lim - 12345, *g, 40000, lim),   # held below the clamp (ff saturates)
        (100, 0, *g, 40000, lim),          # feed-forward alone saturates: integrator held
        (-100, 0, *g, -40000, lim),
        (100, 0, *g, -40000, lim),         # saturated low, error positive: integrates
        (0, 0, *g, 0, 0),                  # zero limit (q_limit when v_d uses the circle)
        (500, 0, *g, 0, 0),
        (500, 1 << 20, 0, KP_SHIFT, 0, KI_SHIFT, 0, 0),
        (3, (1 << 15) - 1, 0, KP_SHIFT, 0, KI_SHIFT, 0, lim),  # integrator rounding edge
        (3, 1 << 15, 0, KP_SHIFT, 0, KI_SHIFT, 0, lim),
        (3, -(1 << 15), 0, KP_SHIFT, 0, KI_SHIFT, 0, lim),
        (3, -(1 << 15) - 1, 0, KP_SHIFT, 0, KI_SHIFT, 0, lim),
        (1, 0, 2048, KP_SHIFT, 0, KI_SHIFT, 0, lim),   # kp*e = 0.5 LSB: rounds up
        (-1, 0, 2048, KP_SHIFT, 0, KI_SHIFT, 0, lim),  # -0.5 LSB: rounds up to 0
        (-3, 0, 2048, KP_SHIFT, 0, KI_SHIFT, 0, lim),  # -1.5 LSB: -1
    ]
    # Wind-up trajectories: 12 ticks of a large error, then it reverses (board gains).
    for e_hi, e_lo, ff in ((3000, -200, 0), (-3000, 200, 0), (800, -50, 10000)):
        integ = 0
        for tick in range(16):
            e = e_hi if tick < 12 else e_lo
            cases.append((e, integ, *g, ff, lim))
            _, integ = pi_step(e, integ, *g, ff, lim)
            integ = int(integ)
    e = _ints(rng, -65536, 65535, N_RANDOM)
    ig = _ints(rng, -i_lim, i_lim, N_RANDOM)
    kp = _ints(rng, 0, 0xFFFF, N_RANDOM)
    ki = _ints(rng, 0, 0xFFFF, N_RANDOM)
    ff = _ints(rng, S16_MIN, S16_MAX, N_RANDOM)
    lm = _ints(rng, 0, lim, N_RANDOM)
    for k in range(N_RANDOM):
        # integ drawn against V_LIMIT, clamped to this row's limit for realism half the time
        integ = ig[k] if k % 2 else max(-(lm[k] << KI_SHIFT), min(lm[k] << KI_SHIFT, ig[k]))
        cases.append((e[k], integ, kp[k], KP_SHIFT, ki[k], KI_SHIFT, ff[k], lm[k]))
    return _dedup(cases)


def _q_limit_cases(rng: np.random.Generator) -> list[Case]:
    """(v_d, v_max): v_d at and beyond the circle, zero radius, random."""
    lim = V_LIMIT_Q15
    vd = [S16_MIN, -lim - 1, -lim, -lim + 1, -1, 0, 1, 100, 12345, lim - 1, lim, lim + 1,
          S16_MAX]
    cases = [(v, m) for v in vd for m in (lim, 0, 1, S16_MAX)]
    cases += [(v, lim) for v in _ints(rng, -lim, lim, N_RANDOM)]
    return _dedup(cases)


def _isqrt_cases(rng: np.random.Generator) -> list[Case]:
    """n in 0 .. 2**32-1: small, powers of 4 and 2, squares and neighbours, random."""
    n = [0, 1, 2, 3, 4, 5, 8, 9, 15, 16, 17, 99, 100, 101]
    for p in (16, 24, 30, 31, 32):
        n += [(1 << p) - 1, 1 << p]
    n += [65535 ** 2 - 1, 65535 ** 2, 65535 ** 2 + 1, 18918 ** 2, 18918 ** 2 - 1,
          32767 ** 2, 32768 ** 2 - 1]
    for r in _ints(rng, 2, 65535, 30):
        n += [r * r - 1, r * r]
    n += _ints(rng, 0, (1 << 32) - 1, N_RANDOM)
    return _dedup([(x,) for x in n if 0 <= x < 1 << 32])


def input_cases() -> dict[str, list[Case]]:
    """The input words of every function, in file order (deterministic: fixed seed)."""
    rng = np.random.default_rng(SEED)
    return {
        "sin_cos": _sin_cos_cases(rng),
        "clarke": _clarke_cases(rng),
        "park": _rotation_cases(rng),
        "inv_park": _rotation_cases(rng),
        "svpwm": _svpwm_cases(rng),
        "pi_step": _pi_cases(rng),
        "q_limit": _q_limit_cases(rng),
        "isqrt": _isqrt_cases(rng),
    }


def outputs(name: str, args: Sequence[int], python: bool = False) -> tuple[int, ...]:
    """The outputs of function ``name`` for ``args`` as a tuple of Python ints.

    ``python=True`` runs ``fn.py_func`` (the uncompiled source) on Python ints.
    """
    fn = FUNCTIONS[name]
    if python:
        fn = fn.py_func
    out = fn(*(int(a) for a in args))
    if not isinstance(out, tuple):
        out = (out,)
    return tuple(int(v) for v in out)


def header() -> dict[str, Any]:
    """The file header: provenance, units and the field order of each function's rows."""
    return {
        "version": VERSION,
        "generator": "python -m firmware_model.fpga.golden --write",
        "seed": SEED,
        "row": "inputs followed by outputs, all integers, in the order of 'fields'",
        "units": {
            "current": "s16 Q1.15 of I_FS = 40 A (1.22 mA/LSB)",
            "voltage": "s16 Q1.15 of V_dc = 48 V (1.46 mV/LSB)",
            "angle": "u16, 2^16 per electrical turn",
            "sin_cos": "s16 Q1.15",
            "count": "PWM compare counts 0..top (top = 1250: 50 MHz, 20 kHz centre-aligned)",
            "integ": "s32, output LSB * 2^ki_shift",
        },
        "fields": {k: {"inputs": list(i), "outputs": list(o)} for k, (i, o) in FIELDS.items()},
    }


def generate() -> dict[str, Any]:
    """All vectors: the header plus, per function, rows of inputs and compiled outputs."""
    vectors: dict[str, Any] = {"header": header()}
    for name, cases in input_cases().items():
        vectors[name] = [list(c) + list(outputs(name, c)) for c in cases]
    return vectors


def dumps(vectors: dict[str, Any]) -> str:
    """JSON text with one row per line (readable diffs), keys in insertion order."""
    head = []
    for key, val in vectors["header"].items():
        if isinstance(val, dict):
            inner = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in val.items())
            head.append(f" {json.dumps(key)}: {{\n{inner}\n }}")
        else:
            head.append(f" {json.dumps(key)}: {json.dumps(val)}")
    parts = ["{\n", '"header": {\n', ",\n".join(head), "\n}"]
    for name, rows in vectors.items():
        if name == "header":
            continue
        body = ",\n".join(json.dumps(r, separators=(",", ":")) for r in rows)
        parts.append(f',\n"{name}": [\n{body}\n]')
    parts.append("\n}\n")
    return "".join(parts)


def load(path: Path | str) -> dict[str, Any]:
    """Read a vector file."""
    return json.loads(Path(path).read_text())


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: ``--write PATH`` writes the vectors, ``--check PATH`` compares with a file."""
    ap = argparse.ArgumentParser(prog="python -m firmware_model.fpga.golden",
                                 description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path, metavar="PATH",
                   help="write the vectors (the project's: tests/fpga/golden_vectors.json)")
    g.add_argument("--check", type=Path, metavar="PATH",
                   help="exit 1 if the file differs from freshly generated vectors")
    a = ap.parse_args(argv)
    vectors = generate()
    if a.write is not None:
        text = dumps(vectors)
        a.write.parent.mkdir(parents=True, exist_ok=True)
        a.write.write_text(text)
        n = sum(len(v) for k, v in vectors.items() if k != "header")
        print(f"wrote {n} rows ({len(text)} bytes) to {a.write}")
        return 0
    if load(a.check) == json.loads(dumps(vectors)):
        print(f"{a.check}: up to date")
        return 0
    print(f"{a.check}: differs from the model", file=sys.stderr)
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
