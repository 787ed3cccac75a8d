"""tests/session_once.py: a value made once per run, read back by every later caller."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.session_once import made_once


def test_the_value_is_made_once_and_read_back(tmp_path_factory: pytest.TempPathFactory
                                              ) -> None:
    calls: list[Path] = []

    def make(d: Path) -> dict[str, Path]:
        calls.append(d)
        (d / "made.txt").write_text("x")
        return {"file": d / "made.txt"}

    name = f"probe-{id(calls)}"
    first = made_once(tmp_path_factory, name, make)
    again = made_once(tmp_path_factory, name, make)
    assert len(calls) == 1 and again == first and first["file"].read_text() == "x"


def test_a_make_that_raised_is_made_again_in_an_empty_directory(
        tmp_path_factory: pytest.TempPathFactory) -> None:
    seen: list[list[str]] = []

    def make(d: Path) -> int:
        seen.append(sorted(p.name for p in d.iterdir()))
        (d / "half.txt").write_text("x")
        if len(seen) == 1:
            raise OSError("disk full")
        return 7

    name = f"probe-{id(seen)}"
    with pytest.raises(OSError):
        made_once(tmp_path_factory, name, make)
    assert made_once(tmp_path_factory, name, make) == 7
    assert seen == [[], []]
