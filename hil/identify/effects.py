"""The identification library, one class per effect: everything the tool knows about it.

Each :class:`Effect` holds, in one place, what used to be spread over if-chains on the
effect's name in the candidate library, the loop and the check against the rig:

* its description and its **candidate definitions** for a record
  (:meth:`Effect.definitions`: the fast model's parameters it switches on, their realistic
  sizes, when it applies, the shape parameters freed once it is in);
* how its **refit starts** (:meth:`Effect.prepare_refit`: the viscosity law takes the
  dampers to the reference temperature, the causal delay takes over the timing skew);
* how its fitted parameters are **reported** (:meth:`Effect.describe`: the physical
  parameters with 95 % intervals by the delta method);
* which of its magnitudes **the check against the rig judges** (:attr:`Effect.judged`:
  truth key, report key, tolerance kind).

The independent rig's own model of each effect (:mod:`hil.identify.rig_effects`, registered
under the same names) stays apart on purpose: it is the other side of the test.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.identify.candidates import FRICTION_SHAPE_START, EffectDef
from hil.identify.experiment import Experiment
from hil.identify.fit import Z95, FitResult
from hil.identify.model import IDX, N_ORDERS, PRESSURE_CHANNELS, SAT_CHANNELS, SAT_PRESSURE


@dataclass
class ParamEstimate:
    """A parameter with its 95 % confidence interval (HAC, delta method where derived)."""

    name: str
    value: float
    ci_low: float
    ci_high: float
    unit: str = ""

    def as_dict(self) -> dict:
        return {"value": self.value, "ci95": [self.ci_low, self.ci_high], "unit": self.unit}


def _delta(fit: FitResult, fn: Callable[[np.ndarray], float], params: list[str]
           ) -> tuple[float, float]:
    """Value of ``fn(theta)`` and its standard error by the delta method."""
    theta = fit.theta
    v = fn(theta)
    idx = [fit.free.index(p) for p in params if p in fit.free]
    if fit.cov is None or not idx:
        return v, float("nan")
    grad = np.zeros(len(idx))
    for k, i in enumerate(idx):
        p = fit.free[i]
        step = max(abs(theta[IDX[p]]) * 1e-4, 1e-9)
        th = theta.copy()
        th[IDX[p]] += step
        grad[k] = (fn(th) - v) / step
    cov = fit.cov[np.ix_(idx, idx)]
    return v, float(np.sqrt(max(grad @ cov @ grad, 0.0)))


def estimate(name: str, fit: FitResult, fn: Callable[[np.ndarray], float],
             params: list[str], unit: str) -> ParamEstimate:
    """``fn(theta)`` of the fit with its 95 % interval (delta method over ``params``)."""
    v, se = _delta(fit, fn, params)
    return ParamEstimate(name, v, v - Z95 * se, v + Z95 * se, unit)


def _value(fit: FitResult, name: str, p: str, unit: str) -> ParamEstimate:
    return estimate(name, fit, lambda t: t[IDX[p]], [p], unit)


def _needs_temperature(exp: Experiment) -> str | None:
    return "no temp_c column" if exp.temperature is None else None


def _needs_strain(exp: Experiment) -> str | None:
    return None if "f_strain" in exp.channels else "no f_strain column"


class Effect:
    """One library effect (module docstring); subclasses fill in the parts."""

    name: str = ""
    description: str = ""
    #: magnitudes judged against the rig's truth: (truth key, report key, "magnitude" or
    #: "amplitude")
    judged: tuple[tuple[str, str, str], ...] = ()

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        """The candidate instances of this effect for the record ``exp``."""
        raise NotImplementedError

    def prepare_refit(self, theta0: np.ndarray, credible: np.ndarray, free: list[str],
                      exp: Experiment, fitted: list[str], est_mask: np.ndarray) -> None:
        """Adjust the refit's start ``theta0`` (and the ``credible`` values the guard falls
        back to) and its ``free`` parameters, in place, once this effect is in; ``fitted``:
        the parameters the fit without it had free."""

    def implausible(self, fit: FitResult, exp: Experiment) -> dict[str, str]:
        """Shape parameters of this effect (of its ``refit_extra``) at which the refit ``fit``
        left the effect's physical law for a degenerate one: {parameter: why}. They are held
        at their starting values and the refit is made again."""
        return {}

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        """The physical parameters of the added instance ``d`` with 95 % intervals."""
        return {p: _value(fit, p, p, "") for p in d.params}


class PumpPulsation(Effect):
    name = "pump_pulsation"
    description = ("displacement ripple (flow and reaction torque) and meshing torque ripple "
                   "at an order of the rotor angle")
    judged = (("amplitude", "amplitude", "amplitude"), ("torque_n", "torque_n", "amplitude"))

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(
            self.name, f"{self.name}[order={n}]",
            (f"puls{n}_flow_s", f"puls{n}_flow_c", f"puls{n}_torque_s", f"puls{n}_torque_c"),
            (0.01, 0.01, 50.0, 50.0),
            f"displacement ripple (flow and reaction torque) and meshing torque ripple at "
            f"order {n} of the rotor angle") for n in range(1, N_ORDERS + 1)]

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        fs_, fc_, ts_, tc_ = d.params
        g = IDX
        order = int(d.label.split("=")[1].rstrip("]"))
        return {
            "order": ParamEstimate("order", order, order, order, ""),
            "amplitude": estimate("amplitude", fit, lambda t: math.hypot(t[g[fs_]], t[g[fc_]]),
                                  [fs_, fc_], "1"),
            "phase_rad": estimate("phase_rad", fit,
                                  lambda t: math.atan2(t[g[fc_]], t[g[fs_]]), [fs_, fc_], "rad"),
            "torque_n": estimate("torque_n", fit, lambda t: math.hypot(t[g[ts_]], t[g[tc_]]),
                                 [ts_, tc_], "N"),
            "torque_phase_rad": estimate("torque_phase_rad", fit,
                                         lambda t: math.atan2(t[g[tc_]], t[g[ts_]]),
                                         [ts_, tc_], "rad"),
        }


class PumpCoulombFriction(Effect):
    name = "pump_coulomb_friction"
    description = ("Coulomb friction of the pump shaft seal, F_c s(v_p/eps); eps and the sign "
                   "law's shape (tanh .. atan) fitted")
    judged = (("force_n", "force_n", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(self.name, self.name, ("pc_force_n",), (40.0,), self.description,
                          refit_extra=(("pc_eps_m_per_s", lambda exp: exp.const.eps_pump),
                                       ("pc_shape", lambda exp: FRICTION_SHAPE_START)))]

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        out = {"force_n": estimate("force_n", fit, lambda t: t[IDX["pc_force_n"]],
                                   list(d.params), "N")}
        if "pc_eps_m_per_s" in fit.free:
            out["eps_m_per_s"] = _value(fit, "eps_m_per_s", "pc_eps_m_per_s", "m/s")
        if "pc_shape" in fit.free:
            out["shape"] = _value(fit, "shape", "pc_shape", "0 tanh .. 1 atan")
        return out


#: A seal's Stribeck velocity below this share of its regularisation velocity is a
#: degenerate law (:meth:`SealFriction.implausible`). The runaways seen went to 2-3 % of it;
#: a fit near it (0.98 of it: free piston, both frictions, slide, seed 1) is a law whose dip
#: and regularisation overlap, which the data may well ask for.
VS_FLOOR_OF_EPS = 0.25
#: The seal's regularisation velocity is fitted when the measured piston speed stays below
#: twice the preset's for at least this share of the record: there the law's linear zone
#: (a damper F_s/eps) carries the piston, and a wrong eps moves the fitted levels (the conrod
#: under the multisine, 0.6-0.8 of the samples: F_c 12 % high with the preset's eps from a
#: start at the truth). Elsewhere the record says little about it (the free piston under the
#: multisine 0.2-0.45, under ``slide`` 0) and a free eps costs a Jacobian column in every
#: refit (the free piston's two-friction bench record 19 -> 31 s of CPU).
STUCK_SHARE = 0.5


def stuck_share(exp: Experiment) -> float:
    """Share of the record's samples whose measured piston speed lies below twice the seal's
    preset regularisation velocity (0 without a piston encoder)."""
    v = exp.measured.get("v_piston")
    if v is None:
        return 0.0
    v = v[np.isfinite(v)]
    return float(np.mean(np.abs(v) < 2.0 * exp.const.eps_seal)) if v.size else 0.0


def top_speed(exp: Experiment) -> float:
    """The record's top measured piston speed (0 without a piston encoder)."""
    v = exp.measured.get("v_piston")
    if v is None:
        return 0.0
    v = np.abs(v[np.isfinite(v)])
    return float(v.max()) if v.size else 0.0


