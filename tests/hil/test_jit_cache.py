"""The kernels' cache folder follows every source a kernel can depend on."""

from __future__ import annotations

from pathlib import Path

import numba

import hil  # noqa: F401  (sets the cache folder)
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
