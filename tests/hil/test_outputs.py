"""Every output option of the command line: refused before the work when its directory
cannot take a file, and when the disk is full after the work, the result still printed
with one line naming the file (exit 1); never an output over an input; never a
half-written file under the real name.

The options are found by walking the parser (argument types of kind ``output`` or
``dir``), so a new output option fails :func:`test_every_output_option_has_a_recipe`
until it is covered here.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
from pathlib import Path

import pytest

from hil.cli import outputs
from hil.cli.args import walk
from hil.cli.root import build_parser, main

#: Inputs of kind "dir" (read, not written): not outputs (--rtl: a directory of Verilog).
INPUT_DIRS = {"rtl"}

#: A cheap command line for each output option; "{out}" is where a positional output goes
#: (an option's value is appended as --opt=VALUE).
RECIPES: dict[tuple[str, str], list[str]] = {
    ("eha-hil plant bode", "--plot"): ["plant", "bode", "--points", "2", "--load", "fixed"],
    ("eha-hil plant tn-curve", "--plot"): ["plant", "tn-curve", "--points", "3"],
    ("eha-hil bus run", "--log"): ["bus", "run", "--seconds", "0.02"],
    ("eha-hil bus run", "--capture"): ["bus", "run", "--seconds", "0.02"],
    ("eha-hil bus run", "--can-log"): ["bus", "run", "--transport", "can", "--seconds", "0.02"],
    ("eha-hil serve", "--capture"): ["serve", "--port", "pty", "--seconds", "0.02", "-q"],
    ("eha-hil serve", "--log"): ["serve", "--port", "pty", "--seconds", "0.02", "-q"],
    ("eha-hil log export", "out"): ["log", "export", "{log}", "{out}"],
    ("eha-hil identify", "--report"): ["identify", "{data}", "--max-effects", "0", "--quiet"],
    ("eha-hil identify-synth", "out"): ["identify-synth", "{out}", "--seconds", "1.01"],
    ("eha-hil identify-check", "--markdown"): ["identify-check", "--case",
                                               "fixed_piston: null", "--seeds", "1",
                                               "--jobs", "1"],
    ("eha-hil identify-check", "--rows"): ["identify-check", "--case",
                                           "fixed_piston: null", "--seeds", "1",
                                           "--jobs", "1"],
    ("eha-hil sweep", "--out"): ["sweep", "current-step", "--seeds", "0..1",
                                 "--workers", "1"],
    ("eha-hil sweep", "--plot-dir"): ["sweep", "current-step", "--seeds", "0..1",
                                      "--workers", "1"],
    ("eha-hil run", "--plot"): ["run", "current-step"],
    ("eha-hil run", "--plot-dir"): ["run", "current-step"],
    ("eha-hil run", "--series"): ["run", "current-step"],
}
#: Streams: written while the command runs; a failed write stops it (nothing on stdout).
STREAMS = {("eha-hil bus run", "--log"), ("eha-hil bus run", "--capture"),
           ("eha-hil bus run", "--can-log"), ("eha-hil serve", "--capture"),
           ("eha-hil serve", "--log")}
#: Long to run (a whole identification): the full-disk case is in the slow set.
SLOW = {("eha-hil identify", "--report"), ("eha-hil identify-check", "--markdown"),
        ("eha-hil identify-check", "--rows")}


def _output_options() -> list[tuple[str, str, str, tuple[str, ...]]]:
    """(verb, option or positional name, kind, suffixes) of every output of every verb."""
    found = []
    for p in walk(build_parser()):
        for a in p._actions:
            kind = getattr(a.type, "kind", None)
            name = a.option_strings[-1] if a.option_strings else a.dest
            if kind in ("output", "dir") and a.dest not in INPUT_DIRS:
                found.append((p.prog, name, kind, getattr(a.type, "suffixes", ("",))))
    return found


OPTIONS = _output_options()


def _ids(o: tuple) -> str:
    return f"{o[0].removeprefix('eha-hil ')} {o[1]}"


def test_every_output_option_has_a_recipe():
    assert len(OPTIONS) >= 14
    missing = [f"{v} {o}" for v, o, _, _ in OPTIONS if (v, o) not in RECIPES]
    assert not missing, f"add a recipe in tests/hil/test_outputs.py: {missing}"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, str]:
    """A frame log and a measured-data CSV, made by the commands themselves."""
    d = tmp_path_factory.mktemp("inputs")
    assert main(["bus", "run", "--seconds", "0.02", "--log", str(d / "run.mcap")]) == 0
    assert main(["identify-synth", str(d / "data.csv"), "--seconds", "2"]) == 0
    (d / "a_file").write_text("not a directory\n")
    return {"log": str(d / "run.mcap"), "data": str(d / "data.csv"), "root": str(d)}


def _argv(verb: str, opt: str, value: str, inputs: dict[str, str]) -> list[str]:
    argv = [a.format(out=value, **inputs) for a in RECIPES[(verb, opt)]]
    if opt.startswith("-"):
        argv.append(f"{opt}={value}")
    return argv


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def _name(kind: str, suffixes: tuple[str, ...], stem: str = "out") -> str:
    return stem if kind == "dir" else stem + suffixes[0]


@contextlib.contextmanager
def _mount(options: str, fill: bool = False):
    """A small tmpfs (read-only, or filled to the last byte); skip without the right."""
    import tempfile

    d = Path(tempfile.mkdtemp(prefix="eha-hil-mnt-"))
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size=256k,{options}", "tmpfs", str(d)],
                       capture_output=True, text=True)
    if r.returncode:
        d.rmdir()
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip()}): needs root")
    try:
        if fill:
            with contextlib.suppress(OSError), open(d / "fill", "wb") as fh:
                while True:
                    fh.write(b"\0" * 65536)
                    fh.flush()
            (d / "small").mkdir(exist_ok=True)  # a directory entry still fits (no blocks)
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=False)
        d.rmdir()


# --- 1. refused before the work ---------------------------------------------------------------
@pytest.mark.parametrize("opt", OPTIONS, ids=_ids)
@pytest.mark.parametrize("where", ["file-as-directory", "/proc", "read-only mount"])
def test_unwritable_directory_refused_before_the_work(opt, where, inputs, tmp_path):
    verb, name, kind, suffixes = opt
    with contextlib.ExitStack() as stack:
        if where == "file-as-directory":
            base = Path(inputs["root"]) / "a_file"
        elif where == "/proc":
            base = Path("/proc")
        else:
            base = stack.enter_context(_mount("ro"))
        target = base / _name(kind, suffixes)
        code, out, err = _run(_argv(verb, name, str(target), inputs))
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (code, err)
    assert len(lines) == 1 and str(base) in lines[0] and "Traceback" not in err, err
    assert out == ""  # nothing was computed or printed


# --- 2. a full disk after the work -------------------------------------------------------------
def _full_cases() -> list:
    return [pytest.param(o, id=_ids(o),
                         marks=[pytest.mark.slow] if (o[0], o[1]) in SLOW else [])
            for o in OPTIONS]


@pytest.mark.parametrize("opt", _full_cases())
def test_full_disk_keeps_the_result_and_names_the_file(opt, inputs, tmp_path, monkeypatch):
    """A file output on /dev/full (through a link with the right name), a directory output
    on a full tmpfs: exit 1, one line naming the file; the result (or, for a stream, the
    position where the run stopped) is still reported; no temporary file is left."""
    verb, name, kind, suffixes = opt
    monkeypatch.chdir(tmp_path)
    with contextlib.ExitStack() as stack:
        if kind == "dir":
            d = stack.enter_context(_mount("rw", fill=True))
            target = d / "small" / "out"
        else:
            d = tmp_path
            target = tmp_path / _name(kind, suffixes, "full")
            target.symlink_to("/dev/full")
        code, out, err = _run(_argv(verb, name, str(target), inputs))
        left = [p.name for p in d.rglob("*partial*")]
    assert code == 1, (code, err[-2000:])
    assert "Traceback" not in err
    failed = [ln for ln in err.splitlines() if "not written" in ln]
    assert len(failed) == 1 and str(target) in failed[0] and "No space left" in failed[0], err
    assert failed[0].startswith(" ".join(verb.split()[:2]))  # the verb ("eha-hil log")
    if (verb, name) in STREAMS:
        assert "stopped" in failed[0]
    elif verb != "eha-hil log export":  # the export's result is the file itself
        assert out.strip(), "the result must still reach stdout"
        assert f"written to {target}" not in out and f"wrote {target}" not in out
    assert not left, left


# --- 3. an output that is an input ----------------------------------------------------------------
def test_output_that_is_an_input_is_refused(inputs, tmp_path):
    log = tmp_path / "run.mcap"
    log.write_bytes(Path(inputs["log"]).read_bytes())
    before = log.read_bytes()
    link = tmp_path / "other.csv"
    link.symlink_to(log)
    for out in (str(log), f"{tmp_path}/./run.mcap", str(link)):
        code, _, err = _run(["log", "export", str(log), out])
        assert code == 2 and "is also an input" in err and err.count("\n") == 1, err
    assert log.read_bytes() == before


def test_check_not_inputs_by_inode(tmp_path):
    a = tmp_path / "a.csv"
    a.write_text("x\n")
    os.link(a, tmp_path / "b.csv")  # another name, the same file
    with pytest.raises(outputs.OutputError, match="is also an input"):
        outputs.check_not_inputs([str(tmp_path / "b.csv")], [str(a)])
    outputs.check_not_inputs([str(tmp_path / "c.csv")], [str(a)])  # a new file: fine


# --- 4. whole or not at all ---------------------------------------------------------------------
def test_replacing_keeps_the_old_file_when_the_writer_fails(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("old\n")
    with pytest.raises(RuntimeError), outputs.replacing(p) as tmp:
        tmp.write_text("half")
        raise RuntimeError("writer failed")
    assert p.read_text() == "old\n"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["t.csv"]
    with outputs.replacing(p) as tmp:
        assert tmp.suffix == ".csv" and tmp.parent == p.parent  # writers choose by suffix
        tmp.write_text("new\n")
    assert p.read_text() == "new\n"
    assert oct(p.stat().st_mode & 0o777) != oct(0o600)  # not mkstemp's private mode


def test_interrupted_stream_is_kept_under_its_name(tmp_path):
    p = tmp_path / "run.log"
    with pytest.raises(KeyboardInterrupt), outputs.replacing(p, keep_on_interrupt=True) as t:
        t.write_text("what ran\n")
        raise KeyboardInterrupt
    assert p.read_text() == "what ran\n"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["run.log"]


@pytest.mark.parametrize("opt", [pytest.param(o, id=_ids(o)) for o in OPTIONS
                                 if o[2] == "output" and (o[0], o[1]) not in SLOW])
def test_full_file_system_names_the_file_and_leaves_nothing(opt, inputs, tmp_path,
                                                            monkeypatch):
    """The same on a real full file system (a filled tmpfs): also the files written beside
    an output (a sweep's journal) are named, and nothing is left behind."""
    verb, name, kind, suffixes = opt
    monkeypatch.chdir(tmp_path)
    with _mount("rw", fill=True) as d:
        target = d / _name(kind, suffixes)
        before = sorted(p.name for p in d.iterdir())
        code, out, err = _run(_argv(verb, name, str(target), inputs))
        after = sorted(p.name for p in d.iterdir())
    assert code == 1, (code, err[-2000:])
    assert "Traceback" not in err
    failed = [ln for ln in err.splitlines() if "not written" in ln]
    assert len(failed) == 1 and str(d) in failed[0] and "No space left" in failed[0], err
    assert after == before  # no half file, no temporary
