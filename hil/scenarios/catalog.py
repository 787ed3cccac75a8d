"""Every scenario's name, summary and settings, without the scenario itself.

The scenario modules load the simulation (numba's kernels) when imported; this one loads
only the settings' checks (:mod:`hil.scenarios.knobs`) and the fault names of
:mod:`hil.fieldbus.faults`, so the command line lists the scenarios (``eha-hil run --help``,
``eha-hil sweep --help``) without loading any. A scenario module registers its runner
under a name listed here (:func:`hil.scenarios.register`), which takes the summary and the
settings from here: one place for each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.fieldbus.faults import KINDS, LINKS, SENSOR_SIGNALS
from hil.scenarios.knobs import Knob


@dataclass(frozen=True)
class Entry:
    """What a scenario is, as listed: one line, and its own settings (``scenario.NAME``)."""

    summary: str
    knobs: tuple[Knob, ...] = ()


#: ``bus-faults``: topologies the scenario offers (the shipped ones).
BUS_FAULT_TOPOLOGIES = ("bench_one_box", "hydra_full")

#: ``bus-faults``: the fault and the run (:mod:`hil.scenarios.bus_faults`).
BUS_FAULT_KNOBS = (
    Knob("topology", "bench_one_box", "the robot on the bus", choices=BUS_FAULT_TOPOLOGIES),
    Knob("model", "auto", "box model: stack (plant, board, link, MCU) or echo; auto: stack "
         "up to 5 actuators", choices=("auto", "stack", "echo")),
    Knob("seconds", 0.5, "simulated time", "s", lo=0.01, hi=600.0),
    Knob("link", "fieldbus.down", "where the fault hits (none: a clean run)",
         choices=("none", *LINKS)),
    Knob("kind", "drop", "what the fault does (hil.fieldbus.faults)",
         choices=tuple(sorted({k for ks in KINDS.values() for k in ks}))),
    Knob("rate", 0.05, "probability per frame (fieldbus) or 1/N of the words (lvds)",
         lo=0.0, hi=1.0),
    Knob("start_s", 0.1, "the fault's window opens", "s", lo=0.0),
    Knob("end_s", math.inf, "the fault's window closes", "s", lo=0.0),
    Knob("delay", 3, "delay: fieldbus cycles (fieldbus) or 50 us ticks (lvds)", lo=1, hi=63),
    Knob("bits", 1, "bits flipped per hit frame (fieldbus bitflip)", lo=1, hi=64),
    Knob("box", 0, "box of an lvds or sensor fault", lo=0),
    Knob("slot", 0, "slot of an lvds or sensor fault", lo=0),
    Knob("signal", "p_cyl_a", "the sensor's signal (sensor faults)",
         choices=tuple(SENSOR_SIGNALS)),
    Knob("sigma", 1e5, "noise of a noisy sensor, 1 sigma in the signal's SI unit", lo=0.0),
    Knob("amplitude_n", 300.0, "force command sine amplitude", "N", lo=0.0, hi=1e5),
    Knob("frequency_hz", 2.0, "force command sine frequency", "Hz", lo=0.0, hi=500.0),
)

_RIG_LOADS = ("fixed_piston", "free_piston", "conrod_fixed")
_RIG_EFFECTS = ("pump_pulsation", "pump_coulomb_friction", "seal_friction",
                "stiffness_vs_position", "viscosity_temperature", "strain_thermal_drift",
                "input_delay", "sensor_saturation", "hose_viscoelastic", "mains_hum",
                "backlash")

#: ``identify-rig``: the record and its effects (:mod:`hil.scenarios.identify_rig`).
IDENTIFY_RIG_KNOBS = (
    Knob("load", "fixed_piston", "the rig's load case", choices=_RIG_LOADS),
    Knob("effect", "none", "an effect in the record (none: the linear model's physics only)",
         choices=("none", *_RIG_EFFECTS)),
    Knob("effect2", "none", "a second effect in the record", choices=("none", *_RIG_EFFECTS)),
    Knob("magnitude", 1.0, "size of the effects relative to the rig's default magnitudes",
         lo=0.0, hi=20.0),
    Knob("profile", "multisine", "excitation (slide, resonance: free_piston only)",
         choices=("multisine", "slide", "resonance")),
    Knob("seconds", 6.0, "record length", "s", lo=1.0, hi=120.0),
    Knob("rate_hz", 5000.0, "sample rate of the record", "Hz", lo=500.0, hi=20000.0),
    Knob("noise_lsb", 1.0, "logged current noise, 1 sigma in LSB of the +-40 A converter",
         "LSB", lo=0.0, hi=50.0),
    Knob("spread", 0.15, "relative range of the rig's parameter draws off the preset",
         lo=0.0, hi=0.5),
)

#: Every scenario, by name (the module that runs it in brackets).
CATALOG: dict[str, Entry] = {
    # hil.scenarios.plant_figures
    "f1": Entry("thesis F1: open-loop response tau_p -> tau_q of the plant, piston fixed "
                "(resonance ~60 Hz model / ~25 Hz measured)"),
    "f2": Entry("thesis F2: T-N curve at 18 A on the plant alone (stall ~1700 N, no-load "
                "~150 mm/s, peak efficiency ~40 %)"),
    # hil.scenarios.f1_measured
    "f1-measured": Entry("thesis F1 as measured: stepped-sine open loop, piston held at the "
                         "cylinder end or through the testbed's rod path (resonance ~25 Hz "
                         "measured, ~60 Hz model)"),
    # hil.scenarios.current
    "current-step": Entry("iq 0 -> 10 A on the driver board, piston fixed: rise, overshoot, "
                          "steady-state error"),
    "current-bode": Entry("closed current loop frequency response, piston fixed: -3 dB "
                          "bandwidth (>= 1 kHz)"),
    # hil.scenarios.thesis
    "f3": Entry("thesis F3: 550 N pressure step, piston fixed: rise via current loop (5 ms) "
                "and via velocity loop (40 ms)"),
    "f4": Entry("thesis F4: pressure tracking error vs pump rotor angle with pulsation: "
                "p-p 0.63 MPa (velocity) -> 0.16 MPa (current), -74 %"),
    "f5": Entry("thesis F5: closed-loop pressure Bode, piston fixed, 0.85 MPa: -3 dB near "
                "100 Hz"),
    "f6": Entry("thesis F6: force Bode with the connecting rod fixed: 22 Hz weak beam, "
                "53 Hz reinforced"),
    # hil.scenarios.strain
    "f7": Entry("thesis F7: low-gain position control, cart moved by hand, seal friction: "
                "RMS force error 12.1 N (pressure fb) -> 1.3 N (strain fb)"),
    "f8": Entry("thesis F8: push/pull on a fixed force gauge while heating: RMS error of "
                "strain gauge 15.1 N > pressure 6.58 N > complementary filter 4.18 N"),
    # hil.scenarios.hip
    "f9": Entry("thesis F9: hip pitch position control through the whole stack, 0.25 deg "
                "sine: position and torque bandwidth 30-40 Hz, unreinforced beside it"),
    "f9-roll": Entry("thesis Fig. 6.22: F9 on the hip roll (K_p 6000 Nm/rad): position "
                     "bandwidth 30-40 Hz, torque gain falling before 30 Hz"),
    # hil.scenarios.bus_faults
    "bus-faults": Entry("a force sine over the fieldbus with one declared fault: watchdog "
                        "trips, safe-offs, lost frames, stale inputs, force error",
                        BUS_FAULT_KNOBS),
    # hil.scenarios.identify_rig
    "identify-rig": Entry("identification of a record from the independent rig (effects, "
                          "size, rate, noise as settings), judged against the rig's truth",
                          IDENTIFY_RIG_KNOBS),
}


__all__ = ["BUS_FAULT_KNOBS", "BUS_FAULT_TOPOLOGIES", "CATALOG", "IDENTIFY_RIG_KNOBS",
           "Entry"]
