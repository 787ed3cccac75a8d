"""Fixtures of the command-line tests."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.session_once import made_once


@pytest.fixture(scope="session")
def identify_record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 s measured-data record (``eha-hil identify-synth``), made once per run for the
    tests that interrupt ``eha-hil identify`` (they only read it; they are in two files,
    which the two xdist workers may each run one of)."""
    return made_once(tmp_path_factory, "identify-record", _synthesise)


def _synthesise(folder: Path) -> Path:
    data = folder / "d.csv"
    exe = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
    subprocess.run([exe, "identify-synth", str(data), "--seconds", "8"], check=True,
                   capture_output=True, timeout=300)
    return data
