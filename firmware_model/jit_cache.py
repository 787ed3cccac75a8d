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

numba itself is not imported here: its import is most of a command's start-up, and a
command that runs no kernel (a log's summary, a mistake in the arguments) need not pay it.
Before numba is loaded the folder is handed to it through ``NUMBA_CACHE_DIR``, which numba
reads when it is imported (and which child processes inherit: :data:`_OURS` tells them the
folder is this module's, not the user's parent folder).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

_ROOT = Path(__file__).resolve().parent.parent
_PACKAGES = ("protocols", "firmware_model", "plant")
#: The environment variable numba reads its cache folder from.
_NUMBA_VAR = "NUMBA_CACHE_DIR"
#: Set beside :data:`_NUMBA_VAR` when this module put the folder there.
_OURS = "EHA_HIL_KERNEL_CACHE"


def _py_files(top: str) -> list[Path]:
    """The ``.py`` files under ``top`` (os.walk: several times faster than ``rglob``, and
    this runs at every start)."""
    found = []
    for folder, subs, names in os.walk(_ROOT / top):
        subs[:] = [d for d in subs if d != "__pycache__"]
        found += [Path(folder, n) for n in names if n.endswith(".py")]
    return found


def _sources() -> list[Path]:
    files = [f for p in _PACKAGES for f in _py_files(p)]
    files += [f for f in _py_files("hil") if b"njit" in f.read_bytes()]
    return sorted(files)


def fingerprint() -> str:
    """Hash of the kernels' sources (path and content of each file)."""
    h = hashlib.sha256()
    for f in _sources():
        h.update(f.relative_to(_ROOT).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def _parent() -> Path:
    """The folder the kernel folders live in: the user's ``NUMBA_CACHE_DIR``, or ours."""
    numba = sys.modules.get("numba")
    given = numba.config.CACHE_DIR if numba is not None else os.environ.get(_NUMBA_VAR, "")
    if given and given == os.environ.get(_OURS):  # a parent process's choice: its parent
        return Path(given).parent
    return Path(given) if given else _ROOT / "firmware_model" / "__pycache__"


def cache_dir() -> Path:
    return _parent() / f"kernels-{fingerprint()}"


def _configure() -> None:
    numba = sys.modules.get("numba")
    if numba is None:  # numba reads the variable when (if ever) it is imported
        os.environ[_NUMBA_VAR] = os.environ[_OURS] = str(cache_dir())
    elif not getattr(numba.config, "_EHA_HIL_CACHE", None):
        numba.config.CACHE_DIR = str(cache_dir())
        numba.config._EHA_HIL_CACHE = numba.config.CACHE_DIR


_configure()
