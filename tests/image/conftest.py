"""Shared pieces of the firmware-image tests: skips with a reason where Unicorn or the Arm
cross compiler is missing, and small images built from C or assembly in a session cache."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("unicorn", reason="unicorn not installed (pip install eha-hil)")

from hil.sim import mcu_builds  # noqa: E402
from hil.sim.image import build  # noqa: E402


def need_tools() -> None:
    missing = mcu_builds.missing_tools("image")
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (make system-deps)")


@pytest.fixture(scope="session")
def make_image(tmp_path_factory):
    """``make_image(source, suffix=".c", startup=True)``: an image of the template's
    startup (unless ``startup`` is false), linker script and ``source`` (C or assembly);
    built once per source."""
    need_tools()
    out_dir = tmp_path_factory.mktemp("images")

    def make(source: str, suffix: str = ".c", startup: bool = True) -> Path:
        digest = hashlib.sha256((f"{suffix}{startup}" + source).encode()).hexdigest()[:12]
        elf = out_dir / f"{digest}.elf"
        if elf.exists():
            return elf
        src = out_dir / f"{digest}{suffix}"
        src.write_text(source)
        t = build.TEMPLATE_DIR
        r = subprocess.run([mcu_builds.ARM_GCC, *build.IMAGE_FLAGS, "-I", str(t), "-T",
                            str(t / "eha_hil.ld"), *([str(t / "startup.c")] if startup else []),
                            str(src), "-o", str(elf)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        return elf

    return make


@pytest.fixture(scope="session")
def law_image():
    need_tools()
    return build.law_image()


def host_elf(tmp_path: Path) -> Path:
    """A host (x86-64 or whatever this is) executable: an ELF for another architecture."""
    cc = mcu_builds.host_compiler()
    if cc is None:
        pytest.skip("no host C compiler")
    src = tmp_path / "main.c"
    src.write_text("int main(void) { return 0; }\n")
    out = tmp_path / "host.elf"
    subprocess.run([cc, str(src), "-o", str(out)], check=True)
    return out


__all__ = ["host_elf", "need_tools", "shutil"]
