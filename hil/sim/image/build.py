"""Builds the harness needs, each cached by the content of its inputs and its flags: the
C hooks (host compiler), the project's image (the MCU law behind the firmware interface)
and the shipped template (its own Makefile, arm-none-eabi-gcc)."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

from hil.sim.mcu_builds import (
    ARM_GCC,
    COMMON_FLAGS,
    BuildError,
    _cache_dir,
    compile_cached,
    host_compiler,
)

HERE = Path(__file__).resolve().parent
MCU_DIR = Path(__file__).resolve().parents[3] / "firmware_model" / "mcu"
IMAGE_DIR = MCU_DIR / "image"
TEMPLATE_DIR = IMAGE_DIR / "template"
#: The image's flags: the law's contraction decision (mcu_builds) and the Cortex-M4F.
CPU_FLAGS = ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard")
IMAGE_FLAGS = (*COMMON_FLAGS, *CPU_FLAGS, "-ffunction-sections", "-fdata-sections",
               "-ffp-contract=off", "-nostartfiles", "--specs=nano.specs",
               "-Wl,--gc-sections")
LAW_SOURCES = (TEMPLATE_DIR / "startup.c", IMAGE_DIR / "law_image.c",
               MCU_DIR / "c" / "mcu_law.c")
LAW_INPUTS = (*LAW_SOURCES, TEMPLATE_DIR / "eha_hil.h", TEMPLATE_DIR / "eha_hil.ld",
              MCU_DIR / "c" / "mcu_law.h")


def hooks_library() -> Path:
    """The Unicorn hooks (``hooks.c``) as a host shared library."""
    cc = host_compiler()
    if cc is None:
        raise BuildError("no C compiler (cc, gcc or $CC) for the image hooks")
    src = HERE / "hooks.c"
    return compile_cached(cc, ("-O2", "-Wall", "-fPIC", "-shared"), (src,), (src,), "eha_hooks.so")


def law_image() -> Path:
    """The project's image: the MCU law built for the firmware interface."""
    if shutil.which(ARM_GCC) is None:
        raise BuildError(f"{ARM_GCC} not installed (make system-deps)")
    flags = (*IMAGE_FLAGS, "-T", str(TEMPLATE_DIR / "eha_hil.ld"))
    return compile_cached(ARM_GCC, flags, LAW_SOURCES, LAW_INPUTS, "mcu_law_image.elf")


def template_image(src: Path = TEMPLATE_DIR) -> Path:
    """The template's image, built by its own Makefile in a copy under the cache (the
    source tree stays clean)."""
    if shutil.which(ARM_GCC) is None or shutil.which("make") is None:
        raise BuildError(f"{ARM_GCC} or make not installed (make system-deps)")
    files = sorted(p for p in src.iterdir() if p.is_file())
    digest = hashlib.sha256()
    for p in files:
        digest.update(p.name.encode() + p.read_bytes())
    work = _cache_dir() / f"template-{digest.hexdigest()[:16]}"
    elf = work / "firmware.elf"
    if elf.exists():
        return elf
    # Built in a folder of this process's own, then renamed: two test workers may race.
    tmp = work.with_name(f"{work.name}.tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for p in files:
        shutil.copy2(p, tmp / p.name)
    r = subprocess.run(["make", "-s"], cwd=tmp, capture_output=True, text=True)
    if r.returncode or not (tmp / "firmware.elf").exists():
        lines = (r.stderr or r.stdout).strip().splitlines() or ["no message"]
        shutil.rmtree(tmp, ignore_errors=True)
        raise BuildError(f"template make failed: {lines[0]}")
    try:
        tmp.rename(work)
    except OSError:  # another process finished first: use its build
        shutil.rmtree(tmp, ignore_errors=True)
    return elf
