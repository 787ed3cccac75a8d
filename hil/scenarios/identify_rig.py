"""``identify-rig``: identification on a record from the independent rig, judged by its truth.

The rig (:mod:`hil.identify.rig`: another integrator, parameters drawn off the preset,
realistic sampling and sensor noise, other friction laws) generates one experiment with the
effects the settings name; :func:`hil.identify.pipeline.identify` sees only the record and
the configuration. The result is judged as ``eha-hil identify-check`` judges a case
(:func:`hil.identify.rigcheck.judge`): every true library effect named and nothing else,
magnitudes within 10 % (amplitudes 20 %), ``unexplained`` exactly when an effect outside
the library is in the record. ``sim.seed`` seeds the rig (its parameter draw and noise), so
``eha-hil sweep identify-rig --seeds 0..19 --param scenario.magnitude=0.25:2:8`` asks from
which size on an effect is found, and how often. The settings themselves (defaults,
ranges, choices) are listed with the summary in
:data:`hil.scenarios.catalog.IDENTIFY_RIG_KNOBS`.
"""

from __future__ import annotations

import math
import time
from typing import Any

from hil.scenarios import Metric, Progress, ScenarioResult, register
from plant.config import Config, ConfigError

#: The rig magnitudes ``scenario.magnitude`` scales, per effect (the size of the effect;
#: shapes, orders, phases and corner frequencies stay). A saturation grows as its level
#: falls, so its level is divided.
SCALED: dict[str, tuple[str, ...]] = {
    "pump_pulsation": ("amplitude", "torque_n"),
    "pump_coulomb_friction": ("force_n",),
    "seal_friction": ("coulomb_n", "static_n"),
    "stiffness_vs_position": (),
    "viscosity_temperature": ("coeff_per_c",),
    "strain_thermal_drift": ("n_per_c",),
    "input_delay": ("delay_s",),
    "sensor_saturation": ("level_pa",),
    "hose_viscoelastic": ("stiffness_ratio",),
    "mains_hum": ("amplitude_pa",),
    "backlash": ("width_rad",),
}


def effects_of(v: dict[str, Any]) -> dict[str, dict[str, float]]:
    """{effect: magnitude overrides} the settings put into the record."""
    from hil.identify.rig import RIG_DEFAULT_MAGNITUDES

    out: dict[str, dict[str, float]] = {}
    for name in (v["effect"], v["effect2"]):
        if name == "none":
            continue
        mags = {}
        for key in SCALED[name]:
            base = RIG_DEFAULT_MAGNITUDES[name][key]
            mags[key] = base / v["magnitude"] if name == "sensor_saturation" else (
                base * v["magnitude"])
        out[name] = mags
    return out


def check_settings(v: dict[str, Any]) -> None:
    """The settings together: two different effects, a profile the load can run, a size the
    rig can make."""
    if v["effect"] != "none" and v["effect"] == v["effect2"]:
        raise ConfigError(f"scenario.effect2: '{v['effect2']}' is scenario.effect already")
    if v["profile"] != "multisine" and v["load"] != "free_piston":
        raise ConfigError(f"scenario.profile '{v['profile']}' needs scenario.load "
                          "free_piston")
    if v["magnitude"] == 0.0 and "sensor_saturation" in (v["effect"], v["effect2"]):
        raise ConfigError("scenario.magnitude 0: a saturation of size 0 has no level; "
                          "use scenario.effect=none")


@register("identify-rig", validate=check_settings)
def identify_rig(cfg: Config, progress: Progress, v: dict[str, Any]) -> ScenarioResult:
    from hil.identify.rig import generate_rig
    from hil.identify.rigcheck import Case, identify_and_judge

    effects = effects_of(v)
    seed = int(cfg.get("sim.seed"))
    t0, c0 = time.perf_counter(), time.process_time()
    rig = generate_rig(v["load"], effects, seconds=v["seconds"], seed=seed,
                       sample_rate_hz=v["rate_hz"], profile=v["profile"],
                       current_noise_lsb=v["noise_lsb"], spread=v["spread"], preset=cfg)
    if progress:
        progress(1, 2)
    case = Case(v["load"], tuple(effects), v["profile"], v["seconds"])
    res = identify_and_judge(case, seed, rig, cfg, t0, c0)
    if progress:
        progress(2, 2)
    mag_err = [abs(found / truth - 1.0) * 100.0 for _, truth, found in res.magnitudes
               if found is not None and truth != 0.0]
    missing_mag = any(found is None for _, _, found in res.magnitudes)
    worst_mag = math.nan if not res.magnitudes else (
        math.inf if missing_mag else max(mag_err))
    base_err = [abs(e) * 100.0 for e in res.param_error.values()]
    metrics = [
        Metric("right", float(res.right), "", "effects named, magnitudes within "
               "10 % (amplitudes 20 %), verdict honest", res.right),
        Metric("effects added", float(len(res.found)), "", "by the identification"),
        Metric("unexplained", float(res.unexplained), "", "1: a structured residual is left"),
        Metric("magnitude error", worst_mag, "%",
               "worst judged magnitude against the truth (inf: not found)"),
        Metric("baseline error", max(base_err) if base_err else math.nan, "%",
               "worst fitted baseline parameter against the truth"),
    ] + [Metric(f"{sym} error", e * 100.0, "%", "fitted / true - 1")
         for sym, e in sorted(res.param_error.items())]
    found = ", ".join(res.found) or "nothing"
    notes = [f"truth: {', '.join(effects) or 'no effect'}; found: {found}; {res.why}"]
    if res.refused:
        notes.append(f"refused: {res.refused}")
    # The record the identification saw (eha-hil run identify-rig --series FILE).
    series: dict[str, Any] = {"t_s": rig.data.t}
    series.update({name: col for name, col in rig.data.columns.items()})
    return ScenarioResult(
        "identify-rig", f"identification on the rig: {case.label}, seed {seed}", metrics,
        series=series, notes=notes)