class SealFriction(Effect):
    name = "seal_friction"
    description = ("rod-seal Coulomb + Stribeck friction on the piston; v_s and the sign "
                   "law's shape (tanh .. atan) fitted, eps too where the piston sits mostly "
                   "in the law's linear zone")
    judged = (("coulomb_n", "coulomb_n", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(self.name, self.name, ("sf_coulomb_n", "sf_static_n"), (15.0, 15.0),
                          self.description,
                          lambda exp: ("piston fixed: the seal never slides"
                                       if exp.load == "fixed" else None),
                          refit_extra=(("sf_vs_m_per_s", lambda exp: exp.const.vs_seal),
                                       ("sf_shape", lambda exp: FRICTION_SHAPE_START))
                          + ((("sf_eps_m_per_s", lambda exp: exp.const.eps_seal),)
                             if stuck_share(exp) >= STUCK_SHARE else ()))]

    def implausible(self, fit: FitResult, exp: Experiment) -> dict[str, str]:
        """A Stribeck velocity far below the regularisation velocity puts the dip inside the
        zone where the sign law is still linear: a bump of a static level that can run to
        any size in a band no sample reaches (the free piston under the ``slide`` profile,
        rig seed 2: v_s 63 um/s, F_s 1.3e12 N, an interval of zero width since no sample
        sees it), not a Stribeck curve."""
        if "sf_vs_m_per_s" not in fit.free:
            return {}
        vs = fit.value("sf_vs_m_per_s")
        eps = ((fit.value("sf_eps_m_per_s") if "sf_eps_m_per_s" in fit.free else 0.0)
               or exp.const.eps_seal)
        if vs < VS_FLOOR_OF_EPS * eps:
            return {"sf_vs_m_per_s": (f"the Stribeck velocity ran to {vs:.3g} m/s, far below "
                                      f"the regularisation velocity {eps:.3g} m/s (a "
                                      "degenerate law); held at its start")}
        top = top_speed(exp)
        if top > 0.0 and vs > top:
            return {"sf_vs_m_per_s": (f"the Stribeck velocity ran to {vs:.3g} m/s, above the "
                                      f"record's top piston speed {top:.3g} m/s (a degenerate "
                                      "law: no sample reaches the Coulomb level); held at its "
                                      "start")}
        return {}

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        ps = list(d.params)
        out = {"coulomb_n": estimate("coulomb_n", fit, lambda t: t[IDX["sf_coulomb_n"]], ps,
                                     "N"),
               "static_n": estimate("static_n", fit, lambda t: t[IDX["sf_static_n"]], ps, "N")}
        if "sf_vs_m_per_s" in fit.free:
            out["stribeck_velocity_m_per_s"] = _value(fit, "stribeck_velocity_m_per_s",
                                                      "sf_vs_m_per_s", "m/s")
        if "sf_eps_m_per_s" in fit.free:
            out["eps_m_per_s"] = _value(fit, "eps_m_per_s", "sf_eps_m_per_s", "m/s")
        if "sf_shape" in fit.free:
            out["shape"] = _value(fit, "shape", "sf_shape", "0 tanh .. 1 atan")
        return out


class StiffnessVsPosition(Effect):
    name = "stiffness_vs_position"
    description = ("k_s(x) = k_s / (1 + c1 x/h + c2 (x/h)^2), h the half stroke: Eq. "
                   "2.25-2.27 make the series compliance exactly quadratic in x")
    judged = (("ks_relative_span", "ks_relative_span", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(self.name, self.name, ("ks_k1", "ks_k2"), (0.1, 0.1),
                          self.description)]

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        # k_s(x) = k_s / (1 + c1 x/h + c2 (x/h)^2): Eq. 2.25-2.27 make the compliance exactly
        # quadratic, 1/k_s(x) = 1/k_s(0) - x^2 / (2 A kappa) with A = V_side + k_c h, so
        # c2 = -h^2 k_s / (2 A kappa) gives the oil volume per side (dead volume + pipe).
        ps = list(d.params)
        g = IDX
        x = exp.position if exp.position is not None else np.zeros(1)
        c = exp.const
        h = c.half_stroke
        lo, hi = float(x.min()) / h, float(x.max()) / h
        mid = 0.5 * (lo + hi)

        def span(t: np.ndarray) -> float:
            def k(xn: float) -> float:
                return 1.0 / (1.0 + t[g["ks_k1"]] * xn + t[g["ks_k2"]] * xn * xn)

            return 0.5 * (k(lo) + k(hi)) / k(mid) - 1.0

        out = {"ks_c1": estimate("ks_c1", fit, lambda t: t[g["ks_k1"]], ps, "1"),
               "ks_c2": estimate("ks_c2", fit, lambda t: t[g["ks_k2"]], ps, "1"),
               "ks_relative_span": estimate("ks_relative_span", fit, span, ps, "1")}
        if fit.value("ks_k2") < 0.0 and c.bulk_modulus > 0.0:
            def side_volume(t: np.ndarray) -> float:
                a = -h * h * t[g["ks"]] / (2.0 * c.bulk_modulus * t[g["ks_k2"]])
                return a - c.kc * h

            out["side_volume_m3"] = estimate("side_volume_m3", fit, side_volume, [*ps, "ks"],
                                             "m^3")
        return out


class ViscosityTemperature(Effect):
    name = "viscosity_temperature"
    description = "d_s, d_p, d_c scale with mu(T) = exp(-c (T - T_ref))"
    judged = (("coeff_per_c", "coeff_per_c", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(self.name, self.name, ("visc_coeff_per_c",), (0.02,),
                          self.description, _needs_temperature, rescales_declared=True)]

    def prepare_refit(self, theta0: np.ndarray, credible: np.ndarray, free: list[str],
                      exp: Experiment, fitted: list[str], est_mask: np.ndarray) -> None:
        if exp.temperature is None:
            return
        # the fitted dampers hold at the record's temperature until the law is in; with it
        # they hold at the reference temperature (a held one already does: the preset's)
        t_mean = float(np.mean(exp.temperature[est_mask]))
        factor = math.exp(theta0[IDX["visc_coeff_per_c"]] * (t_mean - exp.t_ref))
        for p in ("ds", "dp", "dc"):
            if p in fitted:
                theta0[IDX[p]] *= factor
                credible[IDX[p]] *= factor

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        return {"coeff_per_c": estimate("coeff_per_c", fit,
                                        lambda t: t[IDX["visc_coeff_per_c"]], list(d.params),
                                        "1/degC"),
                "t_ref_c": ParamEstimate("t_ref_c", exp.t_ref, exp.t_ref, exp.t_ref, "degC")}


class StrainThermalDrift(Effect):
    name = "strain_thermal_drift"
    description = ("drift of the strain reading with the logged temperature, c (T - T_ref) "
                   "N/degC (thesis 4.4: 2.5 N/degC after compensation)")
    judged = (("n_per_c", "n_per_c", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        return [EffectDef(self.name, self.name, ("drift_n_per_c",), (2.5,), self.description,
                          lambda exp: _needs_strain(exp) or _needs_temperature(exp))]

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        ps = list(d.params)
        out = {"n_per_c": estimate("n_per_c", fit, lambda t: t[IDX["drift_n_per_c"]], ps,
                                   "N/degC")}
        if exp.temperature is not None:
            d_t = float(exp.temperature[-1] - exp.temperature[0])
            out["drift_n"] = estimate("drift_n", fit,
                                      lambda t: t[IDX["drift_n_per_c"]] * d_t, ps, "N")
        return out


class InputDelay(Effect):
    name = "input_delay"
    description = ("causal delay between the logged and the applied current (beyond the "
                   "baseline's sub-sample timing skew, which it replaces when added)")
    judged = (("delay_s", "delay_s", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        def skew_at_bound(exp: Experiment) -> str | None:
            return None if exp.skew_at_bound else (
                "the fit's timing skew lies within half a sample: a sampling alignment, "
                "no delay beyond it")

        return [EffectDef(self.name, self.name, ("delay_s",), (100e-6,), self.description,
                          skew_at_bound, judged_at_fit=True)]

    def prepare_refit(self, theta0: np.ndarray, credible: np.ndarray, free: list[str],
                      exp: Experiment, fitted: list[str], est_mask: np.ndarray) -> None:
        if "skew_s" in free:
            # the causal delay takes over the sub-sample skew: one timing parameter
            theta0[IDX["delay_s"]] = max(theta0[IDX["delay_s"]] + theta0[IDX["skew_s"]], 0.0)
            theta0[IDX["skew_s"]] = 0.0
            free.remove("skew_s")

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        return {"delay_s": estimate("delay_s", fit, lambda t: t[IDX["delay_s"]],
                                    list(d.params), "s")}


class SensorSaturation(Effect):
    name = "sensor_saturation"
    description = "a channel clipped at a level"
    judged = (("level_pa", "level", "magnitude"),)

    def definitions(self, exp: Experiment) -> list[EffectDef]:
        out: list[EffectDef] = []
        sat = [c for c in SAT_CHANNELS if c in exp.plateaus and c in exp.channels]
        if not sat:
            out.append(EffectDef(self.name, self.name, (), (), self.description,
                                 lambda exp: "no channel sits on a plateau at its maximum"))
        press = [c for c in sat if c in PRESSURE_CHANNELS]
        if len(press) > 1:  # the pressure sensors clip as one effect
            levels = ", ".join(f"{c} {exp.plateaus[c]:.6g}" for c in press)
            out.append(EffectDef(self.name, f"{self.name}[pressure]", (SAT_PRESSURE,), (1.0,),
                                 f"pressure sensors clipped at {levels}"))
            sat = [c for c in sat if c not in press]
        for c in sat:
            out.append(EffectDef(self.name, f"{self.name}[{c}]", (f"sat_{c}",), (1.0,),
                                 f"{c} clipped at {exp.plateaus[c]:.6g}"))
        return out

    def describe(self, d: EffectDef, fit: FitResult, exp: Experiment
                 ) -> dict[str, ParamEstimate]:
        ch = d.label.split("[")[1].rstrip("]")
        # the pressure group: the highest plateau (the sensors' common range)
        lvl = (max(exp.plateaus[c] for c in PRESSURE_CHANNELS if c in exp.plateaus)
               if ch == "pressure" else exp.plateaus[ch])
        ps = list(d.params)
        return {"level": ParamEstimate("level", lvl, lvl, lvl,
                                       "Pa" if ch != "f_strain" else "N"),
                "clip_fraction": estimate("clip_fraction", fit, lambda t: t[IDX[ps[0]]], ps,
                                          "1")}


#: The library, by name, in the order its candidates are listed.
EFFECTS: dict[str, Effect] = {e.name: e for e in (
    PumpPulsation(), PumpCoulombFriction(), SealFriction(), StiffnessVsPosition(),
    ViscosityTemperature(), StrainThermalDrift(), InputDelay(), SensorSaturation())}


def library(exp: Experiment) -> list[EffectDef]:
    """Every candidate instance for this experiment (pulsation: one per order 1..8;
    saturation: one per channel that shows a plateau, the pressures as one)."""
    return [d for e in EFFECTS.values() for d in e.definitions(exp)]


__all__ = ["EFFECTS", "Effect", "ParamEstimate", "estimate", "library"]
