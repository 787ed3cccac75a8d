"""Thesis F9 (Fig. 5.13 / 6.19): hip pitch under position control through the whole stack.

A 0.25 deg sine on the pitch reference, stepped in frequency; from the PC's own records
(1 kHz) the closed-loop responses command -> measured joint angle (forward kinematics of
the pistons) and command -> measured joint torque (G^T of the gauges' forces, Eq. 6.4-6.6),
their -3 dB bandwidths beside the thesis's 30-40 Hz, for the reinforced and the
unreinforced rod path (thesis 5.4). The stack: PC joint loop -> fieldbus process image ->
MCU 5 kHz -> driver boards 20 kHz -> two EHA plants coupled by the thigh
(:mod:`hil.sim.hip_stack`).

The load is the thigh with the leg below it (thesis 6.4.1: the robot on a crane, one leg
servo-on; Table 6.1's masses, :class:`plant.hip.thigh.LegBelow`). Two parameters are
calibrated on F9's two figures, position and torque: the rod path's series stiffness and
damping per cylinder (rod-end bearings, beam, slider, the robot's own structure;
:data:`F9_ROD_STIFFNESS_N_PER_M`, :data:`F9_ROD_DAMPING_NS_PER_M`), found by the grid
search :func:`calibrate_rod_path` inside the physical bounds of
:mod:`hil.scenarios.hip_study`. The position figure is shown, not judged: the study maps
the admissible region and shows that no admissible load angle reaches 30-40 Hz with the
thesis's K_p (docs/hip.md). The position loop is the thesis's K_p = 3000 Nm/rad with no
derivative term (K_d = 0: the thesis gives none, and a derivative of the piston-derived
angle, two cycles late, excites the thigh's mode).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_model.pc.joint_loop import JointGains
from hil.scenarios import Metric, Progress, ScenarioResult, register
from hil.scenarios.current import bandwidth_3db
from hil.sim.hip_stack import JointRecord, run_joint
from plant.config import Config
from plant.hip.thigh import LegBelow, ThighParams

AMPLITUDE_RAD = math.radians(0.25)   # thesis 6.4.1
THETA0_RAD = (0.0, 0.0)              # leg hanging
#: Frequencies of the stepped sine, Hz.
F9_FREQS_HZ = (2.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 50.0, 60.0, 80.0)
#: Rod-path damping of the testbed beam's path (the earlier one-figure calibration on F9's
#: torque with the beam's stiffness), N s/m: :func:`hip_bode`'s default.
BEAM_PATH_DAMPING_NS_PER_M = 4000.0
#: The two parameters calibrated on F9 (:func:`calibrate_rod_path`, docs/hip.md): the
#: reinforced rod path's series stiffness (N/m) and damping (N s/m) per cylinder.
F9_ROD_STIFFNESS_N_PER_M = 1.18e6
F9_ROD_DAMPING_NS_PER_M = 2.0e4
#: F9's load: the thigh and the servo-on leg below it.
F9_LOAD = ThighParams(leg=LegBelow())
F9_KD_NMS_PER_RAD = 0.0
START_S = 0.1                        # boot and settle before the first sine


def _plan(freqs: tuple[float, ...]) -> list[tuple[float, float, float]]:
    """(frequency, measure from, measure to) per step, s; each step settles first."""
    out, t = [], START_S
    for f in freqs:
        settle = max(2.0 / f, 0.04)
        span = max(round(6.0 / f * 1000) / 1000, 0.1)
        span = math.ceil(span * f) / f   # whole periods
        out.append((f, t + settle, t + settle + span))
        t += settle + span
    return out


def _reference(plan: list[tuple[float, float, float]], axis: int = 0):  # noqa: ANN202
    starts = [START_S] + [p[2] for p in plan[:-1]]

    def ref(t: float) -> tuple[float, float]:
        for (f, _, end), t0 in zip(plan, starts, strict=True):
            if t0 <= t < end:
                out = list(THETA0_RAD)
                out[axis] += AMPLITUDE_RAD * math.sin(2 * math.pi * f * (t - t0))
                return out[0], out[1]
        return THETA0_RAD

    return ref


def _sine_fit(t: np.ndarray, x: np.ndarray, f: float) -> complex:
    a = np.column_stack([np.cos(2 * math.pi * f * t), np.sin(2 * math.pi * f * t),
                         np.ones(len(t))])
    c, s, _ = np.linalg.lstsq(a, x, rcond=None)[0]
    return complex(c, -s)


def responses(rec: JointRecord, plan: list[tuple[float, float, float]], axis: int = 0
              ) -> tuple[np.ndarray, np.ndarray]:
    """(angle, torque) closed-loop responses per step, from the PC's records."""
    pos, tq, _ = responses_with_load(rec, plan, axis)
    return pos, tq


