"""The command line, ``eha-hil``: the only package that reads arguments, prints for people
and chooses exit codes. The root (:mod:`hil.cli.root`) builds the parser of every verb
and runs one; each other module here is one group of verbs.

Nothing outside this package imports it (``tests/hil/test_layering.py``).
"""

from __future__ import annotations

from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    """The console script ``eha-hil`` (``hil.cli:main``); imports the root only when run."""
    from hil.cli.root import main as run

    return run(argv)
