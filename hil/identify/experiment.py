"""One identification experiment prepared for fitting: constants, channels, schedules, split.

Turns a :class:`~hil.identify.csvdata.MeasuredData` record and an actuator preset into what
the fast model and the fit need:

* the constants the fit does not touch (thesis Table 2.1: J_p, J_c, k_c, k_p; the stroke;
  the regularisation velocities of the friction models) and the starting values of the
  fitted ones (d_s, d_p, d_c, k_s, the current-to-force gain, the rod stiffness);
* the output channels compared with the model: every pressure present (gauge, Pa), the strain
  force (N), and the motor and piston speeds as windowed differences of the encoder angles
  (``omega_m`` rad/s from ``theta_m``, ``v_piston`` m/s from ``x_piston``), because an
  integrating position output accumulates any model error while its difference does not;
* the measured scheduling signals the effects use (rotor angle, piston position, oil
  temperature), smoothed where the sensor is coarse;
* the accumulator precharge (the low side of each pressure pair sits on it), a noise level
  per channel, the saturation plateaus of each channel;
* the split: a burn-in, an estimation part (first 60 %) and a held-out validation part.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hil.identify.csvdata import LOAD_CASES, MeasuredData
from plant.config import Config
from plant.model import motor_torque_constant

PRESSURES = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b")
#: Window of the encoder differences, samples at 5 kHz (2 ms: averages the encoder
#: quantisation, first null at 500 Hz); scaled with the sample rate.
SPEED_WINDOW_S = 2e-3
#: Share of the record used for estimation; the rest is the held-out validation part.
ESTIMATION_SHARE = 0.6
BURN_IN_S = 0.1


@dataclass
class Constants:
    """Parameters the fit holds fixed (SI, piston-equivalent; thesis Table 2.1)."""

    jp: float  # J_p, kg
    jc: float  # J_c, kg
    kc: float  # k_c, m^2
    kp: float  # k~_p, m^3/rad
    half_stroke: float  # m
    eps_pump: float  # tanh regularisation of the pump Coulomb friction, m/s
    eps_seal: float  # tanh regularisation of the seal friction, m/s
    vs_seal: float  # Stribeck velocity, m/s
    bulk_modulus: float = 0.0  # kappa, Pa (only to express k_s(x) as an oil volume)

    @property
    def rotor_per_m(self) -> float:
        """k_c / k~_p: rotor rad per metre of piston-equivalent pump travel."""
        return self.kc / self.kp


@dataclass
class Experiment:
    """A record ready for the fast model (see the module docstring)."""

    data: MeasuredData
    load: str  # plant load kind: fixed | free | conrod
    const: Constants
    start: dict[str, float]  # starting values of the baseline parameters
    channels: list[str]
    measured: dict[str, np.ndarray]  # channel -> measured signal (speeds already differenced)
    sigma0: dict[str, float]  # channel -> first noise/scale guess for weighting
    precharge: float  # Pa gauge
    angle: np.ndarray | None  # measured rotor angle, rad
    position: np.ndarray | None  # measured piston position, m
    temperature: np.ndarray | None  # smoothed oil temperature, degC
    #: temperature at which the dampers hold, degC: the preset's oil reference temperature,
    #: where its own damper values hold, so a damper held at the preset and the fitted ones
    #: (once the viscosity law is in) refer to one temperature
    t_ref: float
    speed_window: int  # samples
    est: np.ndarray  # boolean mask, estimation samples
    val: np.ndarray  # boolean mask, validation samples
    plateaus: dict[str, float] = field(default_factory=dict)  # channel -> clip level
    notes: list[str] = field(default_factory=list)
    #: the input between samples: zoh | foh | bl (:mod:`hil.identify.intersample`)
    intersample: str = "zoh"
    intersample_reason: str = ""
    #: the baseline's skew ended at its upper bound (the outputs lag by more than T/2)
    skew_at_bound: bool = False

    @property
    def n(self) -> int:
        return self.data.n

    @property
    def dt(self) -> float:
        return self.data.dt

    @property
    def iq(self) -> np.ndarray:
        return self.data.col("iq")

    def window_diff(self, y: np.ndarray) -> np.ndarray:
        """(y[k] - y[k - W]) / (W dt); the first W samples are NaN."""
        w = self.speed_window
        out = np.full(y.shape, np.nan)
        out[w:] = (y[w:] - y[:-w]) / (w * self.dt)
        return out


def _smooth(y: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (edges use the available samples)."""
    if n <= 1:
        return y.copy()
    k = np.ones(n)
    num = np.convolve(y, k, mode="same")
    den = np.convolve(np.ones_like(y), k, mode="same")
    return num / den


def quantum(y: np.ndarray) -> float:
    """The converter's step (LSB) if every sample of ``y`` lies on one grid, else 0.

    The grid is found from the sample-to-sample changes, not from the sorted distinct values
    (a long stroke at 5 nm visits far more codes than the record has samples): the smallest
    change is the LSB or a small multiple of it when the signal never moves by one count
    between samples, so ``q = d_min / m`` for the first ``m`` in 1..8 that puts all samples
    (relative to the first) on integer multiples of ``q``.
    """
    y = np.asarray(y, dtype=float)
    d = np.abs(np.diff(y))
    scale = float(np.max(np.abs(y))) if y.size else 0.0
    d = d[d > 1e-12 * max(scale, 1e-300)]
    if d.size < 3:
        return 0.0
    d_min = float(np.min(d))
    rel = y - y[0]
    for m in range(1, 9):
        q = d_min / m
        r = rel / q
        # a float grid k*q carries rounding of about eps*|y|/q counts
        tol = 1e-3 + 1e-12 * scale / q
        if np.mean(np.abs(r - np.round(r)) < tol) >= 0.999:
            return q
    return 0.0


