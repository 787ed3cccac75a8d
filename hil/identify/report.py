"""What ``eha-hil identify`` prints and writes: text tables, the JSON summary, plots.

* :func:`summary` — the machine-readable summary (``--json``): ``effects_added``,
  ``candidates`` (statistic, p-values, selected), ``channels`` (``nrmse_before``,
  ``nrmse_after``, fit %), ``residual_white_before``, ``residual_white_after``,
  ``unexplained`` and its detail, the baseline and final linear parameters with CIs;
* :func:`text` — the same as tables for people;
* :func:`write_report` — ``--report DIR``: the tables as CSV, ``summary.json``, and plots
  (residual against rotor angle, pump velocity and time; order spectrum; autocorrelation;
  measured / before / after overlays of every channel).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from hil.identify.pipeline import IdentifyReport
from hil.output.tables import table


def _f(x: float) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def summary(rep: IdentifyReport) -> dict:
    """The ``--json`` summary (plain types only)."""
    return {
        "file": rep.path,
        "load": rep.load,
        "samples": rep.n_samples,
        "sample_rate_hz": rep.sample_rate_hz,
        "baseline": {k: v.as_dict() for k, v in rep.baseline.items()},
        "final": {k: v.as_dict() for k, v in rep.final.items()},
        "held_at_preset": rep.held,
        "effects_added": [e.as_dict() for e in rep.effects_added],
        "candidates": [{k: (_f(v) if isinstance(v, float) else v) for k, v in row.items()}
                       for row in rep.candidate_table()],
        "channels": [{"channel": c.channel, "nrmse_before": c.nrmse_before,
                      "nrmse_after": c.nrmse_after, "fit_percent_before": c.fit_before,
                      "fit_percent_after": c.fit_after} for c in rep.channels],
        "residual_white_before": rep.residual_before.white,
        "residual_white_after": rep.residual_after.white,
        "residual_before": rep.residual_before.summary(),
        "residual_after": rep.residual_after.summary(),
        "unexplained": rep.unexplained,
        "unexplained_detail": rep.unexplained_detail,
        "consistency": rep.consistency.as_dict() if rep.consistency is not None else None,
        "differs_from_configuration": rep.differs,
        "intersample": {"mode": rep.intersample, "reason": rep.intersample_reason},
        "input_noise": rep.input_noise.as_dict() if rep.input_noise is not None else None,
        "refused": None,
        "rejected": rep.rejected,
        "tried_together": rep.joint,
        "joint_search": rep.joint_why,
        "refitted_from_configuration": rep.restarts,
        "notes": rep.notes,
        "wall_s": rep.wall_s,
    }


def _json_default(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj).__name__)


def to_json(rep: IdentifyReport) -> str:
    return json.dumps(summary(rep), indent=2, default=_json_default)


def text(rep: IdentifyReport) -> str:
    """Tables for the terminal."""
    out = [f"identify {rep.path}: load {rep.load}, {rep.n_samples} samples at "
           f"{rep.sample_rate_hz:g} Hz ({rep.wall_s:.1f} s)"]
    rows = []
    for k, v in rep.baseline.items():
        f = rep.final[k]
        rows.append([k, v.value, f"[{v.ci_low:.4g}, {v.ci_high:.4g}]", f.value,
                     f"[{f.ci_low:.4g}, {f.ci_high:.4g}]", v.unit])
    out.append(table(["parameter", "baseline", "95 % CI", "final", "95 % CI", "unit"], rows,
                     title="\nlinear model (thesis ch. 2), output-error fit"))
    for k, why in rep.held.items():
        out.append(f"  {k}: {why}")
    rows = []
    for row in rep.candidate_table():
        rows.append([row["label"], row["status"], row["statistic"], row["dof"],
                     row["p_holm"], row["share_val"], "yes" if row["selected"] else "",
                     row["reason"][:60]])
    rows.sort(key=lambda r: -r[2])
    out.append(table(["candidate", "status", "Wald", "dof", "p (Holm)", "share val", "added",
                      "reason"], rows, title="\ncandidates (HAC Wald test, Holm-corrected)"))
    if rep.effects_added:
        rows = []
        for e in rep.effects_added:
            for name, p in e.params.items():
                rows.append([e.label, name, p.value, f"[{p.ci_low:.4g}, {p.ci_high:.4g}]",
                             p.unit])
        out.append(table(["effect added", "parameter", "value", "95 % CI", "unit"], rows,
                         title="\neffects added"))
    else:
        out.append("\neffects added: none")
    for r in rep.rejected:
        out.append(f"  rejected: {r}")
    if rep.joint_why:
        out.append(f"  joint search: {rep.joint_why}")
    for j in rep.joint:
        change = j["validation_cost_change"]
        cost = "" if change is None else f"validation cost {change:+.1%}, "
        out.append(f"  tried together: {' + '.join(j['effects'])}: {cost}{j['outcome']}")
    for r in rep.restarts:
        start = r.get("from") or f"the configured {', '.join(r['from_configured'])}"
        out.append(f"  refitted from {start}: "
                   f"validation cost {r['validation_cost_change']:+.1%}, {r['outcome']}")
    rows = []
    b, a = rep.residual_before.channels, rep.residual_after.channels
    for c in rep.channels:
        rows.append([c.channel, c.nrmse_before, c.nrmse_after, c.fit_before, c.fit_after,
                     "white" if b[c.channel].white else "structure",
                     "white" if a[c.channel].white else "structure"])
    out.append(table(["channel", "NRMSE before", "NRMSE after", "fit % before", "fit % after",
                      "residual before", "after"], rows,
                     title="\nvalidation part (held out)"))
    out.append(f"\ninput between samples: {rep.intersample} ({rep.intersample_reason})")
    if rep.input_noise is not None:
        out.append(f"noise on the logged current: {rep.input_noise.rms_a:.4g} A rms "
                   "(accounted for in the residual tests)")
    out.append(f"\nresidual white: before {rep.residual_before.white}, "
               f"after {rep.residual_after.white}")
    out += _consistency_lines(rep)
    if rep.unexplained:
        out.append(f"verdict: unexplained - {rep.unexplained_detail}")
    elif rep.effects_added:
        out.append("verdict: explained - the residual holds no material structure left")
    else:
        out.append("verdict: the linear model explains the data; nothing added")
    for n in rep.notes:
        out.append(f"note: {n}")
    return "\n".join(out)


def _consistency_lines(rep: IdentifyReport) -> list[str]:
    """The parameters refitted on parts of the record (the disagreeing ones, else how many
    agree), and the ones that differ from the configuration."""
    from hil.identify.consistency import MATERIAL_RATIO, MATERIAL_RATIO_CHANNELS
    from hil.identify.pipeline import BASELINE_LABELS

    out = []
    c = rep.consistency
    if c is not None and c.splits:
        bad = c.inconsistent
        if bad:
            out.append("\nparameters that disagree between parts of the record:")
            out += [f"  {s.split}: {s.describe(BASELINE_LABELS[s.name][0])}" for s in bad]
        else:
            splits = sorted({s.split for s in c.splits})
            out.append(f"\nparameters agree across {', '.join(splits)} "
                       f"({len(c.splits)} tests: none apart beyond the intervals by "
                       f"{MATERIAL_RATIO - 1:.0%}, channel groups "
                       f"{MATERIAL_RATIO_CHANNELS - 1:.0%})")
    for sym, d in rep.differs.items():
        lo, hi = d["ci95"]
        out.append(f"differs from the configuration: {sym} {d['value']:.4g} [{lo:.4g}, "
                   f"{hi:.4g}] {d['unit']}, {d['ratio']:.2f}x the configured "
                   f"{d['configured']:.4g} (by itself no sign of a missing effect)")
    return out


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def write_report(rep: IdentifyReport, directory: str | Path) -> list[Path]:
    """Write tables (CSV), ``summary.json`` and plots into ``directory``; return the files."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    files = []
    p = d / "summary.json"
    p.write_text(to_json(rep), encoding="utf-8")
    files.append(p)
    p = d / "channels.csv"
    _write_csv(p, ["channel", "nrmse_before", "nrmse_after", "fit_before", "fit_after"],
               [[c.channel, c.nrmse_before, c.nrmse_after, c.fit_before, c.fit_after]
                for c in rep.channels])
    files.append(p)
    rows = rep.candidate_table()
    p = d / "candidates.csv"
    keys = list(rows[0]) if rows else ["label"]
    _write_csv(p, keys, [[r[k] for k in keys] for r in rows])
    files.append(p)
    p = d / "effects.csv"
    _write_csv(p, ["effect", "parameter", "value", "ci_low", "ci_high", "unit"],
               [[e.label, n, v.value, v.ci_low, v.ci_high, v.unit]
                for e in rep.effects_added for n, v in e.params.items()])
    files.append(p)
    files += _plots(rep, d)
    return files


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plots(rep: IdentifyReport, d: Path) -> list[Path]:
    exp = rep.experiment
    if exp is None:
        return []
    plt = _pyplot()
    files = []
    val = exp.val
    t = exp.data.t
    chans = exp.channels
    # before/after overlays
    fig, axes = plt.subplots(len(chans), 1, figsize=(10, 2.2 * len(chans)), sharex=True)
    axes = np.atleast_1d(axes)
    sel = np.flatnonzero(val)[:2500]
    for ax, c in zip(axes, chans, strict=True):
        ax.plot(t[sel], exp.measured[c][sel], "k", lw=0.8, label="measured")
        ax.plot(t[sel], rep.outputs_before[c][sel], "C1", lw=0.8, label="linear model")
        ax.plot(t[sel], rep.outputs_after[c][sel], "C0--", lw=0.8, label="with effects")
        ax.set_ylabel(c)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t [s] (validation part)")
    fig.tight_layout()
    files.append(_save(fig, d / "overlay.png", plt))
    # residual against time, rotor angle, pump velocity
    for tag, ana, out in (("before", rep.residual_before, rep.outputs_before),
                          ("after", rep.residual_after, rep.outputs_after)):
        fig, axes = plt.subplots(len(chans), 3, figsize=(13, 2.2 * len(chans)))
        axes = np.atleast_2d(axes)
        for i, c in enumerate(chans):
            r = (exp.measured[c] - out[c])[val]
            axes[i, 0].plot(t[val], r, lw=0.4)
            axes[i, 0].set_ylabel(c)
            if exp.angle is not None:
                axes[i, 1].plot(np.mod(exp.angle[val], 2 * np.pi), r, ",", alpha=0.4)
            vs = ana.channels[c].vs_state.get("pump_velocity")
            if "omega_m" in exp.measured:
                v = exp.measured["omega_m"][val] / exp.const.rotor_per_m
                axes[i, 2].plot(v, r, ",", alpha=0.4)
                if vs and vs["centres"]:
                    axes[i, 2].plot(vs["centres"], vs["mean"], "r.-")
        axes[-1, 0].set_xlabel("t [s]")
        axes[-1, 1].set_xlabel("rotor angle mod 2 pi [rad]")
        axes[-1, 2].set_xlabel("pump velocity [m/s]")
        fig.suptitle(f"residual {tag} (validation part)")
        fig.tight_layout()
        files.append(_save(fig, d / f"residual_{tag}.png", plt))
    # order spectrum and autocorrelation
    fig, axes = plt.subplots(2, 2, figsize=(12, 7))
    from hil.identify.residuals import ORDERS

    for j, (tag, ana) in enumerate((("before", rep.residual_before),
                                    ("after", rep.residual_after))):
        for c, cr in ana.channels.items():
            # the judged pressure differences exist only in the analysis, not as channels
            if cr.order_amp is not None and c in exp.measured:
                sd = np.std((exp.measured[c] - (rep.outputs_before if j == 0
                                                else rep.outputs_after)[c])[val])
                axes[0, j].semilogy(ORDERS, cr.order_amp / max(sd, 1e-300), label=c)
            axes[1, j].plot(np.arange(1, cr.acf.size + 1), cr.acf, ".-", label=c, lw=0.6)
        axes[0, j].set_title(f"order spectrum of the residual, {tag}")
        axes[0, j].set_xlabel("order of the rotor angle")
        axes[0, j].set_ylabel("amplitude / residual std")
        axes[1, j].axhline(ana.bound, color="k", ls=":")
        axes[1, j].axhline(-ana.bound, color="k", ls=":")
        axes[1, j].set_title(f"autocorrelation, {tag} (99 % bounds)")
        axes[1, j].set_xlabel("lag [samples]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    files.append(_save(fig, d / "order_spectrum_acf.png", plt))
    return files


def _save(fig, path: Path, plt) -> Path:
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


__all__ = ["summary", "text", "to_json", "write_report"]
