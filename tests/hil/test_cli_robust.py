"""Every user mistake on the command line gets one line; Ctrl-C ends cleanly.

The matrix feeds every verb's every option that takes a number or a path with values a user
may type by mistake (NaN, inf, 0, negative, huge, a directory, a missing file, a file of
the wrong type, an empty file). The options are found by walking the parser, so a new
option is covered without editing this file; the cases run in this process through
``hil.cli.root.main`` (a few through the console script, to show that is the same thing).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from hil.cli import root
from hil.cli.args import walk
from hil.cli.root import build_parser, main

NUMBERS = ["nan", "inf", "-inf", "0", "-3", "1e30", "99999999999"]
PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4

#: Options that take a path but no type of hil.cli.args (their module reads the file).
UNTYPED_PATHS = {"config": "config", "preset": "config", "topology": "input",
                 "port": "device", "log": "input", "out": "output"}
#: Options that take a value which is neither a number nor a path.
TEXT = {"set", "effect", "magnitude", "host", "scenario", "topic", "field", "board", "case",
        "can_channel", "foxglove",  # HOST:PORT, hil.framelog.live.parse_address
        "param", "tolerance", "seeds", "dask", "scenario_name", "require",
        "interface",  # interface: a network interface name, checked by hil.transports.rawether
        "dc_drift_ppm"}  # a number or a comma-separated list, hil.cli.serve._ppm_list

#: Extra arguments that keep a verb cheap when the value under test is valid (tiny
#: durations, --json for no progress lines), and placeholders for required positionals.
BASE = {
    "eha-hil plant bode": ["--points", "2", "--load", "fixed"],
    "eha-hil plant tn-curve": ["--points", "3"],
    "eha-hil bench plant": ["--seconds", "0.01"],
    "eha-hil bench fpga": ["--seconds", "0.01", "--bit-seconds", "0.001"],
    "eha-hil bench stack": ["--seconds", "0.01"],
    "eha-hil bench codecs": ["--seconds", "0.001"],
    "eha-hil bench ethercat": ["--cycles", "10"],
    "eha-hil bench bus": ["--cycles", "5", "--no-replay", "--backends", "inproc"],
    "eha-hil bench identify": ["--seconds", "1.5"],
    "eha-hil bus run": ["--seconds", "0.01"],
    "eha-hil serve": ["--port", "pty", "--seconds", "0.01", "-q"],
    "eha-hil identify-synth": ["--seconds", "1.01"],
    "eha-hil identify-check": ["--case", "no such case"],  # exits 2 before any run
    "eha-hil verify mcu": ["--against", "host-c", "--steps", "20", "--stack-seconds", "0"],
    "eha-hil bench sweep": ["--points", "2", "--scenario", "current-step"],
}


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("mistakes")
    (d / "dir").mkdir()
    (d / "empty.csv").write_bytes(b"")
    (d / "empty.mcap").write_bytes(b"")
    (d / "empty.toml").write_bytes(b"")
    (d / "image.png").write_bytes(PNG)
    (d / "image.csv").write_bytes(PNG)  # a picture under a data file's name
    (d / "image.mcap").write_bytes(PNG)
    (d / "image.toml").write_bytes(PNG)
    # A measured-data CSV that fails its reader at once: the base DATA of `identify`, so
    # that a valid option value ends in a quick exit 2 instead of an identification.
    (d / "bad.csv").write_text("# load: fixed_piston\n# sample_rate_hz: 5000\nt,iq\n0,x\n")
    return {"dir": d / "dir", "root": d}


def _kind(action: argparse.Action) -> str | None:
    kind = getattr(action.type, "kind", None)
    if kind:
        return kind
    if action.type in (int, float):
        return "number"
    return UNTYPED_PATHS.get(action.dest)


def _values(kind: str, action: argparse.Action, f: dict[str, Path]) -> list[str]:
    r, d = f["root"], f["dir"]
    missing_dir = str(r / "no" / "such")
    if kind == "number":
        return NUMBERS
    if kind in ("input", "config"):
        suffix = {"config": ".toml"}.get(kind, ".mcap" if "mcap" in str(action.metavar).lower()
                                         else ".csv")
        return [str(d), missing_dir + suffix, str(r / f"image{suffix}"), str(r / "image.png"),
                str(r / f"empty{suffix}")]
    if kind == "output":
        suffix = getattr(action.type, "suffixes", (".csv",))[0]
        clobber = r / f"clobber{suffix}"  # an existing picture under the output's name
        clobber.write_bytes(PNG)
        return [str(d), missing_dir + suffix, str(r / "out.wrongtype"), str(clobber)]
    if kind == "dir":
        return [str(r / "image.png"), missing_dir + "/sub", str(r / "empty.csv")]
    if kind == "device":
        return [str(d), missing_dir, str(r / "image.png"), str(r / "empty.csv")]
    raise AssertionError(kind)


def _positionals(prog: str, f: dict[str, Path]) -> dict[str, str]:
    r = f["root"]
    return {"scenario": "current-step", "data": str(r / "bad.csv"), "log": str(r / "empty.mcap"),
            "out": str(r / "out.csv")} if prog != "eha-hil identify-synth" else {
        "out": str(r / "synth.csv")}


def _leaf_parsers() -> list[argparse.ArgumentParser]:
    """The parsers of runnable verbs (no further sub-command below them)."""
    return [p for p in walk(build_parser())
            if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)]


def _cases(f: dict[str, Path]) -> list[tuple[str, list[str]]]:
    """(label, argv) for every option x value of every verb."""
    cases = []
    for p in _leaf_parsers():
        verb = p.prog.split()[1:]
        pos = [a for a in p._actions if not a.option_strings]
        fill = _positionals(p.prog, f)
        extra = list(BASE.get(p.prog, []))
        if any("--json" in a.option_strings for a in p._actions):
            extra.append("--json")
        for a in p._actions:
            kind = _kind(a)
            if kind is None:
                continue
            for v in _values(kind, a, f):
                args = [v if b is a else fill[b.dest] for b in pos]
                # --opt=VALUE: argparse would read "-inf" after a space as an option
                opt = [] if not a.option_strings else [f"{a.option_strings[-1]}={v}"]
                label = f"{p.prog} {a.option_strings[-1] if a.option_strings else a.dest} {v}"
                cases.append((label, [*verb, *args, *extra, *opt]))
    return cases


def _in_process(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def _problem(code: object, err: str) -> str:
    if "Traceback" in err:
        return "traceback"
    if code not in (0, 1, 2):
        return f"exit {code}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if len(lines) > 1:
        return f"{len(lines)} lines on stderr"
    return ""


def test_every_option_is_classified():
    """An option taking a value is a number, a path, or listed as text: a new option
    cannot slip past the matrix below."""
    unknown = []
    for p in _leaf_parsers():
        for a in p._actions:
            takes_value = a.nargs != 0 and not isinstance(a, argparse._HelpAction)
            if takes_value and _kind(a) is None and not a.choices and a.dest not in TEXT:
                unknown.append(f"{p.prog} {a.option_strings or a.dest}")
    assert not unknown, f"classify these in tests/hil/test_cli_robust.py: {unknown}"


@pytest.mark.slow  # ~300 cases in this process: 5-15 s
def test_mistake_matrix_gives_at_most_one_line(files, monkeypatch):
    monkeypatch.chdir(files["root"])
    # main() builds the whole parser for each command line (~10 ms, most of a case's time
    # when the value is refused): here built once and parsed with for every case.
    monkeypatch.setattr(root, "build_parser", functools.cache(build_parser))
    cases = _cases(files)
    verbs = {label.split(" -")[0] for label, _ in cases}
    assert len(cases) > 150 and len(verbs) >= 15, (len(cases), sorted(verbs))
    bad = []
    for label, argv in cases:
        code, err = _in_process(argv)
        problem = _problem(code, err)
        if problem:
            bad.append(f"{label}: {problem}: {err.strip()[-300:]}")
    assert not bad, "\n".join(bad)


# The console script is main() plus sys.exit: the same exit code and the same stderr.
@pytest.mark.slow  # a process start each
@pytest.mark.parametrize("argv", [
    ["bus", "run", "--seconds", "nan"],
    ["plant", "tn-curve", "--current", "1e6"],
    ["main", "-c", "{dir}"],
    ["identify-synth", "{root}/image.png"],
    ["bench", "bus", "--cycles", "0"],
    ["config", "presets", "-c", "hydra_linear"],
])
def test_console_script_is_main(files, argv):
    argv = [a.format(**{k: str(v) for k, v in files.items()}) for a in argv]
    exe = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
    proc = subprocess.run([exe, *argv], capture_output=True, text=True, timeout=120)
    code, err = _in_process(argv)
    assert (proc.returncode, proc.stderr) == (code, err)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err


# --- Ctrl-C ----------------------------------------------------------------------------------
class _Running:
    """A console-script run whose stderr is read as it comes (progress lines end in \\r)."""

    def __init__(self, argv: list[str], cwd: Path) -> None:
        exe = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
        # SIGINT back to its default in the child: a test run started in the background
        # (nohup, a CI job, `&`) ignores it, and the child would inherit the ignoring
        self.proc = subprocess.Popen([exe, *argv], cwd=cwd, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE,
                                     preexec_fn=lambda: signal.signal(signal.SIGINT,
                                                                      signal.SIG_DFL))
        self.err = b""
        self._lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        while chunk := os.read(self.proc.stderr.fileno(), 4096):
            with self._lock:
                self.err += chunk

    def wait_for(self, pattern: str, timeout: float = 120.0) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if re.search(pattern.encode(), self.err):
                    return
            assert self.proc.poll() is None, f"ended early: {self.err.decode()[-500:]}"
            time.sleep(0.05)
        raise AssertionError(f"no {pattern!r} on stderr: {self.err.decode()[-500:]}")

    def interrupt(self) -> tuple[int, list[str]]:
        """SIGINT, then (exit code, stderr lines as a terminal shows them)."""
        self.proc.send_signal(signal.SIGINT)
        try:
            code = self.proc.wait(timeout=60)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        time.sleep(0.1)  # the reader thread drains the pipe
        text = self.err.decode()
        return code, [ln.rsplit("\r", 1)[-1] for ln in text.splitlines()]


def _one_interrupt_line(code: int, lines: list[str], verb: str, progress: str) -> str:
    """Exit 130; the last line says what was interrupted; every other line is progress."""
    assert code == 130, lines
    assert not any("Traceback" in ln for ln in lines), "\n".join(lines)
    *before, last = lines
    assert last.startswith(f"eha-hil {verb}: interrupted "), lines
    others = [ln for ln in before if ln and not re.fullmatch(progress, ln)]
    assert not others, others
    return last


# A logged bus run and run thesis interrupted (their files, lines and exit codes, for
# SIGINT, SIGTERM and SIGHUP): tests/hil/test_signals.py.


@pytest.mark.slow
def test_ctrl_c_bench_stack(tmp_path):
    run = _Running(["bench", "stack", "--seconds", "600"], tmp_path)
    run.wait_for(r"bench stack: simulating")
    time.sleep(1.0)  # into the timed run
    code, lines = run.interrupt()
    last = _one_interrupt_line(code, lines, "bench stack", r"bench stack: simulating .*")
    assert last.endswith("nothing written"), last


@pytest.mark.slow
def test_ctrl_c_identify(tmp_path, identify_record):
    run = _Running(["identify", str(identify_record), "--report", str(tmp_path / "rep")],
                   tmp_path)
    # early, while numba loads the model's machine code from its cache: a SIGINT there would
    # land in an LLVM callback, where Python can only print it and go on (hil/cli/interrupts.py)
    # (the whole line: a signal between print's text and its newline would cut the line)
    run.wait_for(r"identify: [^\n]*\n")
    code, lines = run.interrupt()
    last = _one_interrupt_line(code, lines, "identify", r"identify: .*")
    assert "nothing written" in last, last
