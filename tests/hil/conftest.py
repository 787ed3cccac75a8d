"""Fixtures of the command-line tests."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def identify_record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 s measured-data record (``eha-hil identify-synth``), made once for the tests
    that interrupt ``eha-hil identify`` (they only read it)."""
    data = tmp_path_factory.mktemp("identify") / "d.csv"
    exe = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
    subprocess.run([exe, "identify-synth", str(data), "--seconds", "8"], check=True,
                   capture_output=True, timeout=300)
    return data