def _plateau(y: np.ndarray) -> float | None:
    """Clip level if ``y`` sits at its maximum for >= 0.1 % of the samples (and >= 10)."""
    top = float(y.max())
    span = float(y.max() - np.median(y))
    if span <= 0:
        return None
    tol = max(quantum(y) * 0.5, 1e-9 * abs(top))
    count = int(np.count_nonzero(y >= top - tol))
    if count >= max(10, int(1e-3 * y.size)):
        return top
    return None


def prepare(data: MeasuredData, cfg: Config, intersample: str = "zoh") -> Experiment:
    """Build the :class:`Experiment` for ``data`` with constants and start values of ``cfg``;
    the input is taken to behave between samples as ``intersample`` says."""
    h = cfg.section("hydraulics")
    eff = cfg.section("effects")
    load = LOAD_CASES[data.load]
    const = Constants(
        jp=h["jp_kg"], jc=h["jc_kg"], kc=h["kc_m2"], kp=h["kp_m3_per_rad"],
        half_stroke=h["stroke_m"] / 2,
        eps_pump=eff["pump_coulomb"]["velocity_eps_m_per_s"],
        eps_seal=eff["seal_friction"]["velocity_eps_m_per_s"],
        vs_seal=eff["seal_friction"]["stribeck_velocity_m_per_s"],
        bulk_modulus=h["bulk_modulus_pa"],
    )
    gain = motor_torque_constant(cfg) * const.kc / const.kp  # N/A, piston-equivalent
    start = {
        "gain_n_per_a": gain, "ds": h["ds_ns_per_m"], "dp": h["dp_ns_per_m"],
        "dc": h["dc_ns_per_m"], "ks": h["ks_n_per_m"], "jp": h["jp_kg"], "jc": h["jc_kg"],
        "k_rod": cfg.get("load.conrod_stiffness_n_per_m"),
        "c_rod": cfg.get("load.conrod_damping_ns_per_m"), "strain_offset_n": 0.0,
    }
    notes: list[str] = []
    fs = data.sample_rate_hz
    w = max(1, int(round(SPEED_WINDOW_S * fs)))
    cols = data.columns
    pres = [c for c in PRESSURES if c in cols]
    if "p_acc" in cols:
        precharge = float(np.mean(cols["p_acc"]))
    elif pres:
        lows = [np.minimum(cols[a], cols[b]) for a, b in (("p_pump_a", "p_pump_b"),
                                                           ("p_cyl_a", "p_cyl_b"))
                if a in cols and b in cols]
        precharge = float(np.mean(np.concatenate(lows))) if lows else 0.0
    else:
        precharge = 0.0

    n = data.n
    burn = max(int(round(BURN_IN_S * fs)), 2 * w)
    split = burn + int(ESTIMATION_SHARE * (n - burn))
    idx = np.arange(n)
    est = (idx >= burn) & (idx < split)
    val = idx >= split
    if est.sum() < 200 or val.sum() < 200:
        raise ValueError(f"record too short: {n} samples")

    channels: list[str] = []
    measured: dict[str, np.ndarray] = {}
    sigma0: dict[str, float] = {}
    for c in pres:
        channels.append(c)
        measured[c] = cols[c]
    if "f_strain" in cols and not (load == "free" and np.std(cols["f_strain"]) < 5.0):
        channels.append("f_strain")
        measured["f_strain"] = cols["f_strain"]
    elif "f_strain" in cols:
        channels.append("f_strain")
        measured["f_strain"] = cols["f_strain"]
        notes.append("f_strain: no rod force with the piston free; fitted as offset + noise")
    exp_tmp_diff = _WindowDiff(w, data.dt)
    if "theta_m" in cols:
        channels.append("omega_m")
        measured["omega_m"] = exp_tmp_diff(cols["theta_m"])
    if "x_piston" in cols and load != "fixed":
        channels.append("v_piston")
        measured["v_piston"] = exp_tmp_diff(cols["x_piston"])
    for c in channels:
        y = measured[c][est]
        sigma0[c] = float(np.nanstd(y)) or 1.0
    plateaus = {}
    for c in pres + (["f_strain"] if "f_strain" in cols else []):
        level = _plateau(cols[c])
        if level is not None:
            plateaus[c] = level
    angle = None
    if "theta_m" in cols:
        # The encoder floors to its count: add half a count and average over 1 ms so the
        # rotor angle the pulsation terms see is unbiased and its quantisation error small.
        th = cols["theta_m"]
        angle = _smooth(th, max(1, int(round(1e-3 * fs)))) + 0.5 * quantum(th)
    position = cols["x_piston"] if "x_piston" in cols else None
    temperature = None
    t_ref = float(eff["oil_temperature"]["reference_c"])
    if "temp_c" in cols:
        temperature = _smooth(cols["temp_c"], max(1, int(0.2 * fs)))
    return Experiment(data, load, const, start, channels, measured, sigma0, precharge,
                      angle, position, temperature, t_ref, w, est, val, plateaus, notes,
                      intersample)


class _WindowDiff:
    def __init__(self, w: int, dt: float) -> None:
        self.w = w
        self.dt = dt

    def __call__(self, y: np.ndarray) -> np.ndarray:
        out = np.full(y.shape, np.nan)
        out[self.w:] = (y[self.w:] - y[: -self.w]) / (self.w * self.dt)
        return out


__all__ = ["Constants", "Experiment", "PRESSURES", "prepare", "quantum"]
