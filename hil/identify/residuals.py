"""Residual analysis on the held-out validation part.

Per channel:

* **whiteness** — autocorrelation at lags 1..50 with the 99 % bounds ``+-2.576/sqrt(N)``, and
  the Ljung-Box Q over those lags; a channel is white when Q's p-value exceeds
  ``0.01 / (number of channels judged)`` (Bonferroni);
* **cross-correlation with the input** ``iq`` at lags 0..50 (input leading), same bounds;
* **residual against state** — binned means against pump velocity (from the encoder),
  piston position, oil temperature and rotor angle (mod 2 pi), each with the largest
  |mean| / standard error, the standard error inflated by the residual's correlation length;
* **order spectrum** — amplitude of the residual at orders 0.25..10 of the rotor angle,
  ``2/N |sum r_k exp(-i n theta_k)|``: a pulsation is an order of the angle, so it shows
  here at its order even though its frequency changes with speed;
* the strongest **frequency** of the residual (for describing what is left);
* the **predictable share**: the part of the residual variance an AR(20) model predicts
  from the residual's own past (about 20/N for white noise). Structure counts as material
  when this share exceeds 1 %: a long record makes any imperfection statistically
  significant, and the verdict ``unexplained`` should be about structure that matters.

The verdict "white" uses the channels whose measurement noise is white by construction:
pressures and strain force. The encoder speeds are differences of quantised angles, whose
residual is coloured even for a perfect model; they are judged instead by their **excess
over the quantisation floor**: a window difference of an encoder with count ``q`` carries
``q / sqrt(6) / (W dt)`` rms of pure quantisation noise, and a residual above 1.5 times that
is structure (a backlash, a slipping coupling, a model error).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hil.identify import stats
from hil.identify.experiment import Experiment, quantum

MAX_LAG = 50
Z99 = 2.5758293035489
JUDGED = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "f_strain")
SPEEDS = {"omega_m": "theta_m", "v_piston": "x_piston"}
#: Residual rms of an encoder speed above this multiple of its quantisation floor is structure.
MAX_FLOOR_RATIO = 1.5
ORDERS = np.arange(0.25, 10.0 + 1e-9, 0.25)


@dataclass
class ChannelResidual:
    """Residual diagnostics of one channel on the validation part."""

    channel: str
    rms: float
    acf: np.ndarray
    acf_outside: int  # lags outside the 99 % bound
    ljung_box_q: float
    ljung_box_p: float
    ccf: np.ndarray
    ccf_outside: int
    judged: bool
    white: bool = False
    vs_state: dict[str, dict] = field(default_factory=dict)
    order_amp: np.ndarray | None = None
    peak_order: float = 0.0
    peak_order_ratio: float = 0.0  # peak amplitude / median amplitude over orders
    peak_hz: float = 0.0
    peak_hz_ratio: float = 0.0  # spectral peak / median of the spectrum
    floor_ratio: float = 0.0  # encoder speeds: residual rms / quantisation floor (0: n/a)
    predictable_share: float = 0.0  # AR(20) one-step predictable share of the variance

    def summary(self) -> dict:
        return {
            "channel": self.channel, "rms": self.rms, "white": self.white,
            "judged": self.judged, "ljung_box_q": self.ljung_box_q,
            "ljung_box_p": self.ljung_box_p, "acf_lags_outside_99": self.acf_outside,
            "ccf_lags_outside_99": self.ccf_outside,
            "peak_order": self.peak_order, "peak_order_ratio": self.peak_order_ratio,
            "peak_hz": self.peak_hz, "peak_hz_ratio": self.peak_hz_ratio,
            "floor_ratio": self.floor_ratio, "predictable_share": self.predictable_share,
            "vs_state_max_z": {k: v["max_z"] for k, v in self.vs_state.items()},
        }


@dataclass
class ResidualAnalysis:
    """Diagnostics of every channel; ``white`` is the verdict over the judged channels."""

    channels: dict[str, ChannelResidual]
    white: bool
    n: int
    bound: float

    def summary(self) -> dict:
        return {"white": self.white, "n": self.n, "bound_99": self.bound,
                "channels": {c: r.summary() for c, r in self.channels.items()}}


def _binned(x: np.ndarray, r: np.ndarray, corr_len: int, bins: int = 16,
            periodic: bool = False) -> dict:
    """Binned means of ``r`` against ``x`` and the largest |mean|/se."""
    if periodic:
        edges = np.linspace(0, 2 * np.pi, bins + 1)
        xv = np.mod(x, 2 * np.pi)
    else:
        lo, hi = np.percentile(x, [1, 99])
        if not hi > lo:
            return {"centres": [], "mean": [], "se": [], "max_z": 0.0}
        edges = np.linspace(lo, hi, bins + 1)
        xv = x
    idx = np.clip(np.digitize(xv, edges) - 1, 0, bins - 1)
    centres, means, ses = [], [], []
    sd = float(np.std(r))
    for b in range(bins):
        sel = idx == b
        m = int(sel.sum())
        if m < 20:
            continue
        n_eff = max(m / max(corr_len, 1), 1.0)
        centres.append(0.5 * (edges[b] + edges[b + 1]))
        means.append(float(r[sel].mean()))
        ses.append(sd / np.sqrt(n_eff))
    z = max((abs(m) / s for m, s in zip(means, ses, strict=True) if s > 0), default=0.0)
    return {"centres": centres, "mean": means, "se": ses, "max_z": float(z)}


def order_spectrum(r: np.ndarray, angle: np.ndarray, orders: np.ndarray = ORDERS) -> np.ndarray:
    """Amplitude ``2/N |sum r exp(-i n angle)|`` at each order ``n`` of the rotor angle."""
    r = r - r.mean()
    out = np.empty(orders.size)
    for i, o in enumerate(orders):
        out[i] = 2.0 / r.size * abs(np.sum(r * np.exp(-1j * o * angle)))
    return out


def spectrum_peak(r: np.ndarray, fs: float) -> tuple[float, float]:
    """(frequency Hz, peak / median) of the residual's Welch spectrum above 1 Hz."""
    from scipy.signal import welch

    nper = int(min(r.size, 2 ** int(np.log2(fs))))  # about 1 s segments
    f, p = welch(r - r.mean(), fs=fs, nperseg=nper)
    sel = f >= 1.0
    if not sel.any():
        return 0.0, 0.0
    f, p = f[sel], p[sel]
    k = int(np.argmax(p))
    med = float(np.median(p))
    return float(f[k]), float(p[k] / med) if med > 0 else 0.0


