"""The instruction count against an independent emulator: QEMU's netduinoplus2 running the
law's batch image single-stepped (``-singlestep -d exec,nochain``: one log line per
instruction, conditional ones in IT blocks included) on the same inputs as the harness's
image on Unicorn. The code of ``mcu_law.c`` is the same in both images, so the
instructions executed inside its functions must agree step by step. This is what found
that Unicorn calls no code hook for some instructions inside IT blocks."""

from __future__ import annotations

import re
import shutil
import struct
import subprocess

import numpy as np
import pytest
from elftools.elf.elffile import ELFFile
from unicorn import UC_HOOK_CODE

from firmware_model.mcu.c_abi import CONFIG, INPUT, OUTPUT, config_record
from hil.sim import mcu_builds
from hil.sim.image import memory_map as M
from hil.sim.image.law import ImageLaw
from hil.verify.mcu.steps import random_inputs
from plant.config import load_config

from .conftest import need_tools

STEPS = 40


def _law_functions(path) -> dict[str, tuple[int, int]]:
    """name -> (start, end) of the functions compiled from mcu_law.c."""
    out, current = {}, None
    with open(path, "rb") as f:
        for s in ELFFile(f).get_section_by_name(".symtab").iter_symbols():
            kind = s["st_info"]["type"]
            if kind == "STT_FILE":
                current = s.name
            elif kind == "STT_FUNC" and (s.name.startswith("mcu_law_") or (
                    s["st_info"]["bind"] == "STB_LOCAL" and current == "mcu_law.c")):
                start = s["st_value"] & ~1
                out[s.name] = (start, start + s["st_size"])
    return out


def _inside(ranges, address: int) -> bool:
    return any(a <= address < b for a, b in ranges)


def _qemu_counts(elf, config, inputs, work) -> list[int]:
    with open(work / "mcu_in.bin", "wb") as f:
        f.write(struct.pack("<5I", mcu_builds.MAGIC, CONFIG.itemsize, INPUT.itemsize,
                            OUTPUT.itemsize, len(inputs)))
        f.write(config.tobytes() + inputs.tobytes())
    subprocess.run([mcu_builds.QEMU, *mcu_builds.QEMU_ARGS, "-singlestep", "-d",
                    "exec,nochain", "-D", "exec.log", "-kernel", str(elf)], cwd=work,
                   check=True, capture_output=True, timeout=120)
    law = _law_functions(elf)
    entry, ranges = law["mcu_law_step"][0], list(law.values())
    counts: list[int] = []
    for m in re.finditer(r"Trace \d+: \S+ \[\w+/([0-9a-f]{8})/", (work / "exec.log").read_text()):
        a = int(m[1], 16)
        if a == entry:
            counts.append(0)
        if counts and _inside(ranges, a):
            counts[-1] += 1
    return counts


def test_instructions_per_step_agree_with_qemu(tmp_path):
    need_tools()
    if shutil.which(mcu_builds.QEMU) is None:
        pytest.skip(f"{mcu_builds.QEMU} not installed (make system-deps)")
    config = config_record(load_config(None, ()))
    inputs = random_inputs(STEPS, 11)
    expected = _qemu_counts(mcu_builds.build_image("off"), config, inputs, tmp_path)

    law = ImageLaw(None, config)
    ranges = list(_law_functions(law.image.path).values())
    table = law.core.costs
    count = [0]

    def hook(uc, address, size, user) -> None:
        if _inside(ranges, address):
            count[0] += int(table.count[(address - M.FLASH_BASE) >> 1])

    law.core.uc.ctl_remove_cache(M.FLASH_BASE, M.FLASH_BASE + M.FLASH_SIZE)
    law.core.uc.hook_add(UC_HOOK_CODE, hook)
    got, out = [], np.zeros((), OUTPUT)
    for k in range(STEPS):
        count[0] = 0
        law.step(inputs[k], out, f"step {k}")
        got.append(count[0])
    assert len(expected) == STEPS
    assert got == expected
    assert min(got) > 300  # the law ran, not a stub
