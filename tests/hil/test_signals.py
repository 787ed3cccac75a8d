"""SIGINT and SIGTERM end every command that writes the same way: files closed and kept
under their name only when they read back whole (the stock readers agree), no temporary
file left behind, no worker process left running, exit 130 / 143 and one line.

Each case starts the console script, waits until it is busy (its progress on stderr),
sends the signal and checks what is on disk with readers we did not write: mcap's reader,
python-can's BLFReader, dpkt's pcapng reader, json for a sweep's journal.
"""

from __future__ import annotations

import json
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

pytestmark = pytest.mark.slow  # a console-script start each (numba's cache: 2-6 s)

EXE = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"


def _default_signals() -> None:
    for s in (signal.SIGINT, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)


class Running:
    """The console script, its stderr read as it comes."""

    def __init__(self, argv: list[str], cwd: Path) -> None:
        # SIGINT and SIGHUP back to their defaults in the child (a test run in the background
        # ignores SIGINT, one under nohup SIGHUP: the command rightly keeps an ignored SIGHUP)
        self.proc = subprocess.Popen([EXE, *argv], cwd=cwd, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, preexec_fn=_default_signals)
        self.err = b""
        self.out = b""
        self._lock = threading.Lock()
        threading.Thread(target=self._read, args=("err",), daemon=True).start()
        threading.Thread(target=self._read, args=("out",), daemon=True).start()

    def _read(self, which: str) -> None:
        pipe = self.proc.stderr if which == "err" else self.proc.stdout
        while chunk := os.read(pipe.fileno(), 4096):
            with self._lock:
                setattr(self, which, getattr(self, which) + chunk)

    def wait_for(self, pattern: str, timeout: float = 180.0) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if re.search(pattern.encode(), self.err):
                    return
            assert self.proc.poll() is None, f"ended early: {self.err.decode()[-800:]}"
            time.sleep(0.05)
        raise AssertionError(f"no {pattern!r} on stderr: {self.err.decode()[-800:]}")

    def children(self) -> set[int]:
        """Every descendant process of the command (workers of a pool and theirs)."""
        found: set[int] = set()
        todo = [self.proc.pid]
        while todo:
            pid = todo.pop()
            for task in Path(f"/proc/{pid}/task").glob("*"):
                try:
                    kids = (task / "children").read_text().split()
                except OSError:
                    continue
                for k in map(int, kids):
                    if k not in found:
                        found.add(k)
                        todo.append(k)
        return found

    def stop(self, sig: int) -> tuple[int, list[str]]:
        self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=60)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        time.sleep(0.2)  # the reader threads drain the pipes
        return code, [ln.rsplit("\r", 1)[-1] for ln in self.err.decode().splitlines()]


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


SIGNALS = [pytest.param(signal.SIGINT, id="SIGINT"), pytest.param(signal.SIGTERM, id="SIGTERM")]
# SIGINT, SIGTERM and SIGHUP reach a command through one handler (hil.cli.interrupts) that
# raises the same exception, and one function words the line from its signal number: the
# whole matrix runs on one writer (bus run's log, the cheapest start), and each other
# writer is stopped by one signal, SIGINT for some and SIGTERM for others, so that each
# kind of clean-up (stream, pool, all-or-nothing output) meets both. Each case is a
# console-script start of 3-10 s of CPU; the file went from 93 to 62 s of CPU.
INT = [pytest.param(signal.SIGINT, id="SIGINT")]
TERM = [pytest.param(signal.SIGTERM, id="SIGTERM")]


def _ended(code: int, lines: list[str], sig: int, verb: str) -> str:
    assert code == 128 + sig, (code, lines[-5:])
    assert not any("Traceback" in ln for ln in lines), "\n".join(lines)
    last = lines[-1]
    assert last.startswith(f"eha-hil {verb}: interrupted "), lines[-5:]
    return last


def _no_partials(d: Path) -> None:
    left = [p.name for p in d.rglob("*partial*")]
    assert not left, left


# --- streams: the file is closed and kept, readable by the stock readers ----------------------
@pytest.mark.parametrize("sig", [*SIGNALS, pytest.param(signal.SIGHUP, id="SIGHUP")])
def test_bus_run_log_is_finalised(sig, tmp_path):
    """Also SIGHUP (a closed terminal): the same end, exit 129. The line names a signal
    other than Ctrl-C's, says when, and is the only line besides the progress."""
    from mcap.reader import make_reader

    from hil.framelog.reader import FrameLogReader

    # A logged run reports its progress every twentieth of the run: 30 s puts the first
    # report (busy, the log several blocks long) at 1.5 s simulated, 28.5 s before the end.
    run = Running(["bus", "run", "--seconds", "30", "--log", "run.mcap"], tmp_path)
    run.wait_for(r"bus run: [1-9]\d*/30000 cycles")
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "bus run")
    by = "" if sig == signal.SIGINT else f"by {signal.Signals(sig).name} "
    assert re.fullmatch(rf"eha-hil bus run: interrupted {by}at t=\d+\.\d+ s; "
                        r"log run.mcap closed and readable", last), last
    others = [ln for ln in lines[:-1] if ln and not re.fullmatch(r"bus run: \d+/\d+ cycles", ln)]
    assert not others, others
    info = FrameLogReader(tmp_path / "run.mcap").info()
    assert info.complete and info.frame_count > 0
    with (tmp_path / "run.mcap").open("rb") as fh:
        reader = make_reader(fh)  # the stock reader: a summary (footer) and every message
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        assert sum(1 for _ in reader.iter_messages()) == summary.statistics.message_count \
            == info.message_count
    _no_partials(tmp_path)


