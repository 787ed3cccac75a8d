"""The names the parsers offer (scenarios, options of the synthetic records), without the
simulation.

Their sources (:mod:`hil.scenarios`, :mod:`hil.identify.rig`, :mod:`hil.identify.synth`)
load the compiled kernels (numba, ~0.5 s of CPU) when imported; building the parser must
not, or ``eha-hil run --help`` and a mistyped option pay for a simulation that never runs.
What cannot be read from a light module is copied here, and
``tests/hil/test_cli_startup.py`` holds every copy equal to its source: a scenario added,
renamed or given a new summary or setting fails that test until it is listed here too.
"""

from __future__ import annotations

#: Every scenario of :data:`hil.scenarios.SCENARIOS`, by name: (name, summary, the names
#: of its settings), as ``eha-hil run --help`` lists them.
SCENARIOS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("bus-faults", "a force sine over the fieldbus with one declared fault: watchdog trips, "
     "safe-offs, lost frames, stale inputs, force error",
     ("topology", "model", "seconds", "link", "kind", "rate", "start_s", "end_s", "delay",
      "bits", "box", "slot", "signal", "sigma", "amplitude_n", "frequency_hz")),
    ("current-bode", "closed current loop frequency response, piston fixed: -3 dB bandwidth "
     "(>= 1 kHz)", ()),
    ("current-step", "iq 0 -> 10 A on the driver board, piston fixed: rise, overshoot, "
     "steady-state error", ()),
    ("f1", "thesis F1: open-loop response tau_p -> tau_q of the plant, piston fixed "
     "(resonance ~60 Hz model / ~25 Hz measured)", ()),
    ("f1-measured", "thesis F1 as measured: stepped-sine open loop, piston held at the "
     "cylinder end or through the testbed's rod path (resonance ~25 Hz measured, ~60 Hz "
     "model)", ()),
    ("f2", "thesis F2: T-N curve at 18 A on the plant alone (stall ~1700 N, no-load ~150 "
     "mm/s, peak efficiency ~40 %)", ()),
    ("f3", "thesis F3: 550 N pressure step, piston fixed: rise via current loop (5 ms) and "
     "via velocity loop (40 ms)", ()),
    ("f4", "thesis F4: pressure tracking error vs pump rotor angle with pulsation: p-p 0.63 "
     "MPa (velocity) -> 0.16 MPa (current), -74 %", ()),
    ("f5", "thesis F5: closed-loop pressure Bode, piston fixed, 0.85 MPa: -3 dB near 100 Hz",
     ()),
    ("f6", "thesis F6: force Bode with the connecting rod fixed: 22 Hz weak beam, 53 Hz "
     "reinforced", ()),
    ("f7", "thesis F7: low-gain position control, cart moved by hand, seal friction: RMS "
     "force error 12.1 N (pressure fb) -> 1.3 N (strain fb)", ()),
    ("f8", "thesis F8: push/pull on a fixed force gauge while heating: RMS error of strain "
     "gauge 15.1 N > pressure 6.58 N > complementary filter 4.18 N", ()),
    ("f9", "thesis F9: hip pitch position control through the whole stack, 0.25 deg sine: "
     "position and torque bandwidth 30-40 Hz, unreinforced beside it", ()),
    ("f9-roll", "thesis Fig. 6.22: F9 on the hip roll (K_p 6000 Nm/rad): position bandwidth "
     "30-40 Hz, torque gain falling before 30 Hz", ()),
    ("identify-rig", "identification of a record from the independent rig (effects, size, "
     "rate, noise as settings), judged against the rig's truth",
     ("load", "effect", "effect2", "magnitude", "profile", "seconds", "rate_hz", "noise_lsb",
      "spread")),
)

#: :data:`hil.identify.rig.TEMPERATURE_SHAPES`' names, in its order.
RIG_TEMPERATURE_SHAPES: tuple[str, ...] = ("constant", "ramp", "ramp_level", "steps",
                                           "oscillation")
#: :data:`hil.identify.rig.INTERSAMPLE`.
RIG_INTERSAMPLE: tuple[str, ...] = ("continuous", "zoh")
#: :data:`hil.identify.synth.PROFILES`, in its order.
SYNTH_PROFILES: tuple[str, ...] = ("multisine", "resonance", "slide")


def scenario_names() -> list[str]:
    """As :func:`hil.scenarios.names`: sorted."""
    return sorted(name for name, _, _ in SCENARIOS)


def rig_effects() -> tuple[str, ...]:
    """:data:`hil.identify.rig.RIG_EFFECTS` from the rig's registry (a light module): the
    library's effects, then those outside it."""
    from hil.identify.rig_effects import RIG_REGISTRY

    return (tuple(n for n, e in RIG_REGISTRY.items() if e.library)
            + tuple(n for n, e in RIG_REGISTRY.items() if not e.library))


def synth_effects() -> tuple[str, ...]:
    """:data:`hil.identify.synth.ALL_SYNTH_EFFECTS` from the plant generator's registry (a
    light module): the plant's effects, the wrappers', those outside the model."""
    from hil.identify.synth_effects import SYNTH_REGISTRY

    return tuple(n for kind in ("plant", "wrapper", "outside")
                 for n, e in SYNTH_REGISTRY.items() if e.kind == kind)
