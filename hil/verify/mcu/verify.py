"""``eha-hil verify mcu``: the Python MCU model against the C law built for the host, for
the Cortex-M4F under QEMU, or as the harness's firmware image on Unicorn (with its
execution-time profile per set), on random steps and on steps recorded from whole-stack
runs with faults, in all six controller variants."""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.mcu.c_abi import config_record
from hil.sim import mcu_builds
from hil.verify.compare import ComparedSets, Comparison, compare
from hil.verify.mcu.model import run_model
from hil.verify.mcu.stack_steps import stack_inputs
from hil.verify.mcu.steps import VARIANTS, random_sets
from plant.config import Config, load_config

AGAINST = ("host-c", "qemu", "image")
FIELD_NAMES = {"down": [name for _, name, *_ in B.DOWN_REGISTERS],
               "m_analog": [a.si_name for a in B.ANALOG_INPUTS]}


@dataclass
class McuVerification(ComparedSets):
    against: str
    contract: str
    build: str
    sets: list[Comparison] = field(default_factory=list)
    seconds: float = 0.0
    profiles: list[dict] = field(default_factory=list)  # --against image: per set

    def as_dict(self) -> dict:
        first = self.first
        return {"against": self.against, "contract": self.contract, "build": self.build,
                "vectors": self.vectors, "mismatches": self.mismatches,
                "first_mismatch": None if first is None else
                {"set": first.source, **first.as_dict()["first"]},
                "sets": [c.as_dict() for c in self.sets], "seconds": self.seconds,
                **({"execution_time": self.profiles} if self.profiles else {})}


def input_sets(steps: int, seed: int, stack_seconds: float, source: str | None = None,
               overrides: Sequence[str] = ()) -> Iterator[tuple[str, Config, np.ndarray]]:
    """(label, configuration, inputs): whole-stack recordings first (``stack_seconds`` of
    each variant), then ``steps`` random steps over the variants; each variant's
    configuration is ``source`` (a preset or file, None: the default) with ``overrides``,
    then the variant's keys."""
    def cfg_for(variant: tuple[str, ...]) -> Config:
        return load_config(source, (*overrides, *variant))

    label = {v: "/".join(x.split("=")[1] for x in v) for v in VARIANTS}
    if stack_seconds > 0:
        for v in VARIANTS:
            cfg = cfg_for(v)
            yield f"stack {label[v]}", cfg, stack_inputs(cfg, stack_seconds)
    for v, inputs in random_sets(steps, seed):
        yield f"random {label[v]}", cfg_for(v), inputs


def verify_mcu(against: str, steps: int, seed: int = 1, stack_seconds: float = 0.4,
               contract: str = "off", source: str | None = None,
               overrides: Sequence[str] = ()) -> McuVerification:
    """Compare every output word and float of the model and the build, step by step."""
    if against not in AGAINST:
        raise ValueError(f"--against {against!r}: expected one of {', '.join(AGAINST)}")
    t0 = time.perf_counter()
    profiles: list[dict] = []
    if against == "host-c":
        path = mcu_builds.build_host(contract)
        law = mcu_builds.HostLaw(path)
        run = law.run
    elif against == "image":
        from hil.sim.image import build
        from hil.sim.image.law import ImageLaw

        if contract != "off":
            raise ValueError("--against image: the image is built with -ffp-contract=off")
        path = build.law_image()

        def run(config: np.ndarray, inputs: np.ndarray) -> np.ndarray:
            law = ImageLaw(path, config, label)
            out = law.run(inputs)
            profiles.append(law.profile.summary())
            return out
    else:
        path = mcu_builds.build_image(contract)

        def run(config: np.ndarray, inputs: np.ndarray) -> np.ndarray:
            return mcu_builds.run_qemu(path, config, inputs)

    report = McuVerification(against, contract, str(path), profiles=profiles)
    for label, cfg, inputs in input_sets(steps, seed, stack_seconds, source, overrides):
        model = run_model(cfg, inputs)
        built = run(config_record(cfg), inputs)
        report.sets.append(compare(label, model, built, FIELD_NAMES))
    report.seconds = time.perf_counter() - t0
    return report
