"""Does simulating a fit's Jacobian columns together save CPU, at the same bits? A probe.

A forward-difference Jacobian runs one simulation per free parameter, all of the same
record: 57 % (conrod) to 71 % (free piston) of the simulated samples of ``eha-hil bench
identify``. The kernel (:func:`hil.identify.model._simulate`) is a serial chain per
sub-step, so several parameter vectors (*lanes*) advanced in one time loop, taking turns
inside every sub-step, might let the core overlap their chains. This probe times that
against one kernel call per lane, and compares the states bit for bit.

:func:`_simulate_batch` is ``_simulate``'s loop with a lane index, each lane reading its own
discretised matrices, start state, applied force, linear and effect parameters; the loop's
shape, its arithmetic and its order per lane are ``_simulate``'s. The kernel's arguments
are taken as :meth:`~hil.identify.model.FastModel._simulate_states` builds them (the
kernel stood in for once per vector), so the lanes see what a fit's columns see.

Run: ``python -m hil.bench.identify_batch`` (the three cases, 2, 4, 8 and 13 lanes, the
fits' 30,000-sample head of a 16 s, 5 kHz rig record); ``--case``, ``--lanes``,
``--samples 0`` (the whole record), ``--reps``. CPU times are medians of the repetitions,
the two ways taking turns; quote them with ``uptime``. ``--split``: where one Jacobian's
CPU goes instead (:func:`jacobian_split`).

Found (docs/identify.md, "Jacobian columns simulated together"): no gain, and the bits
are ``_simulate``'s only for the linear model and the pump's friction; LLVM compiles the
seal's and the pulsation's code differently in the lane loop (fastmath reassociation), so
their lanes differ from the single runs in the last bits.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
from numba import njit

from hil.identify import model as fast
from hil.identify.model import (
    _E_ALPHA,
    _E_H_SUB,
    _E_HALF,
    _E_K1,
    _E_K2,
    _E_KC_KP,
    _E_PC,
    _E_PC_EPS,
    _E_PC_SHAPE,
    _E_PULS,
    _E_SF_C,
    _E_SF_EPS,
    _E_SF_S,
    _E_SF_SHAPE,
    _E_SF_VS,
    _E_SOLVE_TOL,
    _E_VISC,
    _FAST,
    _solve_friction,
)

#: Probed cases: (load, rig effects in the record, effect parameters in the lanes' vector).
CASES: dict[str, tuple[str, tuple[str, ...], dict[str, float]]] = {
    "linear": ("conrod_fixed", (), {}),
    "conrod": ("conrod_fixed", ("pump_coulomb_friction", "pump_pulsation"),
               {"pc_force_n": 40.0, "puls1_flow_s": 0.02, "puls1_torque_c": 3.0,
                "puls2_flow_c": 0.01, "puls4_torque_s": 1.0}),
    "free": ("free_piston", ("pump_coulomb_friction", "seal_friction"),
             {"pc_force_n": 40.0, "sf_coulomb_n": 20.0, "sf_static_n": 35.0}),
}
#: Parameters a lane moves, in turn (a Jacobian's columns: the linear part, the input's
#: timing and gain, the effects' levels); those a case's model lacks are moved from zero.
MOVED = ("gain_n_per_a", "ds", "dp", "dc", "ks", "k_rod", "c_rod", "jp", "jc", "skew_s",
         "pc_force_n", "sf_coulomb_n", "sf_static_n", "puls1_flow_s", "delay_s")


@njit(cache=True, nogil=True, fastmath=_FAST)
def _simulate_batch(ad, bd, z0, taus, tau_of, ks_l, ds_l, dp_l, dc_l, eff, angle, has_angle,
                    xs, has_x, temp, has_temp, t_ref, n_sub, fixed, out, adh, bdh):
    """``_simulate`` of every lane ``l`` (``ad[l]``, ``bd[l]``, ``z0[l]``,
    ``taus[tau_of[l]]``, ``ks_l[l]`` ... ``eff[l]``, ``adh[l]``, ``bdh[l]``) into
    ``out[l]``, the lanes taking turns inside every sub-step."""
    n_lanes = out.shape[0]
    n = out.shape[1]
    ns = 3 if fixed else 5
    z = z0.copy()
    zn = np.zeros((n_lanes, 5))
    u = np.zeros((n_lanes, 4))
    n_ord = np.zeros(n_lanes, np.int64)
    sf_on = np.zeros(n_lanes, np.bool_)
    ksx_on = np.zeros(n_lanes, np.bool_)
    inputs_on = np.zeros(n_lanes, np.bool_)
    offset = np.zeros(n_lanes)
    fp = np.zeros(n_lanes)
    fs = np.zeros(n_lanes)
    fp_prev = np.zeros(n_lanes)
    fs_prev = np.zeros(n_lanes)
    r_l = np.ones(n_lanes)
    for ln in range(n_lanes):
        for m in range(8):
            for i in range(4):
                if eff[ln, _E_PULS + 4 * m + i] != 0.0:
                    n_ord[ln] = m + 1
        sf_on[ln] = (eff[ln, _E_SF_C] != 0.0 or eff[ln, _E_SF_S] != 0.0) and not fixed
        ksx_on[ln] = eff[ln, _E_K1] != 0.0 or eff[ln, _E_K2] != 0.0
        inputs_on[ln] = n_ord[ln] > 0 or ksx_on[ln] or (eff[ln, _E_VISC] != 0.0 and has_temp)
        offset[ln] = angle[0] - z[ln, 0] * eff[ln, _E_KC_KP] if has_angle else 0.0
    for k in range(n):
        for ln in range(n_lanes):
            for i in range(5):
                out[ln, k, i] = z[ln, i]
        if k == n - 1:
            break
        for ln in range(n_lanes):
            visc = eff[ln, _E_VISC]
            r = 1.0
            if visc != 0.0 and has_temp:
                r = math.exp(-visc * (temp[k] - t_ref))
            r_l[ln] = r
        for j in range(n_sub):
            for ln in range(n_lanes):
                ks = ks_l[ln]
                ds = ds_l[ln]
                r = r_l[ln]
                kx = ksx_on[ln]
                pc = eff[ln, _E_PC]
                vp = z[ln, 1]
                tq = z[ln, 2]
                vc = z[ln, 4]
                f_pump = 0.0
                f_pist = 0.0
                g = 1.0
                if n_ord[ln] > 0:
                    th = ((z[ln, 0] + 0.5 * eff[ln, _E_H_SUB] * vp) * eff[ln, _E_KC_KP]
                          + offset[ln])
                    s1 = math.sin(th)
                    c1 = math.cos(th)
                    s = s1
                    c = c1
                    ripple = 0.0
                    torque = 0.0
                    for m in range(n_ord[ln]):
                        base = _E_PULS + 4 * m
                        ripple += eff[ln, base] * s + eff[ln, base + 1] * c
                        torque += eff[ln, base + 2] * s + eff[ln, base + 3] * c
                        s, c = s * c1 + c * s1, c * c1 - s * s1
                    g = 1.0 + ripple
                    f_pump -= ripple * tq + torque
                if r != 1.0:
                    f_pump -= dp_l[ln] * (r - 1.0) * vp
                    f_pist -= dc_l[ln] * (r - 1.0) * vc
                ks_eff = ks
                if kx or g != 1.0 or r != 1.0:
                    if kx:
                        xpos = xs[k] if has_x else z[ln, 3]
                        xn = xpos / eff[ln, _E_HALF]
                        ks_eff = ks / max(1.0 + eff[ln, _E_K1] * xn + eff[ln, _E_K2] * xn * xn,
                                          0.05)
                    q_rate = ks_eff * (g * vp - tq / (ds * r) - vc) - ks * (vp - tq / ds - vc)
                else:
                    q_rate = 0.0
                u[ln, 0] = taus[tau_of[ln], k * n_sub + j]
                u[ln, 1] = f_pump
                u[ln, 2] = q_rate
                u[ln, 3] = f_pist
                for i in range(ns):
                    acc = 0.0
                    for m in range(ns):
                        acc += ad[ln, i, m] * z[ln, m]
                    acc += bd[ln, i, 0] * u[ln, 0]
                    if inputs_on[ln]:
                        for m in range(1, 4):
                            acc += bd[ln, i, m] * u[ln, m]
                    zn[ln, i] = acc
                dq = 0.0
                if kx:
                    q_end = (ks_eff * (g * zn[ln, 1] - zn[ln, 2] / (ds * r) - zn[ln, 4])
                             - ks * (zn[ln, 1] - zn[ln, 2] / ds - zn[ln, 4]))
                    dq = 0.5 * (q_end - q_rate)
                    for i in range(ns):
                        zn[ln, i] += bd[ln, i, 2] * dq
                if pc != 0.0:
                    f_start = 2.0 * fp[ln] - fp_prev[ln]
                    fp_prev[ln] = fp[ln]
                    _, f = _solve_friction(zn[ln, 1], bd[ln, 1, 1], pc, pc, 0.0,
                                           eff[ln, _E_PC_EPS], eff[ln, _E_PC_SHAPE], f_start,
                                           eff[ln, _E_SOLVE_TOL])
                    fp[ln] = f
                    for i in range(ns):
                        zn[ln, i] -= bd[ln, i, 1] * f
                if sf_on[ln]:
                    vmid = -bdh[ln, 4, 1] * fp[ln]
                    for m in range(ns):
                        vmid += adh[ln, 4, m] * z[ln, m]
                    vmid += bdh[ln, 4, 0] * u[ln, 0]
                    if inputs_on[ln]:
                        for m in range(1, 4):
                            vmid += bdh[ln, 4, m] * u[ln, m]
                    if kx:
                        vmid += bdh[ln, 4, 2] * 0.5 * dq
                    f_start = 2.0 * fs[ln] - fs_prev[ln]
                    fs_prev[ln] = fs[ln]
                    _, f = _solve_friction(vmid, bdh[ln, 4, 3], eff[ln, _E_SF_C],
                                           eff[ln, _E_SF_S], eff[ln, _E_SF_VS],
                                           eff[ln, _E_SF_EPS], eff[ln, _E_SF_SHAPE], f_start,
                                           eff[ln, _E_SOLVE_TOL])
                    fs[ln] = f
                    for i in range(ns):
                        zn[ln, i] -= bd[ln, i, 3] * f
                for i in range(ns):
                    z[ln, i] = zn[ln, i]
        if has_angle:
            for ln in range(n_lanes):
                offset[ln] += eff[ln, _E_ALPHA] * (angle[k + 1] - z[ln, 0] * eff[ln, _E_KC_KP]
                                                   - offset[ln])


def kernel_args(model: fast.FastModel, theta: np.ndarray, n_stop: int | None) -> tuple:
    """The arguments ``model`` hands ``_simulate`` for ``theta`` (the kernel stood in for
    by a recorder for one call; the output array is the run's ``n_stop`` head)."""
    got: list[tuple] = []
    kernel = fast._simulate
    fast._simulate = lambda *a: got.append(a)
    try:
        model._simulate_states(theta, n_stop)
    finally:
        fast._simulate = kernel
    return got[0]


def lane_vectors(base: np.ndarray, lanes: int) -> list[np.ndarray]:
    """``base`` and ``lanes - 1`` vectors each moving one parameter of :data:`MOVED` by a
    forward-difference step (a skew or delay by microseconds), in turn."""
    out = [base]
    for i in range(lanes - 1):
        name = MOVED[i % len(MOVED)]
        theta = base.copy()
        j = fast.IDX[name]
        size = 1 + i // len(MOVED)
        if name in ("skew_s", "delay_s"):
            theta[j] += 3e-6 * size
        elif theta[j] != 0.0:
            theta[j] *= 1.0 + 1e-6 * size
        else:
            theta[j] = 1e-6 * size
        out.append(theta)
    return out


def probe(case: str, lanes: list[int], samples: int | None, reps: int,
          seconds: float = 16.0, seed: int = 3) -> list[dict]:
    """CPU of ``L`` single kernel calls against one batched call, and the bits, per ``L``."""
    from hil.identify.experiment import prepare
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    load, effects, params = CASES[case]
    rig = generate_rig(load, list(effects), seconds=seconds, seed=seed)
    model = fast.FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))
    base = model.start_vector()
    for name, value in params.items():
        base[fast.IDX[name]] = value
    rows = []
    for n_lanes in lanes:
        args = [kernel_args(model, t, samples) for t in lane_vectors(base, n_lanes)]
        forces: list[np.ndarray] = []
        tau_of = []
        for a in args:  # the applied forces the lanes share, stacked once
            same = [i for i, f in enumerate(forces) if f is a[3]]
            if not same:
                forces.append(a[3])
            tau_of.append(same[0] if same else len(forces) - 1)
        taus = np.stack(forces)
        lane_of = np.array(tau_of, dtype=np.int64)

        def stacked(i: int, args: list[tuple] = args) -> np.ndarray:
            return np.stack([a[i] for a in args])

        per_lane = [stacked(i) for i in (0, 1, 2)] + [np.array([a[i] for a in args])
                                                      for i in (4, 5, 6, 7)]
        eff, adh, bdh = stacked(8), stacked(19), stacked(20)
        common = args[0][9:18]
        shape = args[0][18].shape

        def single(args: list[tuple] = args, shape: tuple = shape) -> list[np.ndarray]:
            outs = []
            for a in args:
                o = np.zeros(shape)
                fast._simulate(*a[:18], o, a[19], a[20])
                outs.append(o)
            return outs

        def batched(n_lanes: int = n_lanes, per_lane: list = per_lane, taus: np.ndarray = taus,
                    lane_of: np.ndarray = lane_of, eff: np.ndarray = eff,
                    adh: np.ndarray = adh, bdh: np.ndarray = bdh, shape: tuple = shape,
                    common: tuple = common) -> np.ndarray:
            o = np.zeros((n_lanes, *shape))
            ad, bd, z0, ks, ds, dp, dc = per_lane
            _simulate_batch(ad, bd, z0, taus, lane_of, ks, ds, dp, dc, eff, *common, o, adh,
                            bdh)
            return o

        one, many = single(), batched()  # (compiles the batch kernel once)
        same_bits = [bool(np.array_equal(one[i].view(np.int64), many[i].view(np.int64)))
                     for i in range(n_lanes)]
        scale = [np.max(np.abs(o), axis=0) for o in one]
        rel = max(float(np.max(np.abs(many[i] - one[i]) / np.where(scale[i] > 0, scale[i], 1.0)))
                  for i in range(n_lanes))
        t_single, t_batch = [], []
        for _ in range(reps):
            c = time.process_time()
            single()
            t_single.append(time.process_time() - c)
            c = time.process_time()
            batched()
            t_batch.append(time.process_time() - c)
        s, b = float(np.median(t_single)), float(np.median(t_batch))
        rows.append({"case": case, "load": load, "lanes": n_lanes, "samples": shape[0],
                     "single_cpu_ms": 1e3 * s, "batch_cpu_ms": 1e3 * b, "speedup": s / b,
                     "lanes_same_bits": sum(same_bits), "max_rel_diff": rel})
    return rows


