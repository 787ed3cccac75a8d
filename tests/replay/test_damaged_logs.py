"""Damaged logs through the command line: `eha-hil replay`, `log info` and `log export`
exit 1 (a result: the log is truncated, what is readable was used and the output says
where it ends) or 2 (nothing could be done: empty, foreign, damaged, unreadable metadata,
nothing to replay), each with exactly one line on stderr and never a traceback.

The logs are real ones (`run_logged`, what `eha-hil bus run --log` writes), damaged the
ways a user meets: cut at several points, a flipped byte, the end dropped, an empty file,
a text file, a directory.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from mcap.reader import make_reader

from hil.fieldbus.topology import load_topology
from hil.framelog.reader import MAGIC
from hil.replay.record import FLUSH_CYCLES, run_logged
from hil.sim.pc import demo_pc
from plant.config import load_config
from tests.session_once import made_once

#: A real log made twice and 34 commands run (a few as processes): ~6 s, not in make test-fast.
pytestmark = pytest.mark.slow

EXE = shutil.which("eha-hil") or f"{sys.prefix}/bin/eha-hil"
#: Three blocks of the log (FLUSH_CYCLES each, the last partial): the raw chunks before
#: the last hold whole cycles to replay.
CYCLES = 2 * FLUSH_CYCLES + 100
COMMANDS = {"replay": ["replay", "{log}"], "info": ["log", "info", "{log}"],
            "export": ["log", "export", "{log}", "{out}"]}


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of the top-level records up to the Footer."""
    out, pos = [], len(MAGIC)
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1:pos + 9], "little")
        out.append((pos, op, length))
        if op == 2:
            break
        pos += 9 + length
    return out


def _last_raw_chunk(path: Path) -> int:
    """Offset of the last chunk holding frames the replay reads (not only decoded signals,
    which have chunks of their own: writer.SIGNAL_CHUNKS)."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return max(ci.chunk_start_offset for ci in summary.chunk_indexes
               if any(not summary.channels[c].topic.startswith("/signals/")
                      for c in ci.message_index_offsets))


def _flip(data: bytes, at: int, mask: int = 0xFF) -> bytes:
    b = bytearray(data)
    b[at] ^= mask
    return bytes(b)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Name -> damaged file (or directory), all made from two real logs, once per run (the
    module's tests may run on both xdist workers)."""
    return made_once(tmp_path_factory, "damaged-logs", _damaged_logs)


def _damaged_logs(d: Path) -> dict[str, Path]:
    cfg = load_config("hydra_default")
    full = d / "full.mcap"
    run_logged(load_topology("bench_one_box"), cfg, CYCLES, demo_pc(), full)
    data = full.read_bytes()
    recs = _records(data)
    chunks = [pos for pos, op, _ in recs if op == 6]
    data_end = next(pos for pos, op, _ in recs if op == 15)
    assert len(chunks) >= 2, recs
    meta = data.find(b'{"', data.find(b"eha-hil.replay"))  # the logged configuration
    assert meta > 0
    colon = data.index(b":", meta)
    short = d / "short.mcap"  # a complete log of one cycle: no MCU step was logged
    run_logged(load_topology("bench_one_box"), cfg, 1, demo_pc(), short)
    made = {
        "empty": b"",
        "text": b"this is not a log\n" * 20,
        "cut_in_header": data[:20],
        "cut_in_metadata": data[:recs[2][0] + 40],
        "cut_in_first_chunk": data[:chunks[0] + 50],
        "cut_in_last_chunk": data[:_last_raw_chunk(full) + 50],
        "end_dropped": data[:-40],
        "flipped_chunk_byte": _flip(data, chunks[-1] + 200),
        "flipped_length_byte": _flip(data, len(MAGIC) + 1, 0x01),  # the Header's length
        # Cut before the data-section CRC, which would otherwise catch the flip.
        "flipped_metadata_then_cut": (data[:colon] + b";" + data[colon + 1:])[:data_end],
    }
    out = {}
    for name, blob in made.items():
        (d / f"{name}.mcap").write_bytes(blob)
        out[name] = d / f"{name}.mcap"
    (d / "a_directory").mkdir()
    out["a_directory"] = d / "a_directory"
    out["no_mcu_data"] = short
    return out


# name -> expected exit code of (replay, info, export); None: not run (not damaged).
EXPECTED = {
    "empty": (2, 2, 2),
    "text": (2, 2, 2),
    "a_directory": (2, 2, 2),
    "cut_in_header": (2, 1, 1),
    "cut_in_metadata": (2, 1, 1),
    "cut_in_first_chunk": (2, 1, 1),
    "cut_in_last_chunk": (1, 1, 1),
    "end_dropped": (1, 1, 1),
    "flipped_chunk_byte": (2, 2, 2),
    "flipped_length_byte": (2, 2, 2),
    "flipped_metadata_then_cut": (2, 1, 1),
    "no_mcu_data": (2, None, None),
}


def _run(cmd: str, log: Path, out: Path) -> subprocess.CompletedProcess[str]:
    argv = [a.format(log=log, out=out) for a in COMMANDS[cmd]]
    env = {**os.environ, "COLUMNS": "200"}
    return subprocess.run([str(EXE), *argv], capture_output=True, text=True, timeout=300,
                          env=env)


