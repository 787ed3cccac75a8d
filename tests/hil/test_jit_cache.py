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


def test_the_console_script_imports_neither_numpy_nor_numba_before_main():
    """What ``eha-hil`` imports before main() runs (hil, hil.cli) is light, so that a signal
    in the first second meets main's handlers (one line), not a traceback."""
    import subprocess
    import sys

    code = ("import sys, hil.cli; "
            "print(sorted(m for m in ('numpy', 'numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.strip()
    assert out == "[]"
