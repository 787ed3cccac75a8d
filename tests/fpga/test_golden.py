"""Golden vectors: the fixed-point FOC chain reproduces the checked-in outputs bit for bit.

``tests/fpga/golden_vectors.json`` was written by ``python -m firmware_model.fpga.golden
--write``. Every row is replayed through the compiled function and through ``fn.py_func``
on Python ints; and the vectors regenerated in memory must equal the file, so any change of
the arithmetic (a constant, a rounding, a clamp) fails here until the file is regenerated
on purpose (``docs/fpga.md``, "Golden vectors").
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from firmware_model.fpga import golden

PATH = Path(__file__).with_name("golden_vectors.json")
NAMES = list(golden.FIELDS)


@pytest.fixture(scope="module")
def vectors() -> dict[str, Any]:
    return json.loads(PATH.read_text())


def test_file_layout(vectors: dict[str, Any]) -> None:
    """Header names every function with its field order; rows have that many integers."""
    fields = vectors["header"]["fields"]
    assert sorted(fields) == sorted(NAMES)
    assert sorted(k for k in vectors if k != "header") == sorted(NAMES)
    for name in NAMES:
        n = len(fields[name]["inputs"]) + len(fields[name]["outputs"])
        rows = vectors[name]
        assert 150 <= len(rows) <= 300, name
        bad = [r for r in rows if len(r) != n or not all(type(x) is int for x in r)]
        assert not bad, f"{name}: malformed rows {bad[:3]}"
    assert PATH.stat().st_size < 300_000


@pytest.mark.parametrize("python", [False, True], ids=["compiled", "py_func"])
@pytest.mark.parametrize("name", NAMES)
def test_reproduces_every_output(vectors: dict[str, Any], name: str, python: bool) -> None:
    """Each row's outputs equal the model's, exactly, compiled and as Python source."""
    fields = vectors["header"]["fields"][name]
    n_in = len(fields["inputs"])
    failures = []
    for row in vectors[name]:
        args, want = row[:n_in], tuple(row[n_in:])
        got = golden.outputs(name, args, python=python)
        if got != want:
            named = ", ".join(f"{f}={v}" for f, v in zip(fields["inputs"], args, strict=True))
            failures.append(f"{name}({named}) = {got}, golden {want} "
                            f"({', '.join(fields['outputs'])})")
    variant = "py_func" if python else "compiled"
    assert not failures, (
        f"{len(failures)} of {len(vectors[name])} {name} vectors differ ({variant}):\n"
        + "\n".join(failures[:10])
    )


def test_regenerated_vectors_equal_file(vectors: dict[str, Any]) -> None:
    """Regenerating in memory gives the file: same inputs, same outputs, same header."""
    fresh = json.loads(golden.dumps(golden.generate()))
    assert fresh["header"] == vectors["header"]
    for name in NAMES:
        n_in = len(fresh["header"]["fields"][name]["inputs"])
        old, new = vectors[name], fresh[name]
        assert len(old) == len(new), f"{name}: {len(new)} rows generated, {len(old)} in file"
        for k, (a, b) in enumerate(zip(old, new, strict=True)):
            assert a[:n_in] == b[:n_in], f"{name} row {k}: inputs {b[:n_in]}, file {a[:n_in]}"
            assert a == b, f"{name} row {k} inputs {a[:n_in]}: outputs {b[n_in:]}, file {a[n_in:]}"
    assert fresh == vectors


def test_file_text_is_canonical() -> None:
    """The file is byte-identical to what ``--write`` produces (no hand edits)."""
    assert PATH.read_text() == golden.dumps(golden.generate())


def test_cli_check(tmp_path: Path) -> None:
    """``--write`` then ``--check`` succeeds; a tampered output makes ``--check`` fail."""
    path = tmp_path / "v.json"
    assert golden.main(["--write", str(path)]) == 0
    assert golden.main(["--check", str(path)]) == 0
    data = json.loads(path.read_text())
    data["clarke"][0][-1] += 1
    path.write_text(json.dumps(data))
    assert golden.main(["--check", str(path)]) == 1
