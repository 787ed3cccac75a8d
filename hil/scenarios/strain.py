"""Thesis 4.4 on the full stack: rod-seal friction compensation with the strain gauge.

* F7 (Fig. 4.7-4.9): the actuator under the low-gain local position loop
  (tau_ref = K_pos (0 - x), K_pos = ``mcu.position_kp_n_per_m`` = 10 N/mm), a cart on the
  connecting rod moved back and forth by hand, rod-seal friction on. RMS of the actual rod
  force (plant truth) minus the desired force K_pos (0 - x), closing the force loop on the
  pressure sensors (thesis 12.1 N) and on the strain gauge (thesis 1.3 N).
* F8 (Fig. 4.10-4.11): the rod's far end on a fixed force gauge, force control pushing and
  pulling while the surroundings heat up; RMS error against the true rod force of the
  strain-gauge force, the pressure force k_c (p_cyl_a - p_cyl_b) and the complementary
  filtered force of Eq. 4.4 (thesis 15.1 N, 6.58 N, 4.18 N).

Both run on the configuration they are given (``eha-hil run`` uses ``hydra_thesis``) with
the load and the feedback set here, and the configuration's rod-seal friction switched on
(its magnitude is calibrated in the hydra_thesis preset, whose comment says how). The PC
keeps the MCU's command "off" for :data:`STARTUP_OFF_S` after enable, then starts the
experiment.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil.scenarios import Metric, Progress, ScenarioResult, register
from hil.sim.actuator import PC_PERIOD_TICKS, ActuatorStack
from hil.sim.scheduler import Record
from plant import layout as L
from plant.config import Config

#: The PC sends "off" for this long after enable (the MCU then holds its controller in
#: reset), then the experiment's command, as an operator enables the actuator and then
#: starts. The MCU's Eq. 4.4 high-pass waits for the AD7195's first conversion (before it
#: the register reads code 0, i.e. -3000 N), so this is procedure, not a workaround:
#: with 0 s the F7/F8 figures move by less than 0.15 N.
STARTUP_OFF_S = 0.1

# --- F7: the hand ---------------------------------------------------------------------------
#: The hand as a force source on the cart: a person's arm is far softer (~1 N/mm) than the
#: 10 N/mm position loop, so what the hand sets is the force, and the cart and piston go
#: where the actuator's stiffness lets them. A slow deliberate back-and-forth: +/- 100 N,
#: one 4 s cycle (0.25 Hz), faded in over the first second. With the 10 N/mm loop that
#: moves the piston about +/- 9 mm at up to ~25 mm/s.
HAND_AMPLITUDE_N = 100.0
HAND_FREQUENCY_HZ = 0.25
HAND_FADE_IN_S = 1.0
#: Run length and the start of the steady part the RMS is taken over (three full cycles).
F7_RUN_S = 16.0
F7_STEADY_FROM_S = 4.0
F7_THESIS = {"pressure": 12.1, "strain": 1.3}
F7_PRESSURE_TOL_N = 4.0
F7_STRAIN_MAX_N = 2.5

# --- F8: push/pull on the force gauge while heating ------------------------------------------
#: Force command: a slow sine pushing and pulling the gauge, +/- 300 N at 0.5 Hz, faded in.
F8_AMPLITUDE_N = 300.0
F8_FREQUENCY_HZ = 0.5
F8_FADE_IN_S = 1.0
#: Heat gun: the surroundings warm by 15 degC at a steady 0.25 degC/s over the 60 s run; the
#: rod (strain drift 2.5 N/degC) follows with ``effects.strain_drift.rod_time_constant_s``.
F8_RUN_S = 60.0
F8_HEATING_C = 15.0
F8_FROM_S = 1.0
#: The force feedback the controller closes on in F8. The thesis says only "force control";
#: pressure feedback keeps f_fil a pure observer, so the cutoff sweep below (recomputed
#: from the recorded f_pres and f_strain) is exact.
F8_FEEDBACK = "pressure"
F8_THESIS = {"strain": 15.1, "pressure": 6.58, "complementary": 4.18}
F8_REL_TOL = 0.4
#: Cutoffs (Hz) at which the complementary filter is re-evaluated from the recording.
F8_CUTOFF_SWEEP_HZ = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _fade(t: float, fade_s: float) -> float:
    """0 -> 1 over ``fade_s`` (raised cosine), then 1."""
    if t >= fade_s:
        return 1.0
    return 0.5 - 0.5 * math.cos(math.pi * max(t, 0.0) / fade_s)


def seal_overrides(cfg: Config, coulomb_n: float | None = None) -> dict[str, object]:
    """Seal friction on; with ``coulomb_n`` (N) its Coulomb force replaced and the breakaway
    force scaled by the same factor, so the Stribeck shape stays the configuration's."""
    static, coulomb = (cfg.get(f"effects.seal_friction.{k}") for k in ("static_n", "coulomb_n"))
    if coulomb_n is None:
        return {"effects.seal_friction.enabled": True}
    ratio = static / coulomb if coulomb > 0 else 1.0
    return {"effects.seal_friction.enabled": True,
            "effects.seal_friction.coulomb_n": coulomb_n,
            "effects.seal_friction.static_n": coulomb_n * ratio}


