"""What cannot be identified is refused, with the reason, before anything is fitted.

One place for every content check of an identification record (the CSV reader checks the
file's form; this checks what the numbers say). A record is refused when a fit of it could
only produce a confident answer from garbage:

* values no sensor of this actuator produces, most likely wrong units: pressure outside
  -0.1..10 MPa gauge (or every pressure below 2 kPa: bar or MPa logged as Pa), ``|iq|``
  beyond the drive's 40 A converter range, a temperature outside -40..150 degC, a piston
  position beyond +-0.1 m (the stroke is 50 mm: millimetres logged as metres);
* nothing to identify from: a constant (or zero) input, every output the load case needs
  constant, too few samples for the model's order;
* after the baseline fit, a model that explains less than a tenth of every output: the
  logged current is not what drives these outputs (or the load case is wrong).

Each raises :class:`RefusedData`, whose ``str`` is one line naming the column and the reason.
"""

from __future__ import annotations

import numpy as np

from hil.identify.csvdata import REQUIRED_OUTPUTS, MeasuredData

PRESSURE_RANGE_PA = (-0.1e6, 10e6)
PRESSURE_MIN_SPAN_PA = 2e3
IQ_LIMIT_A = 40.0
TEMPERATURE_RANGE_C = (-40.0, 150.0)
POSITION_LIMIT_M = 0.1
#: Fewest samples: the burn-in, an estimation and a validation part long enough for the
#: residual tests' 50 lags and the ~2 Hz spectra.
MIN_SAMPLES = 2500
#: A baseline that leaves more than this share of every channel's variation unexplained
#: (NRMSE) explains nothing.
MAX_BASELINE_NRMSE = 0.9
PRESSURES = ("p_pump_a", "p_pump_b", "p_cyl_a", "p_cyl_b", "p_acc")


class RefusedData(Exception):
    """A record that cannot be identified; ``str(err)`` is one line with the reason."""


def _constant(y: np.ndarray) -> bool:
    return bool(np.ptp(y) <= 1e-12 * max(float(np.max(np.abs(y))), 1e-300))


def _where(data: MeasuredData, name: str, bad: np.ndarray) -> str:
    k = int(np.flatnonzero(bad)[0])
    return f"column '{name}' at t = {data.t[k]:.6g} s (row {k + 1})"


def check_record(data: MeasuredData) -> None:
    """Refuse a record whose values are impossible or that holds nothing to identify."""
    cols = data.columns
    for name, y in cols.items():
        bad = ~np.isfinite(y)
        if bad.any():
            raise RefusedData(f"{_where(data, name, bad)}: not a finite number")
    iq = cols["iq"]
    pressure_why = ("Pa is outside {lo:g}..{hi:g} MPa gauge (wrong units? declare them with "
                    "'# units: p=bar')")
    ranges = [("iq", -IQ_LIMIT_A, IQ_LIMIT_A, 1.0,
               "A is beyond the drive's +-{hi:g} A (wrong units? the CSV is SI: amperes)")]
    ranges += [(c, *PRESSURE_RANGE_PA, 1e6, pressure_why) for c in PRESSURES]
    ranges += [("temp_c", *TEMPERATURE_RANGE_C, 1.0,
                "degC is outside {lo:g}..{hi:g} degC (kelvin? fahrenheit?)"),
               ("x_piston", -POSITION_LIMIT_M, POSITION_LIMIT_M, 1.0,
                "m is beyond the stroke (+-{hi:g} m; millimetres?)")]
    for name, lo, hi, unit, why in ranges:
        if name not in cols:
            continue
        y = cols[name]
        bad = (y < lo) | (y > hi)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise RefusedData(f"{_where(data, name, bad)}: {y[k]:.6g} "
                              + why.format(lo=lo / unit, hi=hi / unit))
    pres = [cols[c] for c in PRESSURES if c in cols]
    if pres and max(float(np.max(np.abs(y))) for y in pres) < PRESSURE_MIN_SPAN_PA:
        raise RefusedData("every pressure column stays below 2 kPa: logged in bar or MPa, "
                          "not Pa? (declare them with '# units: p=bar')")
    if data.n < MIN_SAMPLES:
        raise RefusedData(f"only {data.n} samples: the model and the residual tests need at "
                          f"least {MIN_SAMPLES} (0.5 s at 5 kHz)")
    if _constant(iq):
        raise RefusedData(f"column 'iq' is constant ({iq[0]:g} A): no input, nothing "
                          "excites the actuator")
    groups = REQUIRED_OUTPUTS[data.load]
    moving = [c for g in groups for c in g if c in cols and not _constant(cols[c])]
    if not moving:
        present = [c for g in groups for c in g if c in cols]
        raise RefusedData(f"every output the load {data.load} needs is constant "
                          f"({', '.join(present)}): nothing to fit")


def check_fit(exp, base) -> None:
    """Refuse when the baseline fit explains (almost) nothing of any channel."""
    worst = []
    for c in exp.channels:
        y = exp.measured[c][exp.est]
        yh = base.outputs[c][exp.est]
        ok = np.isfinite(y) & np.isfinite(yh)
        den = float(np.linalg.norm(y[ok] - y[ok].mean()))
        if den == 0.0:
            continue
        worst.append(float(np.linalg.norm(y[ok] - yh[ok]) / den))
    if worst and min(worst) > MAX_BASELINE_NRMSE:
        raise RefusedData(f"the model explains at most {1 - min(worst):.0%} of any output "
                          "(NRMSE >= 0.9 on every channel): the logged current does not drive "
                          "these outputs, or the load case is wrong")


__all__ = ["RefusedData", "check_fit", "check_record"]