def jacobian_split(case: str, reps: int, seconds: float = 16.0, seed: int = 3) -> dict:
    """CPU of one forward-difference Jacobian of ``case``'s record at the fits' iteration
    head (the baseline's free parameters and the case's effect parameters, the sensors'
    lags on, one thread), split into the simulation kernel, the sensor lags' transforms,
    the rest of the outputs and the stacked residuals, the input's band-limiting (a skew
    column's) and the transposing copy: ``{"columns", "rows", "cpu_ms", part: ms}``."""
    from hil.identify import fit
    from hil.identify.experiment import prepare
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    load, effects, params = CASES[case]
    rig = generate_rig(load, list(effects), seconds=seconds, seed=seed)
    exp = prepare(rig.data, load_config("hydra_default"), "bl")
    model = fast.FastModel(exp)
    theta = model.start_vector()
    for name, value in {**params, "lag_pressure_s": 1e-4, "lag_strain_s": 1.2e-4}.items():
        theta[fast.IDX[name]] = value
    free = fit.baseline_free(exp) + list(params)
    fitter = fit.OutputErrorFit(model, fit.NUISANCE_SCALES(exp.dt))
    fitter._ref = {n: theta[fast.IDX[n]] for n in free if n in fit.LOG_PARAMS}
    mask = fitter.fit_mask()
    mask[np.flatnonzero(mask)[fit.ITERATION_SAMPLES]:] = False
    sigma = {c: float(np.nanstd(exp.measured[c])) or 1.0 for c in exp.channels}
    fun, jac = fitter._problem(free, theta, sigma, mask)
    x = fitter._to_x(theta, free)
    spent = {"kernel": 0.0, "sensor lags": 0.0, "outputs": 0.0, "residuals": 0.0,
             "applied input": 0.0, "transposing copy": 0.0}
    wrapped = [(fast, "_simulate", "kernel"), (fast, "sensor_lags", "sensor lags"),
               (fast.FastModel, "outputs", "outputs"), (fit.OutputErrorFit, "_stack",
                                                        "residuals"),
               (fast.FastModel, "applied_current", "applied input"),
               (fit.np, "ascontiguousarray", "transposing copy")]
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in wrapped]

    def timed(fn, part):  # noqa: ANN001, ANN202 - any callable
        def call(*a, **k):  # noqa: ANN002, ANN003, ANN202
            c = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                spent[part] += time.process_time() - c
        return call

    threads = fast._WORKERS
    fast.set_threads(1)
    try:
        for (owner, name, part), (_, _, fn) in zip(wrapped, saved, strict=True):
            setattr(owner, name, timed(fn, part))
        fun(x)
        for part in spent:
            spent[part] = 0.0
        c = time.process_time()
        for _ in range(reps):
            model._runs.clear()
            j = jac(x)
        total = time.process_time() - c
    finally:
        for owner, name, fn in saved:
            setattr(owner, name, fn)
        fast.set_threads(threads)
    ms = {k: 1e3 * v / reps for k, v in spent.items()}
    # nested parts: the residuals hold the outputs, the outputs the lags
    ms["residuals"] -= ms["outputs"]
    ms["outputs"] -= ms["sensor lags"]
    return {"case": case, "columns": len(free), "rows": j.shape[0],
            "cpu_ms": 1e3 * total / reps, **ms}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.bench.identify_batch",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", action="append", choices=tuple(CASES), default=None)
    parser.add_argument("--lanes", default="2,4,8,13",
                        help="lane counts, comma-separated (default 2,4,8,13)")
    parser.add_argument("--samples", type=int, default=30_000,
                        help="samples simulated (the fits' head; 0: the whole record)")
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--split", action="store_true",
                        help="instead: where one Jacobian's CPU goes, per case")
    parser.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args(argv)
    try:
        lanes = [int(x) for x in args.lanes.split(",")]
    except ValueError:
        parser.error(f"--lanes {args.lanes}: comma-separated whole numbers")
    if min(lanes) < 1 or args.reps < 1 or args.samples < 0:
        parser.error("--lanes, --reps need at least 1, --samples at least 0")
    rows = []
    if args.split:
        for case in args.case or list(CASES):
            rows.append(jacobian_split(case, args.reps))
            if not args.json:
                r = rows[-1]
                parts = ", ".join(f"{k} {r[k]:.0f}" for k in r if k not in (
                    "case", "columns", "rows", "cpu_ms"))
                print(f"{case:6s} Jacobian of {r['columns']} columns x {r['rows']} rows: "
                      f"CPU {r['cpu_ms']:.0f} ms; {parts} ms", flush=True)
        if args.json:
            print(json.dumps(rows, indent=1))
        return 0
    for case in args.case or list(CASES):
        rows += probe(case, lanes, args.samples or None, args.reps)
        if not args.json:
            for r in rows[-len(lanes):]:
                print(f"{r['case']:6s} {r['lanes']:2d} lanes, {r['samples']} samples: "
                      f"single {r['single_cpu_ms']:7.1f} ms, batched {r['batch_cpu_ms']:7.1f} "
                      f"ms CPU (x{r['speedup']:.2f}); lanes with the same bits "
                      f"{r['lanes_same_bits']}/{r['lanes']}, largest relative difference "
                      f"{r['max_rel_diff']:.1e}", flush=True)
    if args.json:
        print(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
