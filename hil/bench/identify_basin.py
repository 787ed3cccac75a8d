"""Is a wrong identification the search's fault or the model's? The loop's fit against a
refit of the same model from the independent rig's truth.

``eha-hil identify-check`` says a row is wrong; it does not say why. Two causes look alike
in the report (``unexplained``, a residual with structure): the model cannot represent the
record (a missing effect, a wrong law), or it can and the loop's search stopped in another
local minimum. This tool tells them apart on a rig record, whose truth is known:

1. run the loop's forward steps (:meth:`hil.identify.pipeline._Loop.forward`, the effects
   added one at a time) as ``identify`` does, on one BLAS thread;
2. put the rig's truth into the loop's parameter vector (:func:`truth_vector`: the linear
   parameters, the frictions' levels and regularisation velocities in the fit's units) and
   refit from there with the loop's free parameters;
3. print both fits' estimation cost (the loop's weights), validation cost and the structure
   the report's judge finds in each, and the estimation cost on the straight line between
   them (:func:`line_costs`): a ridge on it is two basins.

The truth's refit lower and explained is a search failure (docs/identify.md, "The conrod's
two frictions"); the truth's refit leaving the same structure is the model's.

Run: ``python -m hil.bench.identify_basin --load conrod_fixed --effect pump_coulomb_friction
--effect seal_friction --seed 1`` (6 s records, as ``identify-check``; ``--seconds 16 --seed
3`` is the CPU bench's record).

Where the loop's fit is reached only by the joint search (the free piston's two frictions
under the multisine: neither passes alone), ``--through joint`` runs the loop to the end of
:meth:`~hil.identify.pipeline._Loop.joint`. ``--free NAME`` frees more parameters in both
refits (``jc`` held since the baseline, the seal's ``sf_eps_m_per_s`` from the preset);
``--truth linear`` or ``--truth frictions`` puts only that part of the truth into the
start, the rest as the loop's fit has it (:func:`partial_truth`): which part of the start
decides the basin.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Mapping

import numpy as np

#: The rig's sign law is ``(2/pi) atan(v/eps)`` (slope 2/(pi eps) at zero), the fit's atan
#: law ``(2/pi) atan(pi u/2)`` with ``u = v/eps`` (slope 1/eps): the same curve at the fit's
#: ``eps`` = the rig's x pi/2.
ATAN_EPS = math.pi / 2
#: The rig's drawn linear parameters the fit has under the same names.
LINEAR = ("gain_n_per_a", "ds", "dp", "dc", "ks", "jp", "jc", "k_rod", "c_rod")


def truth_vector(theta: np.ndarray, idx: Mapping[str, int],
                 truth: Mapping[str, Mapping]) -> tuple[np.ndarray, list[str]]:
    """``theta`` with the rig's ``truth`` (``RigResult.truth``) put in, in the fit's units:
    the linear parameters, the pump friction's and the seal's levels, Stribeck and
    regularisation velocities (the atan law's, :data:`ATAN_EPS`), their shapes at the atan
    end. Returns the vector and the names set; the rest (pulsation, offsets, lags, skew)
    stay as in ``theta``."""
    th = np.array(theta, dtype=float)
    names: list[str] = []

    def put(name: str, value: float) -> None:
        th[idx[name]] = value
        names.append(name)

    for name in LINEAR:
        if name in truth["parameters"]:
            put(name, float(truth["parameters"][name]))
    eff = truth["effects"]
    if "pump_coulomb_friction" in eff:
        pc = eff["pump_coulomb_friction"]
        put("pc_force_n", pc["force_n"])
        put("pc_eps_m_per_s", pc["eps_m_per_s"] * ATAN_EPS)
        put("pc_shape", 1.0)
    if "seal_friction" in eff:
        sf = eff["seal_friction"]
        put("sf_coulomb_n", sf["coulomb_n"])
        put("sf_static_n", sf["static_n"])
        put("sf_vs_m_per_s", sf["stribeck_m_per_s"])
        put("sf_eps_m_per_s", sf["eps_m_per_s"] * ATAN_EPS)
        put("sf_shape", 1.0)
    return th, names


#: Parameters printed for each fit (those it has free): where two basins differ.
SHOWN = ("gain_n_per_a", "ks", "jp", "jc", "lag_pressure_s", "pc_force_n", "pc_shape",
         "sf_coulomb_n", "sf_static_n", "sf_eps_m_per_s", "sf_shape")
#: The groups of :func:`truth_vector`'s names that ``--truth`` can put in alone: the
#: frictions' levels, velocities and shapes, and the linear parameters.
FRICTION_PREFIXES = ("pc_", "sf_")


def partial_truth(theta: np.ndarray, truth_theta: np.ndarray, names: list[str],
                  idx: Mapping[str, int], group: str) -> tuple[np.ndarray, list[str]]:
    """``theta`` with the entries of ``names`` (set by :func:`truth_vector` in
    ``truth_theta``) of one ``group`` taken from ``truth_theta``: ``all``, ``frictions``
    (the names with a :data:`FRICTION_PREFIXES` prefix) or ``linear`` (the others).
    Returns the vector and the names put in."""
    if group not in ("all", "frictions", "linear"):
        raise ValueError(f"truth group {group!r}: all, frictions or linear")
    put = [n for n in names if group == "all"
           or (n.startswith(FRICTION_PREFIXES) == (group == "frictions"))]
    th = np.array(theta, dtype=float)
    for n in put:
        th[idx[n]] = truth_theta[idx[n]]
    return th, put


def line_costs(cost: Callable[[np.ndarray], float], a: np.ndarray, b: np.ndarray,
               log_idx: set[int], points: int = 11) -> list[float]:
    """``cost`` at ``points`` evenly spaced points from ``a`` to ``b``; the entries of
    ``log_idx`` (the fit's log-parameters, both ends positive) move geometrically, as the
    fit moves them."""
    out = []
    for s in np.linspace(0.0, 1.0, points):
        th = a + s * (b - a)
        for i in log_idx:
            if a[i] > 0 and b[i] > 0:
                th[i] = a[i] * (b[i] / a[i]) ** s
        out.append(float(cost(th)))
    return out


def diagnosis(cost_loop: float, cost_truth: float, residual_at_truth: bool,
              disagree_at_truth: bool) -> str:
    """What the two fits say: the search's fault where the truth's basin is lower (and
    what the judge still finds there, which the search could not have fixed), the model's
    where the truth's refit is no lower."""
    if not cost_truth < cost_loop:
        return "the model: the refit from the truth ends no lower than the loop's fit"
    left = [w for w, on in (("residual structure", residual_at_truth),
                            ("parameters disagreeing", disagree_at_truth)) if on]
    return (f"the search: the truth's basin is {cost_loop / cost_truth:.2f}x lower"
            + (f"; it still leaves {' and '.join(left)}" if left else ", and explained"))


def main(argv: list[str] | None = None) -> int:
    from threadpoolctl import threadpool_limits

    from hil.identify.fit import LOG_PARAMS, NUISANCE_SCALES, OutputErrorFit, guarded_fit
    from hil.identify.model import IDX
    from hil.identify.pipeline import _all_scales, _Loop, _val_cost
    from hil.identify.rig import generate_rig
    from plant.config import load_config

    ap = argparse.ArgumentParser(prog="python -m hil.bench.identify_basin",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--load", default="conrod_fixed")
    ap.add_argument("--effect", action="append", default=[])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--profile", default="multisine")
    ap.add_argument("--through", default="forward", choices=("forward", "joint"),
                    help="the loop's steps run before the comparison (joint: forward, the "
                    "shrunk effects dropped, the joint search)")
    ap.add_argument("--free", action="append", default=[],
                    help="a parameter freed in both refits besides the loop's (repeatable)")
    ap.add_argument("--truth", default="all", choices=("all", "frictions", "linear"),
                    help="the part of the truth put into the second refit's start")
    args = ap.parse_args(argv)
    cfg = load_config("hydra_default")
    rig = generate_rig(args.load, args.effect, seconds=args.seconds, seed=args.seed,
                       profile=args.profile)
    c0 = time.process_time()
    with threadpool_limits(limits=1, user_api="blas"):
        loop = _Loop(rig.data, cfg, lambda msg: None, None)
        loop.forward(6)
        if args.through == "joint":
            loop.drop_shrunk()
            loop.joint(6)
        found = loop.current
        fitter = OutputErrorFit(loop.model, {**NUISANCE_SCALES(loop.exp.dt),
                                             **_all_scales(loop.defs_all)})
        free = list(found.free) + [n for n in args.free if n not in found.free]
        base = found.theta.copy()
        for n in args.free:
            if n == "sf_eps_m_per_s" and not base[IDX[n]]:
                base[IDX[n]] = loop.exp.const.eps_seal  # 0 stands for the preset's
        whole, names = truth_vector(base, IDX, rig.truth)
        start, names = partial_truth(base, whole, names, IDX, args.truth)
        if args.free:
            found, _ = guarded_fit(fitter, base, free, base, sigma=found.sigma,
                                   configured=loop.configured)
        truth, held = guarded_fit(fitter, start, free, start, sigma=found.sigma,
                                  configured=loop.configured)
        rows = []
        first = "the loop's fit" + (f", {', '.join(args.free)} freed" if args.free else "")
        second = ("refit from the rig's truth"
                  + ("" if args.truth == "all" else f" ({args.truth} only)"))
        for label, fit in ((first, found), (second, truth)):
            loop.current = fit
            residual, disagree = loop.structure()
            rows.append((label, fitter.cost(fit.theta, found.sigma),
                         _val_cost(loop.exp, fit.outputs, loop.sigma_ref),
                         residual or "none", disagree or "none",
                         ", ".join(f"{n} {fit.value(n):.4g}" for n in SHOWN
                                   if n in fit.free)))
        line = line_costs(lambda th: fitter.cost(th, found.sigma), found.theta, truth.theta,
                          {IDX[n] for n in LOG_PARAMS})
    print(f"{args.load} {' + '.join(args.effect) or 'null'}, seed {args.seed}, "
          f"{args.seconds:g} s; effects added: {', '.join(sorted(loop.added_labels)) or 'none'}")
    print(f"truth put in: {', '.join(names)}; held in the truth's refit: {held or 'none'}")
    print("| fit | estimation cost | validation cost | residual structure | parameters "
          "disagreeing |\n|---|---|---|---|---|")
    for label, est, val, left, disagree, _ in rows:
        print(f"| {label} | {est:.6g} | {val:.6g} | {left} | {disagree} |")
    for label, *_, values in rows:
        print(f"{label}: {values}")
    print("estimation cost on the line from the loop's fit to the truth's refit: "
          + ", ".join(f"{c:.4g}" for c in line))
    print("diagnosis: " + diagnosis(rows[0][1], rows[1][1], rows[1][3] != "none",
                                    rows[1][4] != "none"))
    print(f"CPU {time.process_time() - c0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