def predictable_share(r: np.ndarray, order: int = 20) -> float:
    """1 - (one-step AR(``order``) prediction error variance) / (residual variance)."""
    r = r - r.mean()
    n = r.size
    if n <= 4 * order:
        return 0.0
    x = np.column_stack([r[order - k - 1: n - k - 1] for k in range(order)])
    y = r[order:]
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    e = y - x @ coef
    v = float(y @ y)
    return float(1.0 - (e @ e) / v) if v > 0 else 0.0


def analyse(exp: Experiment, residual: dict[str, np.ndarray], mask: np.ndarray
            ) -> ResidualAnalysis:
    """Diagnostics of ``residual`` (measured - model, per channel) on the samples ``mask``."""
    iq = exp.iq[mask]
    n = int(mask.sum())
    bound = Z99 / np.sqrt(n)
    judged = [c for c in exp.channels if c in JUDGED]
    out: dict[str, ChannelResidual] = {}
    speed = (exp.measured["omega_m"][mask] / exp.const.rotor_per_m
             if "omega_m" in exp.measured else None)
    all_white = True
    for c in exp.channels:
        r = residual[c][mask]
        ok = np.isfinite(r)
        r = np.where(ok, r, 0.0)
        a = stats.acf(r, MAX_LAG)
        q, p = stats.ljung_box(r, MAX_LAG)
        x = stats.ccf(r, iq, MAX_LAG)
        is_judged = c in judged
        res = ChannelResidual(c, float(np.sqrt(np.mean(r * r))), a,
                              int(np.sum(np.abs(a) > bound)), q, p, x,
                              int(np.sum(np.abs(x) > bound)), is_judged)
        res.white = p > 0.01 / max(len(judged), 1)
        res.predictable_share = predictable_share(r)
        if c in SPEEDS and SPEEDS[c] in exp.data.columns:
            q_enc = quantum(exp.data.col(SPEEDS[c]))
            if q_enc > 0:
                floor = q_enc / np.sqrt(6.0) / (exp.speed_window * exp.dt)
                res.floor_ratio = res.rms / floor
                res.judged = is_judged = True
                res.white = res.floor_ratio < MAX_FLOOR_RATIO
        if is_judged and not res.white:
            all_white = False
        corr_len = stats.correlation_length(r, 400)
        if speed is not None:
            res.vs_state["pump_velocity"] = _binned(speed, r, corr_len)
        if exp.position is not None and exp.load != "fixed":
            res.vs_state["piston_position"] = _binned(exp.position[mask], r, corr_len)
        if exp.temperature is not None:
            res.vs_state["temperature"] = _binned(exp.temperature[mask], r, corr_len)
        res.vs_state["time"] = _binned(exp.data.t[mask], r, corr_len)
        if exp.angle is not None:
            res.vs_state["rotor_angle"] = _binned(exp.angle[mask], r, corr_len, periodic=True)
            amp = order_spectrum(r, exp.angle[mask])
            res.order_amp = amp
            k = int(np.argmax(amp))
            res.peak_order = float(ORDERS[k])
            med = float(np.median(amp))
            res.peak_order_ratio = float(amp[k] / med) if med > 0 else 0.0
        res.peak_hz, res.peak_hz_ratio = spectrum_peak(r, exp.data.sample_rate_hz)
        out[c] = res
    return ResidualAnalysis(out, all_white and bool(judged), n, float(bound))


__all__ = ["ChannelResidual", "ResidualAnalysis", "analyse", "order_spectrum"]
