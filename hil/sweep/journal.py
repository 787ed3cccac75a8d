"""The sweep's journal: every finished point on disk, for ``--resume``.

A JSON-lines file beside the results table (``OUT.points.jsonl`` for ``--out OUT``): a
header line naming the sweep (its fingerprint: scenario, base configuration and every
point's values), then one record per finished point, written and flushed as it arrives. A
sweep stopped at any moment (Ctrl-C, a lost machine) leaves every finished point readable;
a line cut short by the stop is dropped when the sweep resumes. JSON keeps floats exact, so
a resumed table equals an uninterrupted one.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

MAGIC = "eha-hil sweep journal"


class JournalError(Exception):
    """The journal cannot be resumed (another sweep's, unreadable): one line."""


def journal_path(out: str | Path) -> Path:
    """Where the journal of a sweep writing ``out`` lives."""
    out = Path(out)
    return out.with_name(out.name + ".points.jsonl")


class Journal:
    """Opens (fresh or resumed) on :meth:`start`; :meth:`append` adds a finished point."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._file = None

    def _read(self, fingerprint: str) -> dict[int, dict[str, Any]]:
        try:
            lines = self.path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise JournalError(f"--resume: {self.path}: cannot read: {exc}") from None
        try:
            header = json.loads(lines[0]) if lines else {}
        except json.JSONDecodeError:
            header = {}
        if header.get("journal") != MAGIC:
            raise JournalError(f"--resume: {self.path}: not a sweep journal")
        if header.get("fingerprint") != fingerprint:
            raise JournalError(
                f"--resume: {self.path} was written by another sweep (scenario "
                f"{header.get('scenario')!r}, {header.get('points')} points: a different "
                "scenario, configuration or parameter set); drop --resume to start over")
        done: dict[int, dict[str, Any]] = {}
        for line in lines[1:]:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # the line a stop cut short
            if isinstance(rec, dict) and isinstance(rec.get("point"), int):
                done[rec["point"]] = rec
        return done

    def start(self, fingerprint: str, scenario: str, points: int, resume: bool
              ) -> dict[int, dict[str, Any]]:
        """Open the journal; with ``resume`` (and a journal there) the points it holds."""
        done = self._read(fingerprint) if resume and self.path.exists() else {}
        header = {"journal": MAGIC, "fingerprint": fingerprint, "scenario": scenario,
                  "points": points}
        # Rewritten whole (header + kept records), then appended to: no cut line survives.
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            with tmp.open("w", encoding="utf-8") as f:
                f.write(json.dumps(header) + "\n")
                for index in sorted(done):
                    f.write(json.dumps(done[index]) + "\n")
            os.replace(tmp, self.path)
        except OSError:
            tmp.unlink(missing_ok=True)  # a full disk: no half journal left behind
            raise
        self._file = self.path.open("a", encoding="utf-8")
        return done

    def append(self, record: dict[str, Any]) -> None:
        assert self._file is not None, "start() first"
        self._file.write(json.dumps(record) + "\n")
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def readable(path: Path) -> str:
    """"" if a journal's header reads (for the Ctrl-C line), else why not."""
    try:
        with path.open(encoding="utf-8") as f:
            header = json.loads(f.readline())
    except (OSError, ValueError) as exc:
        return str(exc)
    return "" if header.get("journal") == MAGIC else "no journal header"
