"""``bus-faults``: a fieldbus run with one declared fault, judged by what the firmware did.

The PC loop of ``eha-hil bus run`` (a force sine on every actuator) runs over the in-process
transport with one fault of :mod:`hil.fieldbus.faults` switched on in a time window: lost,
corrupted, duplicated or delayed fieldbus frames, a damaged LVDS link, or a stuck, noisy or
dead sensor. The PC sees the inputs as a real PC would (its process image), and the metrics
come from there, except the status words, which are also taken from the boxes themselves at
every cycle (a lost reply hides what happened behind it): how often the MCU's command
watchdog tripped (``CMD_TIMEOUT`` rising edges over all actuators), how often a board was
switched off (``SAFE_OFF``), frames lost and discarded, the share of stale inputs, and how
far the measured force strayed from the command. The fault is the scenario's settings
(``scenario.link``, ``scenario.kind``, ``scenario.rate`` ...), so ``eha-hil sweep
bus-faults --param scenario.rate=0.5:0.9:5`` asks how the watchdog behaves as the loss rate
grows; ``sim.seed`` seeds the fault draws. The settings themselves (defaults, ranges,
choices) are listed with the summary in :data:`hil.scenarios.catalog.BUS_FAULT_KNOBS`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from firmware_model.mcu.mcu import CMD_TIMEOUT, SAFE_OFF, flag_set
from hil.fieldbus.faults import KINDS
from hil.scenarios import Metric, Progress, ScenarioResult, register
from plant.config import Config, ConfigError

CYCLE_S = 1e-3
#: The force error is taken from this time on (the boards boot and the force settles).
SETTLE_S = 0.05


def fault_entry(v: dict[str, Any], seed: int) -> dict[str, Any] | None:
    """The ``[[fault]]`` declaration the settings describe (None for a clean run)."""
    link, kind = v["link"], v["kind"]
    if link == "none":
        return None
    if kind not in KINDS[link]:
        raise ConfigError(f"scenario.kind '{kind}' does not apply to scenario.link "
                          f"'{link}' (there: {', '.join(KINDS[link])})")
    entry: dict[str, Any] = {"link": link, "kind": kind, "start_s": v["start_s"],
                             "seed": seed}
    if v["end_s"] != math.inf:
        entry["end_s"] = v["end_s"]
    if link.startswith("fieldbus"):
        entry.update(rate=v["rate"])
        if kind == "bitflip":
            entry["bits"] = v["bits"]
        if kind == "delay":
            entry["delay_cycles"] = v["delay"]
        return entry
    entry.update(box=v["box"], slot=v["slot"])
    if link.startswith("lvds"):
        if kind in ("bitflip", "drop", "duplicate"):
            if v["rate"] <= 0.0:
                raise ConfigError("scenario.rate: an lvds fault needs a rate above 0 (it "
                                  "hits every 1/rate-th word)")
            entry["rate"] = v["rate"]
        if kind == "delay":
            entry["delay_ticks"] = v["delay"]
        return entry
    entry["signal"] = v["signal"]
    if kind == "noisy":
        entry["sigma"] = v["sigma"]
    return entry


def rising_edges(flags: np.ndarray) -> int:
    """How often a flag went from clear to set, over (cycles, actuators) booleans."""
    f = flags.astype(np.int8)
    return int(np.count_nonzero(np.diff(f, axis=0) > 0) + np.count_nonzero(f[0]))


def check_settings(v: dict[str, Any]) -> None:
    """The settings together: the fault kind applies to its link; window and rate fit."""
    fault_entry(v, 0)
    if v["end_s"] <= v["start_s"]:
        raise ConfigError(f"scenario.end_s ({v['end_s']:g} s) must be after scenario.start_s "
                          f"({v['start_s']:g} s)")


@register("bus-faults", validate=check_settings)
def bus_faults(cfg: Config, progress: Progress, v: dict[str, Any]) -> ScenarioResult:
    from hil.fieldbus.faults import FaultError, check_topology, parse_faults
    from hil.fieldbus.system import BusSystem
    from hil.fieldbus.topology import TopologyError, load_topology
    from hil.sim.pc import demo_pc

    try:
        topo = load_topology(v["topology"])
    except TopologyError as exc:
        raise ConfigError(f"scenario bus-faults: {exc}") from None
    model = v["model"] if v["model"] != "auto" else (
        "stack" if topo.n_actuators <= 5 else "echo")
    entry = fault_entry(v, int(cfg.get("sim.seed")))
    faults = None if entry is None else {"fault": [entry]}
    if faults is not None:
        try:
            check_topology(parse_faults(faults, "scenario bus-faults"), topo)
        except FaultError as exc:
            raise ConfigError(str(exc)) from None
        if model != "stack" and not v["link"].startswith("fieldbus"):
            raise ConfigError(f"scenario bus-faults: an {v['link']} fault needs "
                              "scenario.model stack (the echo model has no link or sensors)")
    cycles = max(1, int(round(v["seconds"] / CYCLE_S)))
    n_act = topo.n_actuators
    status = np.zeros((cycles, n_act), dtype=np.uint16)
    force = np.zeros((cycles, n_act))
    command = np.zeros((cycles, n_act))
    fresh = np.zeros((cycles, n_act), dtype=bool)
    truth = np.zeros((cycles, n_act), dtype=np.uint16)  # the MCUs' own status words
    sine = demo_pc(v["amplitude_n"], v["frequency_hz"])
    step = max(1, cycles // 100)
    boxes: list[Any] = []

    def box_status() -> None:
        # After each cycle the boxes advanced: in lockstep, the cycles of lost frames are
        # advanced when the next frame arrives, so the rows are filled in bursts.
        row = chain.stats.cycles_advanced - 1
        if not 0 <= row < cycles:
            return
        j = 0
        for box in boxes:
            rec = np.frombuffer(box.inputs(), dtype=box.in_dtype)[0]
            for k in box.act:
                truth[row, j] = rec[f"s{k}"]["status"]
                j += 1

    def pc(cycle: int, m: Any) -> None:
        if cycle > 0:  # what the last cycle brought back
            for j in range(n_act):
                got = m.actuator_inputs(j)
                status[cycle - 1, j] = got["status"]
                force[cycle - 1, j] = got["f_filtered"]
                fresh[cycle - 1, j] = got["fresh"]
        sine(cycle, m)
        t = cycle * CYCLE_S
        for j in range(n_act):
            command[cycle, j] = v["amplitude_n"] * math.sin(
                2.0 * math.pi * v["frequency_hz"] * t + 0.4 * j)
        if progress and cycle % step == 0:
            progress(cycle, cycles)

    with BusSystem(topo, cfg, "inproc", model=model, faults=faults) as bs:
        chain = bs.chain
        boxes.extend(chain.boxes)
        chain.on_advance = box_status
        rec = bs.run(cycles, pc)
        for j in range(n_act):  # the last cycle's inputs
            got = bs.master.actuator_inputs(j)
            status[-1, j], force[-1, j], fresh[-1, j] = (got["status"], got["f_filtered"],
                                                         got["fresh"])
    if progress:
        progress(cycles, cycles)
    # The command of cycle k is measured in the inputs of cycle k (same frame) at the
    # earliest; compare each input with the command the PC had sent in that cycle.
    settled = int(math.ceil(SETTLE_S / CYCLE_S))
    err = force[settled:] - command[settled:]
    rms = float(np.sqrt(np.mean(err ** 2))) if err.size else math.nan
    trips = rising_edges(flag_set(truth, CMD_TIMEOUT))
    offs = rising_edges(flag_set(truth, SAFE_OFF))
    seen = rising_edges(flag_set(status, CMD_TIMEOUT))
    m = rec.master
    metrics = [
        Metric("watchdog trips", trips, "", "CMD_TIMEOUT rising edges in the MCUs, all "
               "actuators: 0", trips == 0),
        Metric("safe-off events", offs, "", "SAFE_OFF rising edges in the MCUs: 0", offs == 0),
        Metric("watchdog trips seen", seen, "", "the same in the PC's inputs (a lost reply "
               "hides a change)"),
        Metric("frames lost", m["lost_frames"], "", "frames that did not come back"),
        Metric("frames discarded", m["bad_frames"], "", "replies failing the frame check"),
        Metric("WKC errors", m["wkc_errors"], ""),
        Metric("stale inputs", 100.0 * float(np.mean(~fresh)), "%",
               "actuator-cycles without fresh inputs"),
        Metric("force error rms", rms, "N",
               f"f_filtered - command after {SETTLE_S * 1e3:g} ms, all actuators"),
    ]
    where = "none" if entry is None else f"{entry['link']} {entry['kind']}"
    t = np.arange(1, cycles + 1) * CYCLE_S
    return ScenarioResult(
        "bus-faults", f"{topo.name} ({model}), {cycles} cycles, fault: {where}", metrics,
        series={"t_s": t, "command_n": command[:, 0], "force_n": force[:, 0],
                "cmd_timeout": flag_set(truth[:, 0], CMD_TIMEOUT).astype(float),
                "safe_off": flag_set(truth[:, 0], SAFE_OFF).astype(float),
                "fresh": fresh[:, 0].astype(float),
                "fault_window_s": (np.array([v["start_s"], min(v["end_s"], t[-1])])
                                   if entry else np.array([math.nan, math.nan]))},
        plot=_plot, notes=[f"fault: {entry}" if entry else "no fault (scenario.link = none)"])


def _plot(res: ScenarioResult, path: Path) -> None:
    from hil.output.plots import _pyplot

    plt = _pyplot()
    s = res.series
    fig, (a, b) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True,
                               gridspec_kw={"height_ratios": [3, 1]})
    a.plot(s["t_s"], s["command_n"], "k:", lw=1, label="command (actuator 0)")
    a.plot(s["t_s"], s["force_n"], lw=1, label="f_filtered from the inputs")
    lo, hi = s["fault_window_s"]
    for ax in (a, b):
        if math.isfinite(lo):
            ax.axvspan(lo, hi, color="tab:red", alpha=0.08, lw=0)
    a.set_ylabel("force [N]")
    a.legend(loc="upper right")
    a.set_title(res.title)
    b.step(s["t_s"], s["cmd_timeout"] + 2.2, where="post", label="CMD_TIMEOUT (MCU)")
    b.step(s["t_s"], s["safe_off"] + 1.1, where="post", label="SAFE_OFF (MCU)")
    b.step(s["t_s"], s["fresh"], where="post", label="fresh inputs (PC)")
    b.set_yticks([0.5, 1.6, 2.7], ["fresh (PC)", "SAFE_OFF", "CMD_TIMEOUT"])
    b.set_xlabel("time [s] (shaded: fault window)")
    for ax in (a, b):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
