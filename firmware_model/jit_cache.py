"""Where numba keeps the compiled kernels: one cache folder per version of their sources.

numba checks a cached kernel only against its own source file. A kernel that calls a
kernel of another file, or reads a module constant of another file (a layout's index, a
table of analog inputs), keeps running the cached machine code of the old version after
that other file changed. So the cache lives in a folder named by a hash of every source
the kernels can depend on: all of ``protocols``, ``firmware_model`` and ``plant``, and the
files of ``hil`` that hold kernels. An edit there compiles the kernels afresh (once); an
edit elsewhere (the CLI, scenarios, docs) keeps the cache.

Imported by the ``__init__`` of every package with kernels, before any kernel is defined
(numba picks a kernel's cache folder when its decorator runs). A ``NUMBA_CACHE_DIR`` the
user set is kept as the parent folder.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numba

_ROOT = Path(__file__).resolve().parent.parent
_PACKAGES = ("protocols", "firmware_model", "plant")


def _sources() -> list[Path]:
    files = [f for p in _PACKAGES for f in (_ROOT / p).rglob("*.py")]
    files += [f for f in (_ROOT / "hil").rglob("*.py") if b"njit" in f.read_bytes()]
    return sorted(files)


def fingerprint() -> str:
    """Hash of the kernels' sources (path and content of each file)."""
    h = hashlib.sha256()
    for f in _sources():
        h.update(f.relative_to(_ROOT).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    parent = Path(numba.config.CACHE_DIR) if numba.config.CACHE_DIR else \
        _ROOT / "firmware_model" / "__pycache__"
    return parent / f"kernels-{fingerprint()}"


if not getattr(numba.config, "_EHA_HIL_CACHE", None):
    numba.config.CACHE_DIR = str(cache_dir())
    numba.config._EHA_HIL_CACHE = numba.config.CACHE_DIR