@pytest.mark.parametrize("sig", INT)
def test_bus_run_can_log_blf_is_finalised(sig, tmp_path):
    import can

    run = Running(["bus", "run", "--transport", "can", "--seconds", "120",
                   "--can-log", "x.blf"], tmp_path)
    run.wait_for(r"bus run: [1-9]\d*/120000 cycles")
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "bus run")
    assert last.endswith("CAN log x.blf closed and readable"), last
    reader = can.BLFReader(str(tmp_path / "x.blf"))
    n = sum(1 for _ in reader)
    assert n > 0 and n == reader.object_count  # the header declares what is there
    assert reader.file_size == (tmp_path / "x.blf").stat().st_size
    _no_partials(tmp_path)


@pytest.mark.parametrize("sig", TERM)
def test_bus_run_capture_is_whole(sig, tmp_path):
    import dpkt

    run = Running(["bus", "run", "--seconds", "120", "--capture", "c.pcapng"], tmp_path)
    run.wait_for(r"bus run: [1-9]\d*/120000 cycles")
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "bus run")
    assert last.endswith("capture c.pcapng closed and readable"), last
    with (tmp_path / "c.pcapng").open("rb") as fh:
        packets = sum(1 for _ in dpkt.pcapng.Reader(fh))  # raises on a cut block
    assert packets > 0
    _no_partials(tmp_path)


# --- pools: no worker outlives the command ------------------------------------------------------
@pytest.mark.parametrize("sig", TERM)
def test_identify_check_pool_ends_with_it(sig, tmp_path):
    run = Running(["identify-check", "--jobs", "2", "--seeds", "1", "2", "3",
                   "--markdown", "m.md"], tmp_path)
    end = time.monotonic() + 120
    while len(run.children()) < 2 and time.monotonic() < end:
        assert run.proc.poll() is None, run.err.decode()[-800:]
        time.sleep(0.2)
    workers = run.children()
    assert len(workers) >= 2, "the pool did not start"
    time.sleep(1.0)
    code, lines = run.stop(sig)
    _ended(code, lines, sig, "identify-check")
    time.sleep(1.0)
    assert not [p for p in workers if _alive(p)], "orphaned workers"
    assert not (tmp_path / "m.md").exists()
    _no_partials(tmp_path)


@pytest.mark.parametrize("sig", INT)
def test_sweep_pool_ends_with_it_and_keeps_the_journal(sig, tmp_path):
    run = Running(["sweep", "current-step", "--seeds", "0..400", "--workers", "2",
                   "--out", "t.parquet"], tmp_path)
    run.wait_for(r"sweep current-step: [1-9]\d*/401 points")
    workers = run.children()
    assert workers, "no pool"
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "sweep")
    assert "journal" in last, last
    time.sleep(1.0)
    assert not [p for p in workers if _alive(p)], "orphaned workers"
    assert not (tmp_path / "t.parquet").exists()  # the table is written only when complete
    journal = tmp_path / "t.parquet.points.jsonl"
    records = [json.loads(ln) for ln in journal.read_text().splitlines() if ln.strip()]
    assert records, "the finished points are in the journal"
    _no_partials(tmp_path)


# --- computations with an output at the end -------------------------------------------------------
@pytest.mark.parametrize("sig", TERM)
def test_identify_report_is_all_or_nothing(sig, tmp_path, identify_record):
    run = Running(["identify", str(identify_record), "--report", "rep"], tmp_path)
    run.wait_for(r"identify: baseline fit[^\n]*\n")  # its whole line (print, then "\n")
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "identify")
    assert "nothing written" in last, last
    assert not (tmp_path / "rep").exists()
    _no_partials(tmp_path)


@pytest.mark.parametrize("sig", INT)
def test_run_thesis_keeps_the_finished_plots(sig, tmp_path):
    run = Running(["run", "thesis", "--plot-dir", "plots"], tmp_path)
    run.wait_for(r"f4 \.\.\.")  # f3 is done and its plot written
    time.sleep(1.0)  # into f4 (a signal inside the print of "f4 ..." would cut its line)
    code, lines = run.stop(sig)
    last = _ended(code, lines, sig, "run thesis")
    # the scenario it was in, those done, and their plots
    by = "" if sig == signal.SIGINT else f"by {signal.Signals(sig).name} "
    assert re.match(rf"eha-hil run thesis: interrupted {by}in f[\w-]+ "
                    r"\(f1-measured(, f[\w-]+)* done\); ", last), last
    done = r"plots? f1-measured\.png(, [\w-]+\.png)*, f3\.png(, [\w-]+\.png)* written to plots/$"
    assert re.search(done, last), last
    others = [ln for ln in lines[:-1] if ln and not re.fullmatch(r"f[\w-]+ \.\.\.", ln)]
    assert not others, others  # besides the line, only the scenarios' progress
    from PIL import Image

    with Image.open(tmp_path / "plots" / "f3.png") as im:  # a whole PNG: it decodes
        im.load()
    _no_partials(tmp_path)


@pytest.mark.parametrize("sig", SIGNALS)
def test_serve_capture_is_whole(sig, tmp_path):
    import dpkt

    run = Running(["serve", "--port", "pty", "--capture", "s.pcapng", "-q"], tmp_path)
    run.wait_for(r"eha-hil serve: ready")
    time.sleep(0.5)
    code, lines = run.stop(sig)
    assert "Traceback" not in "\n".join(lines)
    assert code in (0, 1), lines  # serve stops on either; 1: no master came
    with (tmp_path / "s.pcapng").open("rb") as fh:
        assert sum(1 for _ in dpkt.pcapng.Reader(fh)) == 0  # whole, and nothing arrived
    _no_partials(tmp_path)
