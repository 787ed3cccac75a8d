"""The Python MCU model against the C law built by real compilers: a host shared library and
a Cortex-M4F image run by QEMU. Tests that need an absent tool skip and say which."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.mcu.c_abi import OUTPUT, config_record
from hil.cli import main
from hil.sim import mcu_builds
from hil.verify.compare import compare
from hil.verify.mcu.model import run_model
from hil.verify.mcu.steps import random_inputs
from hil.verify.mcu.verify import FIELD_NAMES, verify_mcu
from plant.config import load_config


def _need(target: str) -> None:
    missing = mcu_builds.missing_tools(target)
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (make system-deps)")


def _cpu_has_fma() -> bool:
    try:
        return " fma " in Path("/proc/cpuinfo").read_text().replace("\n", " ")
    except OSError:
        return False


def test_register_numbers_in_the_c_header_are_the_layout_s():
    text = (mcu_builds.SOURCE_DIR / "mcu_law.h").read_text()
    defines = dict(re.findall(r"#define ([UD]_[A-Z_]+) (0x[0-9A-F]+|\d+)", text))
    assert len(defines) >= 14
    for name, value in defines.items():
        if name in ("UP_WORDS", "DOWN_WORDS"):
            continue
        assert int(value, 0) == getattr(B, name), name
    assert int(re.search(r"#define UP_WORDS (\d+)", text)[1]) == B.UP_WORDS
    assert int(re.search(r"#define DOWN_WORDS (\d+)", text)[1]) == B.DOWN_WORDS


def test_compare_names_the_first_differing_word():
    cfg = load_config()
    out = run_model(cfg, random_inputs(50, 5))
    changed = out.copy()
    changed["down"][30, B.D_VQ_FF] ^= 1
    changed["tau_p"][31] = np.nextafter(changed["tau_p"][31], np.float32(np.inf))
    c = compare("t", out, changed, FIELD_NAMES)
    assert (c.vectors, c.mismatches) == (50, 2)
    assert (c.first.step, c.first.field) == (30, "down.vq_ff")
    assert c.fields == {"down.vq_ff": 1, "tau_p": 1}
    assert compare("t", out, out.copy(), FIELD_NAMES).mismatches == 0


def test_host_c_is_bit_identical_to_the_model():
    _need("host-c")
    rep = verify_mcu("host-c", steps=12_000, seed=2, stack_seconds=0.2)
    assert rep.vectors >= 12_000 + 6 * 1000
    assert rep.mismatches == 0, rep.as_dict()["first_mismatch"]


def test_the_steps_reach_every_status_bit_the_law_sets():
    """The compared steps are not all alike: limits, watchdog, board and link bits all occur."""
    cfg = load_config(None, ("mcu.force_feedback=strain",))
    status = np.bitwise_or.reduce(run_model(cfg, random_inputs(6000, 3))["status"])
    assert status & 0x3FF == 0x3FF


@pytest.mark.slow
def test_contracted_host_build_is_caught():
    _need("host-c")
    if not _cpu_has_fma():
        pytest.skip("this CPU has no FMA: the contracted host build cannot run")
    rep = verify_mcu("host-c", steps=600, stack_seconds=0, contract="fast")
    assert rep.mismatches > 0


@pytest.mark.skipif(shutil.which(mcu_builds.ARM_OBJDUMP) is None,
                    reason=f"{mcu_builds.ARM_OBJDUMP} not installed (make system-deps)")
def test_firmware_image_has_no_fused_multiply_add():
    assert mcu_builds.fused_instructions(mcu_builds.build_image("off")) == []
    assert mcu_builds.fused_instructions(mcu_builds.build_image("fast"))


@pytest.mark.slow
def test_cortex_m4_image_under_qemu_is_bit_identical_to_the_model():
    """At least 10^4 steps on the emulated STM32F405, random and from whole-stack runs."""
    _need("qemu")
    rep = verify_mcu("qemu", steps=10_000, seed=3, stack_seconds=0.2)
    assert rep.vectors >= 10_000
    assert rep.mismatches == 0, rep.as_dict()["first_mismatch"]


@pytest.mark.slow
def test_contracted_image_under_qemu_is_caught():
    _need("qemu")
    rep = verify_mcu("qemu", steps=600, stack_seconds=0, contract="fast")
    assert rep.mismatches > 0
    assert rep.first.first.field


@pytest.mark.slow
def test_qemu_reruns_are_identical():
    _need("qemu")
    cfg = load_config()
    inputs = random_inputs(500, 9)
    elf = mcu_builds.build_image("off")
    a = mcu_builds.run_qemu(elf, config_record(cfg), inputs)
    b = mcu_builds.run_qemu(elf, config_record(cfg), inputs)
    assert a.dtype == OUTPUT and a.tobytes() == b.tobytes()


def test_cli_verify_mcu_reports_json(capsys):
    _need("host-c")
    assert main(["verify", "mcu", "--against", "host-c", "--steps", "300",
                 "--stack-seconds", "0", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["vectors"], data["mismatches"], data["first_mismatch"]) == (300, 0, None)


def test_cli_verify_mcu_names_the_first_mismatch(capsys):
    _need("qemu")
    assert main(["verify", "mcu", "--against", "qemu", "--steps", "300", "--stack-seconds",
                 "0", "--contract", "fast"]) == 1
    out = capsys.readouterr().out
    assert re.search(r"300 vectors compared, [1-9]\d* mismatches", out)
    assert re.search(r"first mismatch: random \S+, step \d+, field \S+: model .+, build", out)


@pytest.mark.parametrize("argv", [
    ["--against", "arm"], ["--against", "qemu", "--steps", "-3"],
    ["--against", "host-c", "--stack-seconds", "x"],
])
def test_cli_verify_mcu_bad_input_is_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["verify", "mcu", *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_a_broken_build_is_one_line(monkeypatch, tmp_path):
    """A compiler error reaches the user as one line naming the compiler's first error."""
    _need("host-c")
    src = tmp_path / "c"
    shutil.copytree(mcu_builds.SOURCE_DIR, src)
    # The error in the lanes file: a file with an error is only parsed, and the lanes file
    # is the build's long one to optimise (~3 s of CPU; mcu_law.c ~0.1 s).
    law = src / "mcu_law_lanes.c"
    law.write_text(law.read_text() + "\nint broken(void) { return }\n")
    monkeypatch.setattr(mcu_builds, "SOURCE_DIR", src)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    with pytest.raises(mcu_builds.BuildError) as exc:
        mcu_builds.build_host()
    assert "\n" not in str(exc.value) and "error" in str(exc.value)


@pytest.mark.slow  # a fresh process
def test_a_build_keeps_its_own_functions_after_another_build_went_global():
    """The robot engine loads the plain build with global symbols (numba calls it by name).
    A contracted build loaded after it in the same process must still run its own
    functions, not the plain build's: the comparison has to catch it there too."""
    _need("host-c")
    if not _cpu_has_fma():
        pytest.skip("this CPU has no FMA: the contracted host build cannot run")
    code = ("import llvmlite.binding as llvm\n"
            "from hil.sim import mcu_builds\n"
            "from hil.verify.mcu.verify import verify_mcu\n"
            "llvm.load_library_permanently(str(mcu_builds.build_host('off')))\n"
            "print(verify_mcu('host-c', steps=600, stack_seconds=0, contract='fast')"
            ".mismatches)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2])
    assert int(out.stdout.split()[-1]) > 0