def _probe_plant(stack: ActuatorStack) -> None:
    """Probe plant outputs at the MCU's rate and ticks (no full plant record needed)."""
    y = stack.fpga.plant.y
    for name, idx in (("f_rod", L.Y_F_ROD), ("x_piston", L.Y_X_PISTON),
                      ("v_piston", L.Y_V_PISTON)):
        stack.sched.probe("plant_" + name, lambda i=idx: float(y[i]), stack.mcu.period)


def _probes(rec: Record, *names: str) -> tuple[np.ndarray, ...]:
    """(t, values...) of probes sampled on the same ticks."""
    t = rec.probe(names[0])[0]
    return (t, *(rec.probe(n)[1] for n in names))


def _lowpass_split(x: np.ndarray, dt: float, f_cut: float) -> tuple[float, float]:
    """RMS of the parts of ``x`` below and above ``f_cut`` (FFT brick wall)."""
    spec = np.fft.rfft(x)
    f = np.fft.rfftfreq(len(x), dt)
    low = np.fft.irfft(np.where(f < f_cut, spec, 0.0), len(x))
    return _rms(low), _rms(x - low)


# === F7 ======================================================================================
def f7_run(cfg: Config, feedback: str, coulomb_n: float | None = None) -> dict[str, object]:
    """One F7 run closing the force loop on ``feedback``; errors and decimated series."""
    over = {"load.kind": "cart", "mcu.force_feedback": feedback, **seal_overrides(cfg, coulomb_n)}
    cfg = cfg.with_overrides(over, f"F7 {feedback} feedback")

    def command(t: float) -> tuple[str, float]:
        return ("off", 0.0) if t < STARTUP_OFF_S else ("position", 0.0)

    stack = ActuatorStack(cfg, command, record_every=0)
    _probe_plant(stack)
    plant = stack.fpga.plant
    tick_s = stack.tick_s

    def hand(tick: int) -> None:
        t = tick * tick_s
        plant.set_external_force(_fade(t, HAND_FADE_IN_S) * HAND_AMPLITUDE_N
                                 * math.sin(2.0 * math.pi * HAND_FREQUENCY_HZ * t))

    stack.sched.every(PC_PERIOD_TICKS, hand, "hand")
    rec = stack.run(F7_RUN_S)
    t, desired, actual, strain, pres, x, v = _probes(
        rec, "tau_ref", "plant_f_rod", "f_strain", "f_pres", "plant_x_piston", "plant_v_piston")
    steady = t >= F7_STEADY_FROM_S
    err = actual - desired
    low, high = _lowpass_split(err[steady], float(t[1] - t[0]), 5.0)
    dec = slice(None, None, 10)  # 500 Hz for the plots
    return {
        "rms": _rms(err[steady]),
        "rms_gauge": _rms((strain - desired)[steady]),
        "rms_low": low, "rms_high": high,
        "stroke_mm": float(np.ptp(x[steady]) * 1e3),
        "v_peak_mm_s": float(np.max(np.abs(v[steady])) * 1e3),
        "t": t[dec], "x": x[dec], "desired": desired[dec], "actual": actual[dec],
        "strain": strain[dec], "pres": pres[dec], "steady_from": F7_STEADY_FROM_S,
        "k_pos": cfg.get("mcu.position_kp_n_per_m"),
    }


