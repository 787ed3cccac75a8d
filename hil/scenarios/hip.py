"""Thesis F9 (Fig. 5.13 / 6.19): hip pitch under position control through the whole stack.

A 0.25 deg sine on the pitch reference, stepped in frequency; from the PC's own records
(1 kHz) the closed-loop responses command -> measured joint angle (forward kinematics of
the pistons) and command -> measured joint torque (G^T of the gauges' forces, Eq. 6.4-6.6),
their -3 dB bandwidths beside the thesis's 30-40 Hz, for the reinforced and the
unreinforced rod path (thesis 5.4). The stack: PC joint loop -> fieldbus process image ->
MCU 5 kHz -> driver boards 20 kHz -> two EHA plants coupled by the thigh
(:mod:`hil.sim.hip_stack`).

One figure is calibrated on F9: the damping of the rod path between piston and thigh
(rod-end bearings, beam, slider; :data:`F9_ROD_DAMPING_NS_PER_M`), on the torque
bandwidth with the reinforced structure. The position loop is the thesis's K_p =
3000 Nm/rad with no derivative term (K_d = 0: the thesis gives none, and a derivative of
the piston-derived angle, two cycles late, excites the thigh's mode).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from firmware_model.pc.joint_loop import JointGains
from hil.scenarios import Metric, Progress, ScenarioResult, register
from hil.scenarios.current import bandwidth_3db
from hil.sim.hip_stack import JointRecord, run_joint
from plant.config import Config

AMPLITUDE_RAD = math.radians(0.25)   # thesis 6.4.1
THETA0_RAD = (0.0, 0.0)              # leg hanging
#: Frequencies of the stepped sine, Hz.
F9_FREQS_HZ = (2.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 50.0, 60.0, 80.0)
#: The one parameter calibrated on F9 (docs/hip.md): rod-path damping, N s/m.
F9_ROD_DAMPING_NS_PER_M = 4000.0
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
    pos, tq = [], []
    for f, a, b in plan:
        k = (rec.t >= a) & (rec.t < b)
        t = rec.t[k]
        pos.append(_sine_fit(t, rec.theta[k, axis], f) / _sine_fit(t, rec.theta_ref[k, axis], f))
        tq.append(_sine_fit(t, rec.tau[k, axis], f) / _sine_fit(t, rec.tau_cmd[k, axis], f))
    return np.array(pos), np.array(tq)


def hip_bode(cfg: Config, freqs: tuple[float, ...], reinforced: bool,
             kd: float = F9_KD_NMS_PER_RAD, progress: Progress = None,
             rod_damping_ns_per_m: float = F9_ROD_DAMPING_NS_PER_M, axis: int = 0,
             feed_forward: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequencies, angle response, torque response) of the hip pitch (axis 0) or roll
    (axis 1)."""
    plan = _plan(freqs)
    kds = [JointGains().kd_nms_per_rad[0], JointGains().kd_nms_per_rad[1]]
    kds[axis] = kd
    gains = JointGains(kd_nms_per_rad=(kds[0], kds[1]))
    rec = run_joint(cfg, plan[-1][2] + 0.002, _reference(plan, axis), gains, reinforced,
                    progress, rod_damping_ns_per_m, feed_forward=feed_forward)
    pos, tq = responses(rec, plan, axis)
    return np.array([p[0] for p in plan]), pos, tq


def _within(value: float, lo: float, hi: float) -> bool:
    return bool(lo <= value <= hi)


def f9_result(cfg: Config, freqs: tuple[float, ...], progress: Progress = None,
              axis: int = 0) -> ScenarioResult:
    """F9 on the pitch (axis 0) or, as Fig. 6.22, on the roll (axis 1)."""
    bodes, metrics = [], []
    for reinforced in (True, False):
        name = "reinforced" if reinforced else "unreinforced"
        f, pos, tq = hip_bode(cfg, freqs, reinforced, progress=progress, axis=axis)
        bodes += [(f"angle, {name}", f, pos), (f"torque, {name}", f, tq)]
        bp, bt = bandwidth_3db(f, pos), bandwidth_3db(f, tq)
        judged = reinforced and axis == 0  # the roll is shown, not judged
        metrics += [
            Metric(f"position -3 dB, {name}", bp, "Hz",
                   "30-40 Hz +/- 10 Hz" if judged else "",
                   _within(bp, 20.0, 50.0) if judged else None,
                   thesis=35.0 if judged else None),
            Metric(f"torque -3 dB, {name}", bt, "Hz", "30-40 Hz +/- 10 Hz" if judged else "",
                   _within(bt, 20.0, 50.0) if judged else None,
                   thesis=35.0 if judged else None),
        ]
    notes = [f"calibrated on F9: rod-path damping {F9_ROD_DAMPING_NS_PER_M:g} N s/m "
             "(load.conrod_damping_ns_per_m for the hip's rods); K_p = "
             f"{JointGains().kp_nm_per_rad[axis]:g} Nm/rad from the thesis, "
             f"K_d = {F9_KD_NMS_PER_RAD:g}, no inverse-dynamics feed-forward (it lowers "
             "the position figure: docs/hip.md)",
             "stack: PC 1 kHz -> fieldbus (in-process) -> MCU 5 kHz -> FPGA 20 kHz -> two "
             "plants coupled by the thigh at 20 kHz; 0.25 deg sine about theta = 0 (hanging)",
             "a -3 dB figure of nan: the gain never fell below -3 dB over the frequencies run"]
    joint = ("pitch", "roll")[axis]
    if axis == 1:
        notes.append("roll: K_p = 6000 Nm/rad (thesis 6.4.1); the rod-path damping is "
                     "the pitch's calibration, not refitted")
    return ScenarioResult("f9" if axis == 0 else "f9-roll",
                          f"hip {joint} position control, 0.25 deg sine", metrics,
                          series={"bodes": bodes}, plot=_plot, notes=notes)


@register("f9", "thesis F9: hip pitch position control through the whole stack, 0.25 deg "
          "sine: position and torque bandwidth 30-40 Hz, unreinforced beside it")
def f9(cfg: Config, progress: Progress = None) -> ScenarioResult:
    return f9_result(cfg, F9_FREQS_HZ, progress)


@register("f9-roll", "thesis Fig. 6.22: F9 on the hip roll (K_p 6000 Nm/rad): position "
          "bandwidth 30-40 Hz, torque gain falling before 30 Hz")
def f9_roll(cfg: Config, progress: Progress = None) -> ScenarioResult:
    return f9_result(cfg, F9_FREQS_HZ, progress, axis=1)


def _plot(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot, mark_thesis

    plt = _pyplot()
    fig, (ag, ap) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    styles = {"angle": "b", "torque": "r"}
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
