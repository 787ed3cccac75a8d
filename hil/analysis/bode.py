"""Open-loop frequency responses of the plant: simulated, and analytic (thesis Eq. 2.32-2.38).

Two experiments of thesis 2.4.3:

* piston fixed, tau_p -> tau_q, analytic ``d_s k_s / G_1(s)`` (Eq. 2.32, 2.36);
* piston free, tau_p -> piston velocity, analytic ``d_s k_s / G_3(s)`` (Eq. 2.34).

``G_3`` as printed in the thesis (Eq. 2.38) carries an overall sign and two term signs
that do not follow from Eq. 2.28-2.31: its leading and constant coefficients differ in sign,
so it has a right-half-plane root (far above the band of interest) and a DC gain 7 % off;
between 1 and 300 Hz it stays within 0.7 dB and 5 deg of the re-derived form.
Eliminating theta_p, theta_q from the same equations gives

    G_3(s) = (J_c s + d_c) G_1(s) + (J_p s + d_p) d_s k_s

which is what :func:`g3` returns; docs/plant.md shows the derivation.

The simulation excites the plant with an ideal pump force (``DriveMode.FORCE``): a multisine
whose components sit on the DFT grid of one period, so each frequency is read exactly by
one DFT bin after the transient has died out. The input is a zero-order-hold staircase (one
value per tick); its fundamental is computed from the samples with the exact ZOH factor
``(1 - e^{-jwh}) / (jwh)``, and each output sample carries its true time stamp (the end of
its tick), so the comparison with the continuous model holds no half-tick bias.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plant.config import Config
from plant.layout import OUTPUT_NAMES, Y_TAU_Q, Y_V_PISTON
from plant.model import Plant


@dataclass(frozen=True)
class LinearParams:
    """The linear model's parameters (Table 2.1), SI units, piston-equivalent."""

    jp: float
    jc: float
    dp: float
    dc: float
    ds: float
    ks: float

    @classmethod
    def from_config(cls, cfg: Config) -> LinearParams:
        h = cfg.section("hydraulics")
        return cls(h["jp_kg"], h["jc_kg"], h["dp_ns_per_m"], h["dc_ns_per_m"],
                   h["ds_ns_per_m"], h["ks_n_per_m"])


def g1(s: np.ndarray, m: LinearParams) -> np.ndarray:
    """G_1(s), Eq. 2.36."""
    return m.jp * m.ds * s**2 + (m.jp * m.ks + m.dp * m.ds) * s + (m.dp + m.ds) * m.ks


def g3(s: np.ndarray, m: LinearParams) -> np.ndarray:
    """G_3(s) re-derived from Eq. 2.28-2.31 (see module docstring)."""
    return (m.jc * s + m.dc) * g1(s, m) + (m.jp * s + m.dp) * m.ds * m.ks


def analytic_fixed(freq_hz: np.ndarray, m: LinearParams) -> np.ndarray:
    """tau_q / tau_p with the piston fixed: d_s k_s / G_1(jw), dimensionless."""
    s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
    return m.ds * m.ks / g1(s, m)


def analytic_free(freq_hz: np.ndarray, m: LinearParams) -> np.ndarray:
    """piston velocity / tau_p with the piston free: d_s k_s / G_3(jw), (m/s)/N."""
    s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
    return m.ds * m.ks / g3(s, m)