@register("f7")
def f7(cfg: Config, progress: Progress = None) -> ScenarioResult:
    runs = {}
    for i, fb in enumerate(("pressure", "strain")):
        runs[fb] = f7_run(cfg, fb)
        if progress:
            progress(i + 1, 2)
    ep, es = runs["pressure"]["rms"], runs["strain"]["rms"]
    ok_p = bool(abs(ep - F7_THESIS["pressure"]) <= F7_PRESSURE_TOL_N)
    ok_s = bool(es <= F7_STRAIN_MAX_N)
    metrics = [
        Metric("RMS error, pressure feedback", ep, "N",
               f"thesis 12.1 N; 12.1 +/- {F7_PRESSURE_TOL_N:g} N (seal Coulomb force "
               "calibrated on it)", ok_p, thesis=F7_THESIS["pressure"]),
        Metric("RMS error, strain feedback", es, "N",
               f"thesis 1.3 N; <= {F7_STRAIN_MAX_N:g} N", ok_s, thesis=F7_THESIS["strain"]),
        Metric("reduction by strain feedback", ep / es, "x", "informative",
               thesis=F7_THESIS["pressure"] / F7_THESIS["strain"]),
        Metric("RMS error vs strain-gauge reading, pressure fb", runs["pressure"]["rms_gauge"],
               "N", "informative: the thesis's 'actual' was the gauge"),
        Metric("RMS error vs strain-gauge reading, strain fb", runs["strain"]["rms_gauge"],
               "N", "informative"),
        Metric("piston stroke (p-p), pressure fb", runs["pressure"]["stroke_mm"], "mm",
               "informative: the hand's motion"),
        Metric("peak piston speed, pressure fb", runs["pressure"]["v_peak_mm_s"], "mm/s",
               "informative"),
    ]
    notes = []
    kp = cfg.get("mcu.kp_force")
    # Meshing-ripple frequency at the strain run's peak speed: order x rotor speed.
    ripple_hz = (cfg.get("effects.pulsation.order") * cfg.get("hydraulics.kc_m2")
                 / cfg.get("hydraulics.kp_m3_per_rad") * runs["strain"]["v_peak_mm_s"] * 1e-3
                 / (2.0 * math.pi))
    if not ok_p:
        notes.append(
            f"pressure-feedback error {ep:.1f} N misses 12.1 +/- {F7_PRESSURE_TOL_N:g} N by "
            f"{abs(ep - F7_THESIS['pressure']) - F7_PRESSURE_TOL_N:.1f} N: it is set by the "
            f"rod-seal friction (Coulomb {cfg.get('effects.seal_friction.coulomb_n'):g} N, "
            "calibrated in the hydra_thesis "
            "preset; another preset's meshing ripple or loop gains shift it)")
    # What the strain feedback leaves, said whether or not it meets the requirement: the
    # thesis's 1.3 N is below it, and a reader comparing the two needs the split.
    verdict = (f"misses <= {F7_STRAIN_MAX_N:g} N by {es - F7_STRAIN_MAX_N:.1f} N" if not ok_s
               else f"meets <= {F7_STRAIN_MAX_N:g} N")
    ripple = cfg.get("effects.pulsation.torque_n") + cfg.get(
        "effects.pulsation.torque_amplitude") * HAND_AMPLITUDE_N
    notes.append(
        f"strain-feedback error {es:.1f} N {verdict} ({es / F7_THESIS['strain']:.1f}x the "
        f"thesis's 1.3 N); {runs['strain']['rms_low']:.1f} N of it below 5 Hz, "
        f"{runs['strain']['rms_high']:.1f} N above. The strain feedback removes the seal "
        f"friction (observer at {cfg.get('mcu.seal_observer_hz'):g} Hz, which lags the seal's "
        "flip at each reversal); below 5 Hz what is left is mostly the pressure loop's own "
        "tracking error while the hand backdrives the pump: the pump-side inertia J_p a "
        f"({cfg.get('hydraulics.jp_kg'):g} kg seen from the piston) and the momentum "
        f"observer's lag on d_p v, divided by 1 + kp_force = {1 + kp:g}; Fig. 5.2 has no "
        "inertia feed-forward, and integral action on the strain error destabilises this "
        "low-gain position loop (docs/mcu.md). Above 5 Hz it is the meshing torque ripple "
        f"(up to {ripple:.0f} N at the hand's peak force) at 4x the rotor speed, up to "
        f"{ripple_hz:.0f} Hz while backdriven")
    return ScenarioResult(
        "f7", "low-gain position control (10 N/mm), cart moved by hand, seal friction on",
        metrics, series=runs, plot=_plot_f7, notes=notes)


