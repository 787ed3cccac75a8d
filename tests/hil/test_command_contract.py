"""Every command keeps one contract: it is registered with a ``run(args, ctx)`` that returns
an Outcome, and the root alone prints it. The registry is walked, so a new command is
covered without editing this file: each gets a planted mistake (one line ``eha-hil VERB:
what``, exit 2) and a planted result holding NaN and infinities (with ``--json``: strictly
valid JSON, the missing numbers as null). Then the root's own jobs on real runs: a stdout
that cannot be written, SIGTERM and SIGHUP, a signal while the command line is importing.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import io
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hil.cli import contract, root
from hil.cli.args import walk
from hil.cli.contract import Outcome, UsageError

ROOT = Path(__file__).resolve().parents[2]
CLI = ROOT / "hil" / "cli"


def _leaves() -> list[argparse.ArgumentParser]:
    return [p for p in walk(root.build_parser())
            if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)]


def _has_json(p: argparse.ArgumentParser) -> bool:
    return any("--json" in a.option_strings for a in p._actions)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, str]:
    """Values for required positionals that pass their argument types."""
    d = tmp_path_factory.mktemp("contract")
    (d / "data.csv").write_text("# load: fixed_piston\nt,iq\n0,0\n")
    (d / "run.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(64))
    return {"scenario": "current-step", "data": str(d / "data.csv"),
            "log": str(d / "run.mcap"), "out": str(d / "out.csv")}


def _argv(p: argparse.ArgumentParser, inputs: dict[str, str]) -> list[str]:
    words = p.prog.split()[1:]
    pos = [inputs[a.dest] for a in p._actions if not a.option_strings]
    required = []
    for a in p._actions:
        if a.option_strings and a.required:
            required += [a.option_strings[-1], a.choices[0] if a.choices else "x"]
    return [*words, *pos, *required]


def _main(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = root.main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def _planted(monkeypatch, leaf_prog: str, run) -> None:  # noqa: ANN001
    """Build the registry with ``run`` in place of the command of ``leaf_prog``."""
    build = root.build_parser

    def patched(only: str | None = None) -> argparse.ArgumentParser:
        parser = build(only)
        for p in walk(parser):
            if p.prog == leaf_prog:
                p.set_defaults(run=run)
        return parser

    monkeypatch.setattr(root, "build_parser", patched)


def _strict(text: str) -> object:
    def refuse(name: str) -> None:
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def test_every_leaf_is_a_registered_command():
    leaves = _leaves()
    assert len(leaves) >= 25, len(leaves)
    bad = [p.prog for p in leaves
           if not callable(p.get_default("run")) or p.get_default("func") is not None]
    assert not bad, f"not registered with hil.cli.contract.command: {bad}"


@pytest.mark.parametrize("prog", [p.prog for p in _leaves()])
def test_every_command_one_stderr_form_and_one_json_path(prog, inputs, monkeypatch):
    leaf = next(p for p in _leaves() if p.prog == prog)
    argv = _argv(leaf, inputs)
    verb = root._verb(root.build_parser().parse_args(argv))  # `run` names its scenario too
    assert verb.startswith(prog) or prog.startswith(verb)  # `log` names itself shorter

    def mistake(args, ctx):  # noqa: ANN001, ANN202
        raise UsageError("--x 3: planted mistake")

    _planted(monkeypatch, prog, mistake)
    assert _main(argv) == (2, "", f"{verb}: --x 3: planted mistake\n")

    data = {"nan": math.nan, "inf": np.float64(np.inf), "arr": np.array([1.5, -np.inf]),
            "n": np.int64(3), "ok": np.bool_(True)}

    def result(args, ctx):  # noqa: ANN001, ANN202
        return Outcome("for people", data, 1, error="half of it is missing")

    _planted(monkeypatch, prog, result)
    code, out, err = _main(argv)
    assert (code, out, err) == (1, "for people\n", f"{verb}: half of it is missing\n")
    if _has_json(leaf):
        code, out, err = _main([*argv, "--json"])
        assert code == 1 and err == f"{verb}: half of it is missing\n"
        assert _strict(out) == {"nan": None, "inf": None, "arr": [1.5, None], "n": 3,
                                "ok": True}


def test_argparse_mistakes_have_the_same_form():
    code, out, err = _main(["bus", "run", "--seconds", "nan"])
    assert code == 2 and out == "" and err.startswith("eha-hil bus run: argument --seconds")
    assert err.count("\n") == 1


def _calls(path: Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id == "print" and \
                not any(k.arg == "file" for k in node.keywords):
            found.append((node.lineno, "print to stdout"))
        if isinstance(f, ast.Attribute) and f.attr == "write" and \
                isinstance(f.value, ast.Attribute) and f.value.attr == "stdout":
            found.append((node.lineno, "sys.stdout.write"))
    return found


def test_only_the_contract_prints_a_result():
    bad = {p.name: _calls(p) for p in sorted(CLI.glob("*.py"))
           if p.name != "contract.py" and _calls(p)}
    assert not bad, bad


def test_the_print_check_finds_a_print(tmp_path):
    f = tmp_path / "x.py"
    f.write_text("import sys\nprint('a')\nprint('b', file=sys.stderr)\nsys.stdout.write('c')\n")
    assert _calls(f) == [(2, "print to stdout"), (4, "sys.stdout.write")]


def test_one_usage_error_class_and_one_exit_usage():
    classes, exits = [], []
    for path in sorted((ROOT / "hil").rglob("*.py")):
        text = path.read_text()
        # Both names are identifiers, which the source spells out: a module without the
        # word holds neither, and walking every module's tree was most of this test's time.
        if "usage" not in text.lower():
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef) and "usage" in node.name.lower():
                classes.append(f"{path.relative_to(ROOT)}:{node.name}")
            if isinstance(node, ast.Assign) and any(
                    isinstance(t, ast.Name) and t.id == "EXIT_USAGE" for t in node.targets):
                exits.append(str(path.relative_to(ROOT)))
    assert classes == ["hil/cli/contract.py:UsageError"]
    assert exits == ["hil/cli/contract.py"]


def test_strict_json_of_what_numpy_and_floats_hold():
    text = contract.to_json({"a": [math.nan, 1e308 * 10, np.float32(2.5)], "b": (1, 2)})
    assert _strict(text) == {"a": [None, None, 2.5], "b": [1, 2]}


# --- the root's jobs on real runs -------------------------------------------------------------
def _cli(*argv: str, **kw) -> subprocess.Popen:  # noqa: ANN003
    return subprocess.Popen([sys.executable, "-m", "hil.cli", *argv], cwd=ROOT,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            **kw)


@pytest.mark.parametrize("argv", [["esi"], ["config", "show"], ["config", "presets", "--json"]])
def test_a_stdout_that_cannot_be_written_is_one_line_and_exit_1(argv):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    with open("/dev/full", "w") as full:
        proc = _cli(*argv, stdout=full)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert err == f"eha-hil {' '.join(w for w in argv if w != '--json')}: cannot write to " \
                  "stdout: No space left on device\n"


def test_a_reader_that_goes_away_is_quiet():
    proc = _cli("esi", stdout=subprocess.PIPE)
    proc.stdout.read(10)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and err == ""


# SIGTERM and SIGHUP ending a logged run like Ctrl-C (exit 143 / 129, the signal named in
# the one line, the log closed and readable): tests/hil/test_signals.py.


def _catches(pid: int, sig: signal.Signals) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (SigCgt in /proc/PID/status)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            caught = next(ln for ln in status if ln.startswith("SigCgt:"))
    except (OSError, StopIteration):
        return False
    return bool(int(caught.split()[1], 16) >> (sig - 1) & 1)


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_the_command_line_imports_is_one_line(sig, code):
    """The signal arrives while the root imports numpy and numba (the first second).

    It is sent once the early handlers are in place (the kernel shows SIGTERM caught), not
    after a fixed delay: on a loaded machine the interpreter's own start can take longer than
    any fixed delay, and a signal before the first line of ours is the operating system's
    business, not the command line's.
    """
    proc = _cli("config", "presets", stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not _catches(proc.pid, signal.SIGTERM) and time.monotonic() < deadline:
        time.sleep(0.002)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the command finished before the signal (a very fast machine)")
    assert proc.returncode == code and "Traceback" not in err, err
    assert err.count("\n") == 1 and err.startswith("eha-hil"), err