@dataclass
class BodeResult:
    """One frequency response: simulated and analytic complex gains at ``freq_hz``."""

    load: str  # "fixed" or "free"
    output: str  # "tau_q" (N/N) or "v_piston" ((m/s)/N)
    freq_hz: np.ndarray
    simulated: np.ndarray
    analytic: np.ndarray
    params: LinearParams

    def analytic_at(self, freq_hz: np.ndarray) -> np.ndarray:
        """The analytic response at other frequencies (for smooth plots)."""
        fn = analytic_fixed if self.load == "fixed" else analytic_free
        return fn(freq_hz, self.params)

    @staticmethod
    def db(h: np.ndarray) -> np.ndarray:
        return 20.0 * np.log10(np.abs(h))

    @staticmethod
    def deg(h: np.ndarray) -> np.ndarray:
        return np.degrees(np.angle(h))

    def gain_error_db(self) -> np.ndarray:
        return self.db(self.simulated) - self.db(self.analytic)

    def phase_error_deg(self) -> np.ndarray:
        d = np.angle(self.simulated / self.analytic)
        return np.degrees(d)

    def peak_hz(self, which: str = "simulated") -> float:
        """Frequency of the largest gain among the measured points."""
        h = self.simulated if which == "simulated" else self.analytic
        return float(self.freq_hz[int(np.argmax(np.abs(h)))])

    def rows(self) -> list[dict[str, float]]:
        out = []
        for i, f in enumerate(self.freq_hz):
            out.append(
                {
                    "freq_hz": float(f),
                    "sim_gain_db": float(self.db(self.simulated[i])),
                    "sim_phase_deg": float(self.deg(self.simulated[i])),
                    "model_gain_db": float(self.db(self.analytic[i])),
                    "model_phase_deg": float(self.deg(self.analytic[i])),
                }
            )
        return out


def log_grid(f_min: float, f_max: float, points: int, period_s: float = 1.0) -> np.ndarray:
    """Log-spaced frequencies rounded onto the 1/period grid, unique and sorted, Hz."""
    df = 1.0 / period_s
    raw = np.geomspace(f_min, f_max, points)
    grid = np.unique(np.maximum(np.round(raw / df), 1) * df)
    return grid


def _schroeder_phases(n: int) -> np.ndarray:
    """Schroeder phases keep a multisine's crest factor low."""
    k = np.arange(1, n + 1)
    return -np.pi * k * (k - 1) / n


def simulate_bode(
    cfg: Config,
    load: str,
    freq_hz: np.ndarray,
    amplitude_n: float = 20.0,
    settle_s: float = 0.4,
    period_s: float = 1.0,
    x0_m: float = 0.0,
) -> BodeResult:
    """Excite the configured plant with a multisine pump force and read its response.

    ``load`` is "fixed" (output tau_q) or "free" (output piston velocity); it overrides
    ``load.kind`` of ``cfg``; ``x0_m`` is the piston position (about mid-stroke) it starts
    at. Frequencies must lie on the 1/``period_s`` grid.
    """
    if load not in ("fixed", "free"):
        raise ValueError(f"load must be 'fixed' or 'free', not {load!r}")
    cfg = cfg.with_overrides({"load.kind": load, "load.x0_m": x0_m}, source=f"bode {load}")
    plant = Plant(cfg)
    freq_hz = np.asarray(freq_hz, dtype=float)
    h = plant.tick_s
    n_period = int(round(period_s / h))
    n_settle = int(round(settle_s / period_s)) * n_period or n_period
    n_total = n_settle + n_period
    cycles = np.round(freq_hz * period_s).astype(int)
    if np.any(np.abs(cycles / period_s - freq_hz) > 1e-9) or len(set(cycles)) != len(cycles):
        raise ValueError("frequencies must be distinct multiples of 1/period_s")
    w = 2.0 * np.pi * freq_hz
    phases = _schroeder_phases(len(freq_hz))
    k = np.arange(n_total)
    t_in = k * h
    u = amplitude_n * np.sin(np.outer(t_in, w) + phases).sum(axis=1)

    col = Y_TAU_Q if load == "fixed" else Y_V_PISTON
    y = np.zeros(n_total)
    for i in range(n_total):
        plant.set_force(u[i])
        plant.advance(1)
        y[i] = plant.y[col]

    sl = slice(n_settle, n_total)
    t_u = t_in[sl]
    t_y = t_u + h  # output sample i is taken at the end of tick i
    e_u = np.exp(-1j * np.outer(w, t_u))
    e_y = np.exp(-1j * np.outer(w, t_y))
    u_samples = e_u @ u[sl]
    zoh = (1.0 - np.exp(-1j * w * h)) / (1j * w * h)
    u_cont = u_samples * zoh
    y_cont = e_y @ y[sl]
    simulated = y_cont / u_cont
    m = LinearParams.from_config(cfg)
    analytic = analytic_fixed(freq_hz, m) if load == "fixed" else analytic_free(freq_hz, m)
    return BodeResult(load, OUTPUT_NAMES[col], freq_hz, simulated, analytic, m)
