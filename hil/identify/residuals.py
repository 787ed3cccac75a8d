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
  from the residual's own past, per degree of freedom left (about 0 for white noise).
  Structure counts as material when this share exceeds 1 %: a long record makes any
  imperfection statistically significant, and the verdict ``unexplained`` should be about
  structure that matters.

The verdict "white" uses the channels whose measurement noise is white by construction:
pressures and strain force. The encoder speeds are differences of quantised angles, whose
residual is coloured even for a perfect model; they are judged instead by their **excess
over the quantisation floor**: a window difference of an encoder with count ``q`` carries
``q / sqrt(6) / (W dt)`` rms of pure quantisation noise, and a residual above 1.5 times that
is structure (a backlash, a slipping coupling, a model error) when its excess over the floor
is material too: at least 1 % of the speed's own rms. The floor falls with the sample rate
(it is a count per window), so at 1 kHz a parameter the record cannot pin, held at its
configured value, leaves a speed error of a fraction of a percent several floors high.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hil.identify import stats
from hil.identify.experiment import Experiment, quantum

MAX_LAG = 50
Z99 = 2.5758293035489
JUDGED = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "f_strain")
PAIRS = (("p_pump_a", "p_pump_b"), ("p_cyl_a", "p_cyl_b"))
SPEEDS = {"omega_m": "theta_m", "v_piston": "x_piston"}
#: Residual rms of an encoder speed above this multiple of its quantisation floor is structure.
MAX_FLOOR_RATIO = 1.5
#: ... and its excess over that floor, as a share of the speed's rms, above this is material.
MATERIAL_EXCESS = 0.01
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
    excess_share: float = 0.0  # encoder speeds: rms beyond the floor / the speed's rms
    predictable_share: float = 0.0  # AR(20) one-step predictable share of the variance

    def summary(self) -> dict:
        return {
            "channel": self.channel, "rms": self.rms, "white": self.white,
            "judged": self.judged, "ljung_box_q": self.ljung_box_q,
            "ljung_box_p": self.ljung_box_p, "acf_lags_outside_99": self.acf_outside,
            "ccf_lags_outside_99": self.ccf_outside,
            "peak_order": self.peak_order, "peak_order_ratio": self.peak_order_ratio,
            "peak_hz": self.peak_hz, "peak_hz_ratio": self.peak_hz_ratio,
            "floor_ratio": self.floor_ratio, "excess_share": self.excess_share,
            "predictable_share": self.predictable_share,
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
    basis = _order_basis(angle, orders) if angle.size * orders.size <= BASIS_MAX else None
    out = np.empty(orders.size)
    for i, o in enumerate(orders):
        e = basis[i] if basis is not None else np.exp(-1j * o * angle)
        out[i] = 2.0 / r.size * abs(np.sum(r * e))
    return out


#: Most complex values of the kept order basis (64 MB; a 16 s record's validation part at
#: 5 kHz takes a third of it; longer records compute it channel by channel).
BASIS_MAX = 4_000_000


def _order_basis(angle: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """``exp(-i n angle)`` for every order: one record's channels and analyses share one
    angle, and the complex exponentials were most of the spectrum's time (the last one is
    kept)."""
    key = (angle.size, hash(angle.tobytes()), orders.tobytes())
    hit = _BASIS.get("last")  # one tuple, swapped whole
    if hit is None or hit[0] != key:
        hit = (key, np.stack([np.exp(-1j * o * angle) for o in orders]))
        _BASIS["last"] = hit
    return hit[1]


_BASIS: dict[str, tuple] = {}


def _nperseg(n: int, fs: float) -> int:
    return int(min(n, 2 ** int(np.log2(fs))))  # about 1 s segments


def spectrum_peak(r: np.ndarray, fs: float, half_width_hz: float = 15.0) -> tuple[float, float]:
    """(frequency Hz, ratio) of the residual's most prominent narrow peak above 1 Hz: each
    bin of the Welch spectrum is judged against the median of its neighbourhood
    (+-``half_width_hz``, the bin and its direct neighbours left out), so the highest random
    bin of a broad hump does not read as a line."""
    from scipy.ndimage import median_filter
    from scipy.signal import welch

    f, p = welch(r - r.mean(), fs=fs, nperseg=_nperseg(r.size, fs))
    if f.size < 8:
        return 0.0, 0.0
    df = float(f[1] - f[0])
    half = max(3, int(round(half_width_hz / df)))
    fp = np.ones(2 * half + 1, dtype=bool)
    fp[half - 1: half + 2] = False
    local = median_filter(p, footprint=fp, mode="reflect")
    sel = f >= 1.0
    ratio = np.where(local > 0, p / np.where(local > 0, local, 1.0), 0.0)
    ratio[~sel] = 0.0
    k = int(np.argmax(ratio))
    return float(f[k]), float(ratio[k])


def whiten(r: np.ndarray, noise_part: np.ndarray | None, fs: float) -> np.ndarray:
    """``r`` divided, bin by bin, by the spectrum a right model leaves: a white sensor floor
    plus what input noise through the model makes (``noise_part``, see
    :mod:`hil.identify.noise`). Returns ``r`` unchanged when there is no noise part.

    ``noise_part`` of several rows is that many draws of the input noise's part
    (:func:`hil.identify.noise.predicted_draws`): the spectrum is then their mean's shape at
    the level the residual itself holds, within the draws' spread (:func:`draws_target`)."""
    from scipy.signal import welch

    if noise_part is None or not np.any(noise_part):
        return r
    nper = _nperseg(r.size, fs)
    f, pr = welch(r - r.mean(), fs=fs, nperseg=nper)
    if noise_part.ndim == 2:
        pds = np.stack([welch(d - d.mean(), fs=fs, nperseg=nper)[1] for d in noise_part])
        target = draws_target(pr, pds)
    else:
        _, pd = welch(noise_part - noise_part.mean(), fs=fs, nperseg=nper)
        target = _floor(pr, pd) + pd
    n = r.size
    fr = np.fft.rfftfreq(n, 1.0 / fs)
    w = 1.0 / np.sqrt(np.interp(fr, f, target))
    return np.fft.irfft(np.fft.rfft(r - r.mean()) * w, n)


def _floor(pr: np.ndarray, pd: np.ndarray) -> float:
    """The sensor's own floor: what the residual's spectrum ``pr`` holds beyond the
    predicted input-noise part ``pd`` (a twentieth of its median at least)."""
    return max(float(np.median(pr - pd)), 0.05 * float(np.median(pr)), 1e-300)


#: Levels of the input-noise part tried between the draws' lowest and highest power.
DRAW_LEVELS = 17


def draws_target(pr: np.ndarray, pds: np.ndarray) -> np.ndarray:
    """The spectrum a right model leaves when its input-noise part is known only in
    distribution: the residual's spectrum ``pr`` against ``floor + c mean(pds)``, the mean
    of the draws' spectra ``pds`` (draws x bins) scaled by the level ``c`` that fits ``pr``
    best (Whittle's likelihood, ``sum log t + pr/t``), ``c`` within the draws' own powers
    relative to their mean (the record's realisation is one more draw: a level beyond the
    strongest draw's is not granted), the floor as :func:`whiten` takes it for that level.

    Through a seal that holds the piston the part is intermittent: one draw's spectrum
    says little about the record's (docs/identify.md, *The conrod triple at seed 2: what
    the 11 % at the rig's basin is*)."""
    pd = pds.mean(axis=0)
    total = float(pd.sum())
    if not total > 0:
        return _floor(pr, pd) + pd
    powers = pds.sum(axis=1) / total
    best: tuple[float, np.ndarray] | None = None
    for c in np.geomspace(max(float(powers.min()), 1e-6), max(float(powers.max()), 1e-6),
                          DRAW_LEVELS):
        t = _floor(pr, c * pd) + c * pd
        nll = float(np.sum(np.log(t) + pr / t))
        if best is None or nll < best[0]:
            best = (nll, t)
    return best[1]


def predictable_share(r: np.ndarray, order: int = 20) -> float:
    """1 - (one-step AR(``order``) prediction error variance) / (residual variance), the
    error variance per degree of freedom left (an adjusted R^2): in-sample, ``order``
    coefficients fitted to white noise predict ``order/n`` of it by chance, 0.7 % of a 3 s
    validation part at 1 kHz, near the 1 % that counts as material."""
    r = r - r.mean()
    n = r.size
    if n <= 4 * order:
        return 0.0
    x = np.column_stack([r[order - k - 1: n - k - 1] for k in range(order)])
    y = r[order:]
    # least squares by the (order x order) normal equations: an SVD of the n x order matrix
    # took most of the residual analysis' time
    coef, *_ = np.linalg.lstsq(x.T @ x, x.T @ y, rcond=None)
    e = y - x @ coef
    v = float(y @ y)
    m = y.size
    return float(1.0 - (e @ e) / (m - order) / (v / m)) if v > 0 else 0.0


def analyse(exp: Experiment, residual: dict[str, np.ndarray], mask: np.ndarray,
            noise_part: dict[str, np.ndarray] | None = None) -> ResidualAnalysis:
    """Diagnostics of ``residual`` (measured - model, per channel) on the samples ``mask``.

    ``noise_part`` (per channel, full length, or draws x full length) is what the logged
    current's own noise makes through the model (:mod:`hil.identify.noise`): whiteness and
    predictability are judged on the residual whitened by it (:func:`whiten`), encoder
    speeds against their floor plus its mean power."""
    iq = exp.iq[mask]
    n = int(mask.sum())
    bound = Z99 / np.sqrt(n)
    residual = dict(residual)
    noise_part = dict(noise_part) if noise_part is not None else None
    channels = list(exp.channels)
    # A pressure pair is judged by its difference: each side sees the load only while its
    # side is the high one, so the input noise it carries switches on and off with the sign
    # of the load; the difference k_c (p_a - p_b) is the whole load, a stationary signal.
    paired = set()
    for a_, b_ in PAIRS:
        if a_ in residual and b_ in residual:
            name = f"{a_}-{b_}"
            residual[name] = residual[a_] - residual[b_]
            if noise_part is not None and a_ in noise_part and b_ in noise_part:
                noise_part[name] = noise_part[a_] - noise_part[b_]
            channels.append(name)
            paired |= {a_, b_}
    judged = [c for c in channels if (c in JUDGED and c not in paired) or "-" in c]
    out: dict[str, ChannelResidual] = {}
    speed = (exp.measured["omega_m"][mask] / exp.const.rotor_per_m
             if "omega_m" in exp.measured else None)
    all_white = True
    for c in channels:
        r = residual[c][mask]
        ok = np.isfinite(r)
        r = np.where(ok, r, 0.0)
        d = None
        if noise_part is not None and c in noise_part:
            d = np.nan_to_num(noise_part[c][..., mask])
        fs = exp.data.sample_rate_hz
        rw = whiten(r, d, fs) if c not in SPEEDS else r
        a = stats.acf(rw, MAX_LAG)
        q, p = stats.ljung_box(rw, MAX_LAG)
        x = stats.ccf(rw, iq, MAX_LAG)
        is_judged = c in judged
        res = ChannelResidual(c, float(np.sqrt(np.mean(r * r))), a,
                              int(np.sum(np.abs(a) > bound)), q, p, x,
                              int(np.sum(np.abs(x) > bound)), is_judged)
        res.white = p > 0.01 / max(len(judged), 1)
        res.predictable_share = predictable_share(rw)
        if c in SPEEDS and SPEEDS[c] in exp.data.columns:
            q_enc = quantum(exp.data.col(SPEEDS[c]))
            if q_enc > 0:
                floor = q_enc / np.sqrt(6.0) / (exp.speed_window * exp.dt)
                expected = floor * floor + (float(np.mean(d * d)) if d is not None else 0.0)
                res.floor_ratio = res.rms / np.sqrt(expected)
                speed_rms = float(np.nanstd(exp.measured[c][mask]))
                res.excess_share = (float(np.sqrt(max(res.rms ** 2 - expected, 0.0))) / speed_rms
                                    if speed_rms > 0 else np.inf)
                res.judged = is_judged = True
                res.white = (res.floor_ratio < MAX_FLOOR_RATIO
                             or res.excess_share < MATERIAL_EXCESS)
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
        res.peak_hz, res.peak_hz_ratio = spectrum_peak(rw, fs)
        out[c] = res
    return ResidualAnalysis(out, all_white and bool(judged), n, float(bound))


__all__ = ["ChannelResidual", "ResidualAnalysis", "analyse", "order_spectrum"]