#: Cases run through the console script itself (a process each, ~1.5 s of start-up); the
#: others go through the same ``main`` in this process, and the two are checked to agree.
THROUGH_SCRIPT = ("empty", "cut_in_last_chunk", "flipped_metadata_then_cut")


def _run_here(cmd: str, log: Path, out: Path) -> subprocess.CompletedProcess[str]:
    """What the console script does (``hil.cli.main``, its return code or SystemExit), with
    stdout and stderr captured: a traceback escaping ``main`` fails the test."""
    import contextlib
    import io

    from hil.cli import main

    argv = [a.format(log=log, out=out) for a in COMMANDS[cmd]]
    so, se = io.StringIO(), io.StringIO()
    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "200"
    try:
        with contextlib.redirect_stdout(so), contextlib.redirect_stderr(se):
            try:
                code = main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        if columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = columns
    return subprocess.CompletedProcess([str(EXE), *argv], int(code or 0), so.getvalue(),
                                       se.getvalue())


def _jobs() -> list[tuple[str, str]]:
    return [(name, cmd) for name, codes in EXPECTED.items()
            for cmd, code in zip(COMMANDS, codes, strict=True) if code is not None]


@pytest.fixture(scope="module")
def results(logs: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
            ) -> dict[tuple[str, str], subprocess.CompletedProcess[str]]:
    """Every (case, command) run once per run (not once per xdist worker): the console
    script's cases two processes at a time, the rest through ``main`` here."""
    return made_once(tmp_path_factory, "damaged-logs-results",
                     lambda out_dir: _results(logs, out_dir))


def _results(logs: dict[str, Path], out_dir: Path
             ) -> dict[tuple[str, str], subprocess.CompletedProcess[str]]:
    script = [job for job in _jobs() if job[0] in THROUGH_SCRIPT]
    with ThreadPoolExecutor(max_workers=2) as pool:
        done = dict(zip(script, pool.map(
            lambda job: _run(job[1], logs[job[0]], out_dir / f"{job[0]}.csv"), script),
            strict=True))
    for name, cmd in _jobs():
        if (name, cmd) not in done:
            done[(name, cmd)] = _run_here(cmd, logs[name], out_dir / f"{name}.here.csv")
    return done


def test_the_console_script_and_main_here_agree(logs: dict[str, Path], results: dict,
                                                tmp_path: Path) -> None:
    """The in-process runs stand for the console script: on the cases run both ways, the
    same exit code and the same stderr, byte for byte."""
    for name, cmd in [job for job in _jobs() if job[0] in THROUGH_SCRIPT]:
        p = results[(name, cmd)]
        out = Path(p.args[-1]) if cmd == "export" else tmp_path / f"{name}.csv"
        q = _run_here(cmd, logs[name], out)
        assert (q.returncode, q.stderr) == (p.returncode, p.stderr), (name, cmd)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_exit_code_and_one_line_on_stderr(name: str, logs: dict[str, Path],
                                          results: dict) -> None:
    for cmd, want in zip(COMMANDS, EXPECTED[name], strict=True):
        if want is None:
            continue
        p = results[(name, cmd)]
        where = f"{cmd} {name}: rc {p.returncode}, stderr {p.stderr!r}"
        assert "Traceback" not in p.stderr, where
        assert p.returncode == want, where
        lines = p.stderr.splitlines()
        assert len(lines) == 1, where
        prefix = "eha-hil replay: " if cmd == "replay" else "eha-hil log: "
        assert lines[0].startswith(prefix) and logs[name].name in lines[0], where


def test_truncated_replay_says_so_and_where(results: dict) -> None:
    """A cut log is replayed up to its readable end, and both streams say it is cut."""
    p = results[("cut_in_last_chunk", "replay")]
    assert "TRUNCATED log (file ends inside a Chunk record at byte" in p.stdout
    assert "MCU steps" in p.stdout and "match bit for bit" in p.stdout
    steps = int(p.stdout.split("MCU steps")[0].split()[-1])
    assert 0 < steps < 5 * (CYCLES - 1)  # a prefix: more than nothing, less than the whole run
    assert "truncated: file ends inside a Chunk record at byte" in p.stderr
    assert "replayed up to t = " in p.stderr


def test_truncated_replay_json_says_truncated(logs: dict[str, Path]) -> None:
    p = subprocess.run([str(EXE), "replay", str(logs["end_dropped"]), "--json"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 1
    data = json.loads(p.stdout)
    assert data["ok"] and data["truncated"] and data["stop_reason"].startswith("file ends")
    assert data["mcu_steps"] == 5 * (CYCLES - 1)  # only the summary is lost: every step replayed


@pytest.mark.parametrize(("name", "cmd", "words"), [
    ("no_mcu_data", "replay", "no MCU cycle logged: nothing to replay"),
    ("cut_in_first_chunk", "replay", "truncated before the MCU channels of box 0"),
    ("cut_in_metadata", "replay", "truncated before its replay metadata"),
    ("flipped_metadata_then_cut", "replay", "replay metadata: config:"),
    ("flipped_length_byte", "info", "(a damaged length field)"),
    ("flipped_chunk_byte", "export", "damaged at byte"),
    ("cut_in_last_chunk", "info", "truncated: file ends inside a Chunk record at byte"),
])
def test_the_line_says_what_is_wrong(name: str, cmd: str, words: str, results: dict) -> None:
    assert words in results[(name, cmd)].stderr