def responses_with_load(rec: JointRecord, plan: list[tuple[float, float, float]],
                        axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(angle, torque, the load's own angle) responses per step: the first two from the
    PC's records, the third from the plant's truth (what the thigh did)."""
    pos, tq, own = [], [], []
    for f, a, b in plan:
        k = (rec.t >= a) & (rec.t < b)
        t = rec.t[k]
        ref = _sine_fit(t, rec.theta_ref[k, axis], f)
        pos.append(_sine_fit(t, rec.theta[k, axis], f) / ref)
        tq.append(_sine_fit(t, rec.tau[k, axis], f) / _sine_fit(t, rec.tau_cmd[k, axis], f))
        own.append(_sine_fit(t, rec.theta_true[k, axis], f) / ref)
    return np.array(pos), np.array(tq), np.array(own)


def hip_bode(cfg: Config, freqs: tuple[float, ...], reinforced: bool,
             kd: float = F9_KD_NMS_PER_RAD, progress: Progress = None,
             rod_damping_ns_per_m: float = BEAM_PATH_DAMPING_NS_PER_M, axis: int = 0,
             feed_forward: bool = False, rod_stiffness_n_per_m: float | None = None,
             thigh: ThighParams | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequencies, angle response, torque response) of the hip pitch (axis 0) or roll
    (axis 1)."""
    f, pos, tq, _ = hip_bode_with_load(cfg, freqs, reinforced, kd, progress,
                                       rod_damping_ns_per_m, axis, feed_forward,
                                       rod_stiffness_n_per_m, thigh)
    return f, pos, tq


def hip_bode_with_load(cfg: Config, freqs: tuple[float, ...], reinforced: bool,
                       kd: float = F9_KD_NMS_PER_RAD, progress: Progress = None,
                       rod_damping_ns_per_m: float = BEAM_PATH_DAMPING_NS_PER_M,
                       axis: int = 0, feed_forward: bool = False,
                       rod_stiffness_n_per_m: float | None = None,
                       thigh: ThighParams | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`hip_bode` and the load's own angle response (plant truth)."""
    plan = _plan(freqs)
    kds = [JointGains().kd_nms_per_rad[0], JointGains().kd_nms_per_rad[1]]
    kds[axis] = kd
    gains = JointGains(kd_nms_per_rad=(kds[0], kds[1]))
    rec = run_joint(cfg, plan[-1][2] + 0.002, _reference(plan, axis), gains, reinforced,
                    progress, rod_damping_ns_per_m, thigh=thigh, feed_forward=feed_forward,
                    rod_stiffness_n_per_m=rod_stiffness_n_per_m)
    pos, tq, own = responses_with_load(rec, plan, axis)
    return np.array([p[0] for p in plan]), pos, tq, own


def _within(value: float, lo: float, hi: float) -> bool:
    return bool(lo <= value <= hi)


def f9_result(cfg: Config, freqs: tuple[float, ...], progress: Progress = None,
              axis: int = 0) -> ScenarioResult:
    """F9 on the pitch (axis 0) or, as Fig. 6.22, on the roll (axis 1): the thigh and the
    servo-on leg below it on the calibrated rod path; the position figure shown beside the
    admissible region's study (:mod:`hil.scenarios.hip_study`), the pitch's torque judged."""
    from hil.scenarios.hip_study import study_summary

    bodes, metrics = [], []
    for reinforced in (True, False):
        name = "reinforced" if reinforced else "unreinforced"
        f, pos, tq, own = hip_bode_with_load(
            cfg, freqs, reinforced, progress=progress, axis=axis,
            rod_damping_ns_per_m=F9_ROD_DAMPING_NS_PER_M,
            rod_stiffness_n_per_m=F9_ROD_STIFFNESS_N_PER_M, thigh=F9_LOAD)
        bodes += [(f"angle, {name}", f, pos), (f"torque, {name}", f, tq)]
        bp, bt = bandwidth_3db(f, pos), bandwidth_3db(f, tq)
        shown = reinforced  # the thesis's figures are of the reinforced structure
        judged = reinforced and axis == 0  # the roll is shown, not judged
        metrics += [
            Metric(f"position -3 dB, {name}", bp, "Hz",
                   "30-40 Hz: shown, not judged (study below)" if shown else "",
                   None, thesis=35.0 if shown else None),
            Metric(f"torque -3 dB, {name}", bt, "Hz", "30-40 Hz +/- 10 Hz" if judged else "",
                   _within(bt, 20.0, 50.0) if judged else None,
                   thesis=35.0 if shown else None),
        ]
        if reinforced:
            bodes.append((f"load angle, {name}", f, own))
            metrics.append(Metric(f"load's own angle -3 dB, {name}", bandwidth_3db(f, own),
                                  "Hz", "informative: the plant's thigh, not the PC's "
                                  "piston-derived angle"))
    kp = JointGains().kp_nm_per_rad[axis]
    study = study_summary(axis, kp, F9_LOAD.inertia(), ThighParams().inertia())
    metrics += [
        Metric("study: best load angle in the admissible region", study.best_load_hz, "Hz",
               "informative (ideal torque layer)"),
        Metric("study: best, thigh alone", study.best_thigh_hz, "Hz", "informative"),
    ]
    notes = [f"calibrated on F9's two figures (grid search, docs/hip.md): rod path "
             f"{F9_ROD_STIFFNESS_N_PER_M:.3g} N/m and {F9_ROD_DAMPING_NS_PER_M:g} N s/m per "
             f"cylinder (reinforced; unreinforced / "
             f"{cfg.get('load.beam_reinforcement_ratio'):.4g}); load: thigh "
             f"{F9_LOAD.mass_kg:g} kg and the servo-on leg below ({F9_LOAD.leg.shank_kg:g} + "
             f"{F9_LOAD.leg.foot_kg:g} kg, Table 6.1), I = {F9_LOAD.inertia():.2f} kg m^2; "
             f"K_p = {kp:g} Nm/rad from the thesis, K_d = {F9_KD_NMS_PER_RAD:g}, no "
             "inverse-dynamics feed-forward",
             *study.lines(),
             "stack: PC 1 kHz -> fieldbus (in-process) -> MCU 5 kHz -> FPGA 20 kHz -> two "
             "plants coupled by the thigh at 20 kHz; 0.25 deg sine about theta = 0 (hanging)",
             "a -3 dB figure of nan: the gain never fell below -3 dB over the frequencies run"]
    joint = ("pitch", "roll")[axis]
    if axis == 1:
        notes.append("roll: K_p = 6000 Nm/rad (thesis 6.4.1); the rod path is the pitch's "
                     "calibration, not refitted; nothing judged")
    return ScenarioResult("f9" if axis == 0 else "f9-roll",
                          f"hip {joint} position control, 0.25 deg sine", metrics,
                          series={"bodes": bodes}, plot=_plot, notes=notes)


@register("f9")
def f9(cfg: Config, progress: Progress = None) -> ScenarioResult:
    return f9_result(cfg, F9_FREQS_HZ, progress)


@register("f9-roll")
def f9_roll(cfg: Config, progress: Progress = None) -> ScenarioResult:
    return f9_result(cfg, F9_FREQS_HZ, progress, axis=1)


def _plot(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot, mark_thesis

    plt = _pyplot()
    fig, (ag, ap) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    styles = {"angle": "b", "torque": "r", "load angle": "g"}
    for name, f, h in res.series["bodes"]:
        c = styles[name.split(",")[0]]
        ls = "o-" if "unreinforced" not in name else "s:"
        ag.semilogx(f, 20 * np.log10(np.abs(h)), ls, color=c if "unr" not in name else "k",
                    ms=4, label=name)
        ap.semilogx(f, np.degrees(np.unwrap(np.angle(h))), ls,
                    color=c if "unr" not in name else "k", ms=4)
    ag.axhline(-3.0, color="r", ls=":", lw=0.8)
    for x in (30.0, 40.0):
        mark_thesis(ag, x=x, label="30-40 Hz" if x == 30.0 else "")
    ag.set_ylabel("gain [dB]")
    ap.set_ylabel("phase [deg]")
    ap.set_xlabel("frequency [Hz]")
    ag.set_title(f"{res.name.upper()}: {res.title}")
    ag.legend(fontsize=8)
    for a in (ag, ap):
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


#: A response whose gain exceeds this anywhere is not that of a stable linear loop, dB.
LINEAR_LOOP_MAX_DB = 20.0


@dataclass(frozen=True)
class RodPathPoint:
    """One (stiffness, damping) point of the rod-path calibration and what F9 gave there."""

    stiffness_n_per_m: float
    damping_ns_per_m: float
    position_hz: float
    torque_hz: float
    linear: bool           # both responses within LINEAR_LOOP_MAX_DB (a stable loop)

    def cost(self, target_hz: float) -> float:
        """Squared log errors of both figures against ``target_hz``; inf off a linear loop
        or where a gain never fell below -3 dB."""
        if not self.linear or math.isnan(self.position_hz) or math.isnan(self.torque_hz):
            return math.inf
        return (math.log(self.position_hz / target_hz) ** 2
                + math.log(self.torque_hz / target_hz) ** 2)


def rod_path_point(cfg: Config, k: float, c: float, freqs: tuple[float, ...],
                   thigh: ThighParams | None = None, axis: int = 0) -> RodPathPoint:
    """F9 (reinforced) at rod-path stiffness ``k`` and damping ``c``."""
    f, pos, tq = hip_bode(cfg, freqs, True, rod_damping_ns_per_m=c, rod_stiffness_n_per_m=k,
                          thigh=thigh, axis=axis)
    gains = 20.0 * np.log10(np.abs(np.concatenate([pos, tq])))
    return RodPathPoint(k, c, bandwidth_3db(f, pos), bandwidth_3db(f, tq),
                        bool(np.all(gains < LINEAR_LOOP_MAX_DB)))


def calibrate_rod_path(cfg: Config, target_hz: float, stiffness: np.ndarray,
                       damping: np.ndarray, freqs: tuple[float, ...] = F9_FREQS_HZ,
                       thigh: ThighParams | None = None,
                       log: Callable[[RodPathPoint], None] | None = None
                       ) -> tuple[RodPathPoint, list[RodPathPoint]]:
    """Grid search of the rod path's (stiffness, damping) for F9's two figures, position
    and torque, both against ``target_hz``: (the best point, every point run)."""
    points = []
    for k in stiffness:
        for c in damping:
            pt = rod_path_point(cfg, float(k), float(c), freqs, thigh)
            points.append(pt)
            if log:
                log(pt)
    return min(points, key=lambda p: p.cost(target_hz)), points
