"""Current-loop scenarios on the driver board with the plant (piston fixed).

``current-step``: iq reference 0 -> 10 A written by the MCU side; rise time (10-90 %),
overshoot and steady-state error of the motor's q current (plant truth), plus the link
latency until the board received the new reference.

``current-bode``: a sinusoidal iq reference about a 6 A bias, written every tick; gain and
phase from the reference the board actually used to the q current it sampled, on a
frequency grid; the -3 dB bandwidth by interpolation. Both run the value-level stack.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from firmware_model.fpga import layout as B
from hil.scenarios import Metric, Progress, ScenarioResult, register
from hil.sim.actuator import FpgaStack
from plant import layout as L
from plant.config import Config

STEP_A = 10.0
BANDWIDTH_MIN_HZ = 1000.0
#: Operating point of the frequency response: 6 A (about 720 N of pressure force) with a
#: +/- 2 A sine keeps every phase current outside the +/- 2 A band in which the inverter's
#: dead-time error changes sign. Inside it that error acts as an extra 0.48 ohm
#: (t_d f_pwm V_dc / 2 A), which the PI (zero at R/L) does not cancel; the scenario reports
#: that small-signal figure about 0 A as well.
BIAS_A = 6.0
AMPLITUDE_A = 2.0


def _fixed(cfg: Config) -> Config:
    return cfg.with_overrides({"load.kind": "fixed"}, "scenario: piston fixed")


def step_metrics(t: np.ndarray, i: np.ndarray, target: float, t0: float
                 ) -> tuple[float, float, float]:
    """(rise time 10-90 % in s from t0, overshoot in % of the step, steady-state error in A
    as the mean over the last quarter of the record minus the target)."""
    after = t >= t0
    ts, xs = t[after], i[after]
    lo, hi = 0.1 * target, 0.9 * target
    t10 = ts[np.argmax(xs >= lo)] if np.any(xs >= lo) else math.nan
    t90 = ts[np.argmax(xs >= hi)] if np.any(xs >= hi) else math.nan
    overshoot = max(0.0, (xs.max() - target) / target * 100.0)
    tail = xs[int(0.75 * len(xs)):]
    return t90 - t10, overshoot, float(tail.mean() - target)


@register("current-step")
def current_step(cfg: Config, progress: Progress = None) -> ScenarioResult:
    cfg = _fixed(cfg)
    stack = FpgaStack(cfg)
    stack.boot()
    pre = 40
    total = 400  # 20 ms after the step
    rec = np.zeros((pre + total, L.N_OUTPUTS))
    row = stack.advance(pre, rec)
    t_step = stack.tick
    stack.mcu_link.write("iq_ref", round(STEP_A * 1000))
    latency_ticks = 0
    while stack.board.down_value("iq_ref") != round(STEP_A * 1000):
        row = stack.advance(1, rec, row)
        latency_ticks += 1
        if latency_ticks > 100:
            raise RuntimeError("the iq reference never reached the board")
    row = stack.advance(pre + total - row, rec, row)
    if progress:
        progress(1, 1)
    t = (np.arange(1, row + 1) + (t_step - pre)) * stack.tick_s
    iq = rec[:row, L.Y_IQ]
    t0 = t_step * stack.tick_s
    rise, overshoot, ss = step_metrics(t, iq, STEP_A, t0)
    tick_ms = stack.tick_s * 1e3
    metrics = [
        Metric("rise time 10-90 %", rise * 1e3, "ms", "from the MCU's write"),
        Metric("overshoot", overshoot, "%"),
        Metric("steady-state error", ss, "A", "mean of the last 5 ms"),
        Metric("steady-state error rel.", ss / STEP_A * 100.0, "%"),
        Metric("link latency", latency_ticks * tick_ms, "ms",
               "write -> board's memory (<= one downstream sweep + a tick)"),
        Metric("measured iq (board)", stack.mcu_link.read("iq") / 1000.0, "A", "upstream register"),
    ]
    return ScenarioResult(
        "current-step", "q-current step 0 -> 10 A, piston fixed", metrics,
        series={"t_s": t - t0, "iq_a": iq, "id_a": rec[:row, L.Y_ID], "target_a": STEP_A},
        plot=_plot_step,
    )


def _plot_step(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot

    plt = _pyplot()
    s = res.series
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(s["t_s"] * 1e3, s["iq_a"], label="i_q (plant)")
    ax.plot(s["t_s"] * 1e3, s["id_a"], label="i_d (plant)")
    ax.axhline(s["target_a"], color="k", ls=":", lw=0.8)
    ax.set_xlim(-0.5, 5.0)
    ax.set_xlabel("time after the write [ms]")
    ax.set_ylabel("current [A]")
    ax.set_title(res.title)
    ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _sine_fit(x: np.ndarray, w_tick: float) -> complex:
    """Complex amplitude of the component at ``w_tick`` rad/tick (least squares with DC)."""
    k = np.arange(len(x))
    a = np.column_stack([np.cos(w_tick * k), np.sin(w_tick * k), np.ones(len(x))])
    c, s, _ = np.linalg.lstsq(a, x, rcond=None)[0]
    return complex(c, -s)


def closed_loop_response(cfg: Config, freqs_hz: np.ndarray, bias_a: float = BIAS_A,
                         amplitude_a: float = AMPLITUDE_A, progress: Progress = None
                         ) -> np.ndarray:
    """Complex closed-loop gain iq / iq_ref (board's reference -> sampled q current) for
    iq_ref = bias + amplitude sin(2 pi f t), one frequency after the other."""
    stack = FpgaStack(_fixed(cfg))
    stack.boot()
    fs = 1.0 / stack.tick_s
    out = np.empty(len(freqs_hz), dtype=complex)
    iq_addr = B.D_IQ_REF
    amp_ma = amplitude_a * 1000.0
    bias_ma = bias_a * 1000.0
    stack.mcu_link.write("iq_ref", round(bias_ma))
    stack.advance(400)  # let the pressure built by the bias settle
    for j, f in enumerate(freqs_hz):
        w = 2.0 * math.pi * f / fs
        settle = max(int(3 * fs / f), 100)
        n = max(int(10 * fs / f), 400)
        ref = np.empty(n)
        iq = np.empty(n)
        for k in range(settle + n):
            stack.mcu_link.down[iq_addr] = round(bias_ma + amp_ma * math.sin(w * k)) & 0xFFFF
            if k >= settle:
                # The reference the board uses at this tick, and the current it samples.
                ref[k - settle] = stack.board.down_value("iq_ref") / 1000.0
                iq[k - settle] = stack.y[L.Y_IQ]
            stack.advance(1)
        # The board used down[] during advance(1): shift so ref[k] pairs with iq at tick k.
        ref_used = np.empty(n)
        ref_used[:-1] = ref[1:]
        ref_used[-1] = ref[-1]
        out[j] = _sine_fit(iq[:-1], w) / _sine_fit(ref_used[:-1], w)
        if progress:
            progress(j + 1, len(freqs_hz))
    return out


def bandwidth_3db(freqs_hz: np.ndarray, h: np.ndarray) -> float:
    """First frequency at which |h| falls below -3 dB (log interpolation); nan if never."""
    db = 20.0 * np.log10(np.abs(h))
    below = np.nonzero(db < -3.0)[0]
    if len(below) == 0:
        return math.nan
    i = below[0]
    if i == 0:
        return float(freqs_hz[0])
    f0, f1 = math.log(freqs_hz[i - 1]), math.log(freqs_hz[i])
    d0, d1 = db[i - 1], db[i]
    return float(math.exp(f0 + (-3.0 - d0) * (f1 - f0) / (d1 - d0)))


@register("current-bode")
def current_bode(cfg: Config, progress: Progress = None) -> ScenarioResult:
    freqs = np.geomspace(50.0, 5000.0, 15)
    h = closed_loop_response(cfg, freqs, progress=progress)
    h0 = closed_loop_response(cfg, freqs, bias_a=0.0)
    bw = bandwidth_3db(freqs, h)
    db = 20.0 * np.log10(np.abs(h))
    metrics = [
        Metric("-3 dB bandwidth", bw, "Hz",
               f">= {BANDWIDTH_MIN_HZ:.0f} Hz at {BIAS_A:g} A +/- {AMPLITUDE_A:g} A",
               ok=bool(bw >= BANDWIDTH_MIN_HZ)),
        Metric("-3 dB bandwidth about 0 A", bandwidth_3db(freqs, h0), "Hz",
               "informative: dead-time error acts as 0.48 ohm there"),
        Metric("peak gain", float(db.max()), "dB"),
        Metric("phase at 1 kHz", float(np.degrees(np.angle(np.interp(
            1000.0, freqs, h.real) + 1j * np.interp(1000.0, freqs, h.imag)))), "deg"),
    ]
    return ScenarioResult(
        "current-bode", "closed current loop iq_ref -> iq, piston fixed", metrics,
        series={"freq_hz": freqs, "gain_db": db, "phase_deg": np.degrees(np.unwrap(np.angle(h))),
                "bandwidth_hz": bw, "gain0_db": 20.0 * np.log10(np.abs(h0)),
                "phase0_deg": np.degrees(np.unwrap(np.angle(h0)))},
        plot=_plot_bode,
    )


def _plot_bode(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot

    plt = _pyplot()
    s = res.series
    fig, (ag, ap) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ag.semilogx(s["freq_hz"], s["gain_db"], "bo-", ms=4, label=f"{BIAS_A:g} A bias")
    ag.semilogx(s["freq_hz"], s["gain0_db"], "s--", color="0.5", ms=3, label="0 A bias")
    ag.axhline(-3.0, color="r", ls=":", lw=0.8)
    if math.isfinite(s["bandwidth_hz"]):
        ag.axvline(s["bandwidth_hz"], color="r", ls="--", lw=0.8,
                   label=f"-3 dB at {s['bandwidth_hz']:.0f} Hz")
    ag.legend()
    ag.set_ylabel("gain [dB]")
    ap.semilogx(s["freq_hz"], s["phase_deg"], "bo-", ms=4)
    ap.semilogx(s["freq_hz"], s["phase0_deg"], "s--", color="0.5", ms=3)
    ap.set_ylabel("phase [deg]")
    ap.set_xlabel("frequency [Hz]")
    ag.set_title(res.title)
    for a in (ag, ap):
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
