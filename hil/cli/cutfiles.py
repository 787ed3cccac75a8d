"""One way to say that an input file ends early, for every reader (MCAP frame logs,
pcap/pcapng captures, BLF/ASC/candump CAN logs, measured-data CSV).

A cut file (a killed writer, a full disk, an interrupted copy) is read up to its last
complete record and then reported with one line on stderr, the same for every format and
command: ``eha-hil VERB: FILE: truncated: WHY; read up to t = X s``. The command's exit
code is then :data:`EXIT_TRUNCATED` (1): a script must not take a part for the whole.
"""

from __future__ import annotations

import sys

#: Exit code of a command whose input was cut (its result covers the part it read).
EXIT_TRUNCATED = 1


def message(path: object, why: str, until_s: float | None, what: str = "read") -> str:
    """``FILE: truncated: WHY; read up to t = X s`` (or ``nothing``): a command's
    ``Outcome.error``, which the root prints after the verb."""
    upto = "nothing" if until_s is None else f"t = {until_s:.6f} s"
    return f"{path}: truncated: {why}; {what} up to {upto}"


def line(verb: str, path: object, why: str, until_s: float | None, what: str = "read"
         ) -> str:
    """``eha-hil VERB: FILE: truncated: WHY; read up to t = X s`` (or ``nothing``)."""
    return f"eha-hil {verb}: {message(path, why, until_s, what)}"


def report(verb: str, path: object, why: str, until_s: float | None, what: str = "read"
           ) -> int:
    """Print :func:`line` on stderr; return EXIT_TRUNCATED."""
    print(line(verb, path, why, until_s, what), file=sys.stderr)
    return EXIT_TRUNCATED


__all__ = ["EXIT_TRUNCATED", "line", "message", "report"]
