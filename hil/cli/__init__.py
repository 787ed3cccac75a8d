"""The command line, ``eha-hil``: the only package that reads arguments, prints for people
and chooses exit codes. The root (:mod:`hil.cli.root`) builds the registry of every verb and
runs one through the contract of :mod:`hil.cli.contract`; each other module here is one
group of verbs.

Nothing outside this package imports it (``tests/hil/test_layering.py``). This file stays
light: the console script imports it before anything else, and a signal in the second the
root's imports take (numpy, numba) must still end the command with its one line.
"""

from __future__ import annotations

from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    """The console script ``eha-hil`` (``hil.cli:main``)."""
    import sys

    from hil.cli import signals

    signals.install_early()
    try:
        from hil.cli.root import main as run
    except KeyboardInterrupt as exc:
        from hil.cli import progress

        print(progress.interrupted_line(signals.signal_of(exc)), file=sys.stderr, flush=True)
        return 128 + signals.signal_of(exc)
    return run(argv)
