"""The kernels' cache folder follows every source a kernel can depend on."""

from __future__ import annotations

from pathlib import Path

import numba

import hil.sim  # noqa: F401  (sets the cache folder)
from firmware_model import jit_cache

ROOT = Path(__file__).resolve().parents[2]


def test_the_cache_folder_is_named_by_the_sources_hash():
    assert Path(numba.config.CACHE_DIR).name == f"kernels-{jit_cache.fingerprint()}"


def test_the_hash_covers_the_tables_kernels_read_and_the_harness_kernels_only():
    files = {str(p.relative_to(ROOT)) for p in jit_cache._sources()}
    # a table the compiled board tick reads, and a kernel that calls other files' kernels
    assert {"firmware_model/fpga/layout.py", "plant/sensors/harness.py",
            "hil/sim/actuator.py", "hil/replay/fpga_replay.py"} <= files
    assert "hil/cli/root.py" not in files and "hil/scenarios/strain.py" not in files


def test_every_room_with_kernels_sets_the_cache_folder_first():
    """A room of hil/ holding a numba kernel imports jit_cache in its __init__ (run before
    any of its modules), so that no kernel is cached under the wrong folder."""
    rooms = {p.relative_to(ROOT / "hil").parts[0] for p in (ROOT / "hil").rglob("*.py")
             if b"@njit" in p.read_bytes() or b"@numba.njit" in p.read_bytes()}
    assert rooms >= {"sim", "replay"}
    missing = [r for r in sorted(rooms) if "import jit_cache"
               not in (ROOT / "hil" / r / "__init__.py").read_text()]
    assert not missing


def _child(code: str, env: dict[str, str] | None = None) -> str:
    """What a fresh Python process running ``code`` in the checkout prints."""
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, cwd=ROOT, env=env).stdout.strip()


def test_the_console_script_imports_neither_numpy_nor_numba_before_main():
    """What ``eha-hil`` imports before main() runs (hil, hil.cli) is light, so that a signal
    in the first second meets main's handlers (one line), not a traceback."""
    code = ("import sys, hil.cli; "
            "print(sorted(m for m in ('numpy', 'numba') if m in sys.modules))")
    assert _child(code) == "[]"


def test_the_command_line_and_the_configuration_import_no_numba():
    """numba's import is most of a command's start-up: the command line's root and the
    configuration (the presets, the layouts) leave it to the commands that run a kernel."""
    code = ("import sys, hil.cli.root, plant.config, firmware_model.fpga.layout; "
            "print('numba' in sys.modules)")
    assert _child(code) == "False"


def test_a_child_process_keeps_the_same_cache_folder():
    """The folder reaches numba through NUMBA_CACHE_DIR, which child processes inherit: a
    child of the same sources finds the same folder, not one nested inside it."""
    import os

    out = _child("import numba, hil.sim; print(numba.config.CACHE_DIR)", dict(os.environ))
    assert out == numba.config.CACHE_DIR


def test_a_user_s_cache_folder_is_the_parent(tmp_path):
    import os

    env = {k: v for k, v in os.environ.items() if k != jit_cache._OURS}
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    code = "import hil.sim, numba; print(numba.config.CACHE_DIR)"
    assert Path(_child(code, env)) == tmp_path / f"kernels-{jit_cache.fingerprint()}"