def _plot_f7(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot

    plt = _pyplot()
    s = res.series
    fig = plt.figure(figsize=(11, 7))
    grid = fig.add_gridspec(2, 2)
    for row, (fb, label) in enumerate((("pressure", "without strain feedback (Fig. 4.7)"),
                                       ("strain", "with strain feedback (Fig. 4.8)"))):
        r = s[fb]
        ax = fig.add_subplot(grid[row, 0])
        ax.plot(r["t"], r["actual"], "r", lw=0.8, label="actual rod force (truth)")
        ax.plot(r["t"], r["desired"], "g", lw=0.8, label="desired K_pos (0 - x)")
        ax.plot(r["t"], r["pres"], "b", lw=0.6, alpha=0.7, label="pressure force")
        ax.plot(r["t"], r["actual"] - r["desired"], "k", lw=0.6,
                label=f"error ({r['rms']:.1f} N RMS)")
        ax.axvline(r["steady_from"], color="0.5", ls=":", lw=0.8)
        ax.set_ylabel("force [N]")
        ax.set_title(label, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
        if row == 1:
            ax.set_xlabel("time [s]")
    ax = fig.add_subplot(grid[:, 1])
    for fb, colour in (("pressure", "b"), ("strain", "g")):
        r = s[fb]
        keep = r["t"] >= r["steady_from"]
        ax.plot(r["x"][keep] * 1e3, r["actual"][keep], ".", color=colour, ms=1.5,
                label=f"{fb} feedback ({r['rms']:.1f} N RMS)")
    xs = np.array([s["pressure"]["x"].min(), s["pressure"]["x"].max()])
    ax.plot(xs * 1e3, -s["pressure"]["k_pos"] * xs, "r-", lw=1.0, label="desired")
    ax.set_xlabel("piston position [mm]")
    ax.set_ylabel("actual rod force [N]")
    ax.set_title("position vs force (Fig. 4.9)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle("F7: " + res.title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# === F8 ======================================================================================
def complementary(f_pres: np.ndarray, f_strain: np.ndarray, cutoff_hz: float, dt: float
                  ) -> np.ndarray:
    """Eq. 4.4 as the MCU computes it (float64): f_pres + HP(f_strain - f_pres), the
    high-pass y = a (y + u - u_prev), a = 1 / (1 + 2 pi f_c dt), started at rest."""
    from scipy.signal import lfilter

    a = 1.0 / (1.0 + 2.0 * math.pi * cutoff_hz * dt)
    du = np.diff(f_strain - f_pres, prepend=f_strain[0] - f_pres[0])
    return f_pres + lfilter([a], [1.0, -a], du)


@register("f8")
def f8(cfg: Config, progress: Progress = None) -> ScenarioResult:
    over = {"load.kind": "conrod", "mcu.force_feedback": F8_FEEDBACK, **seal_overrides(cfg)}
    cfg = cfg.with_overrides(over, "F8")
    t_amb0 = cfg.get("effects.oil_temperature.ambient_c")

    def command(t: float) -> tuple[str, float]:
        if t < STARTUP_OFF_S:
            return "off", 0.0
        return "force", (_fade(t - STARTUP_OFF_S, F8_FADE_IN_S) * F8_AMPLITUDE_N
                         * math.sin(2.0 * math.pi * F8_FREQUENCY_HZ * (t - STARTUP_OFF_S)))

    stack = ActuatorStack(cfg, command, record_every=0)
    _probe_plant(stack)
    plant = stack.fpga.plant
    tick_s = stack.tick_s

    def heat(tick: int) -> None:
        plant.set_ambient(t_amb0 + F8_HEATING_C * min(tick * tick_s / F8_RUN_S, 1.0))

    stack.sched.every(200, heat, "heat gun")
    stack.sched.probe("t_rod", lambda: float(plant.x[L.S_TROD]), 200)
    stack.sched.probe("t_amb", lambda: float(plant.u[L.IN_T_AMB]), 200)
    rec = stack.run(F8_RUN_S)
    if progress:
        progress(1, 1)
    t, f_pres, f_strain, f_fil, truth, v = _probes(
        rec, "f_pres", "f_strain", "f_fil", "plant_f_rod", "plant_v_piston")
    keep = t >= F8_FROM_S
    errs = {"strain": f_strain - truth, "pressure": f_pres - truth,
            "complementary": f_fil - truth}
    rms = {k: _rms(e[keep]) for k, e in errs.items()}
    t_rod_t, t_rod = rec.probe("t_rod")
    rod_at = np.interp(t, t_rod_t, t_rod)
    drift_gain = float(np.polyfit(rod_at[keep], errs["strain"][keep], 1)[0])
    dt = float(t[1] - t[0])
    on = t >= STARTUP_OFF_S  # the MCU's filter starts on its first step after "off"
    sweep = [_rms((complementary(f_pres[on], f_strain[on], fc, dt) - truth[on])[keep[on]])
             for fc in F8_CUTOFF_SWEEP_HZ]
    best = int(np.argmin(sweep))
    ordered = rms["strain"] > rms["pressure"] > rms["complementary"]

    metrics = []
    for name in ("strain", "pressure", "complementary"):
        th = F8_THESIS[name]
        metrics.append(Metric(
            f"RMS error, {name}", rms[name], "N",
            f"thesis {th:g} N; +/- {F8_REL_TOL * 100:.0f} %",
            bool(abs(rms[name] - th) <= F8_REL_TOL * th), thesis=th))
    metrics += [
        Metric("order strain > pressure > complementary", float(ordered), "",
               "required (1 = holds)", bool(ordered)),
        Metric("strain drift vs rod temperature", drift_gain, "N/degC",
               "informative (Fig. 4.10)", thesis=2.5),
        Metric("rod temperature rise", float(t_rod[-1] - t_rod[0]), "degC", "informative"),
        Metric("best complementary cutoff in the sweep", F8_CUTOFF_SWEEP_HZ[best], "Hz",
               f"informative: {sweep[best]:.2f} N RMS there (preset "
               f"{cfg.get('mcu.complementary_cutoff_hz'):g} Hz)"),
    ]
    notes = []
    v_rms = _rms(v[keep])
    c_eq = cfg.get("effects.seal_friction.static_n") / cfg.get(
        "effects.seal_friction.velocity_eps_m_per_s")
    shape = (
        f"the pressure error is the rod-seal friction: the piston moves only "
        f"{v_rms * 1e3:.2f} mm/s RMS against the rod, inside the seal's pre-sliding regime, "
        f"which the tanh-regularised model renders as a viscous {c_eq / 1e3:.1f} kN s/m "
        "(breakaway / eps): the error follows the piston velocity (a quarter period ahead of "
        "the force) instead of the thesis's push/pull-dependent constant offset, and scales "
        "with the command's force rate and 1 / conrod stiffness")
    for m in metrics[:3]:
        if m.ok:
            continue
        name = m.name.split(", ")[1]
        th = F8_THESIS[name]
        miss = abs(m.value - th) - F8_REL_TOL * th
        why = {
            "strain": "set by the rod temperature rise (heating rate, rod time constant) times "
                      "2.5 N/degC",
            "pressure": shape,
            "complementary": "the high-pass lets slope x tau_hp of the strain drift through "
                             "and the low-pass keeps the friction's slow part",
        }[name]
        notes.append(f"{name} error {m.value:.2f} N misses {th:g} N +/- "
                     f"{F8_REL_TOL * 100:.0f} % by {miss:.2f} N: {why}")
    if metrics[1].ok:
        notes.append("pressure-error shape: " + shape)
    if not ordered:
        notes.append("the order strain > pressure > complementary does not hold")
    dec = slice(np.argmax(keep), None, 25)  # 200 Hz for the plot, from F8_FROM_S
    series = {"t": t[dec], "truth": truth[dec], "strain": f_strain[dec], "pressure": f_pres[dec],
              "complementary": f_fil[dec], "t_temp": t_rod_t, "t_rod": t_rod,
              "t_amb": rec.probe("t_amb")[1], "rms": rms,
              "sweep_hz": np.array(F8_CUTOFF_SWEEP_HZ), "sweep_rms": np.array(sweep)}
    return ScenarioResult(
        "f8", "push/pull on a fixed force gauge, surroundings heated by 15 degC", metrics,
        series=series, plot=_plot_f8, notes=notes)


def _plot_f8(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot

    plt = _pyplot()
    s = res.series
    t = s["t"]
    colours = {"strain": "b", "pressure": "g", "complementary": "r"}
    fig = plt.figure(figsize=(11, 7.5))
    grid = fig.add_gridspec(2, 2, height_ratios=(1, 1.2))
    span = 2.0 / F8_FREQUENCY_HZ
    for col, (lo, title) in enumerate(((F8_FROM_S, "start (cold)"),
                                       (t[-1] - span, "end (heated)"))):
        ax = fig.add_subplot(grid[0, col])
        w = (t >= lo) & (t <= lo + span)
        ax.plot(t[w], s["truth"][w], "k", lw=2.5, label="force gauge (truth)")
        for name, c in colours.items():
            ax.plot(t[w], s[name][w], c, lw=0.8, label=name)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("force [N]")
        ax.grid(True, alpha=0.3)
        if col == 0:
            ax.legend(fontsize=7)
    ae = fig.add_subplot(grid[1, :])
    for name, c in colours.items():
        ae.plot(t, s[name] - s["truth"], c, lw=0.6,
                label=f"{name} ({s['rms'][name]:.2f} N RMS)")
    ae.set_xlabel("time [s]")
    ae.set_ylabel("error vs force gauge [N]")
    ae.grid(True, alpha=0.3)
    ae.legend(loc="upper left", fontsize=8)
    at = ae.twinx()
    at.plot(s["t_temp"], s["t_amb"], color="orange", ls=":", label="surroundings")
    at.plot(s["t_temp"], s["t_rod"], color="orange", ls="--", label="connecting rod")
    at.set_ylabel("temperature [degC]")
    at.legend(loc="lower right", fontsize=8)
    fig.suptitle("F8 (Fig. 4.11): " + res.title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
