"""The command line starts without the simulation: building the parser, any ``--help``, an
argument mistake and a log's summary import no numba (its kernels are the commands' to
load), and a help no bus, log or table library either; the scenarios the help lists come
from the catalogue their runners register under."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: Run in a fresh interpreter (this one has the kernels loaded by other tests): build the
#: whole registry and each group alone, print every parser's help, note what that imported;
#: make mistakes through the root (bad options, an unknown scenario, a sweep of nothing),
#: report each one's exit code and stderr; read a log's summary (``log info``); then what
#: got imported. One interpreter for all: each start is a noticeable part of the check.
_PROBE = r"""
import contextlib, io, json, sys
from hil.cli.args import walk
from hil.cli.root import GROUPS, build_parser, main

helps = 0
for word in [None] + [w for words, _ in GROUPS for w in words]:
    for p in walk(build_parser(word)):
        helps += bool(p.format_help())
help_packages = sorted({m.split(".")[0] for m in sys.modules})
mistakes = {}
for argv in (["bus", "run", "--bogus"], ["log", "info"], ["run", "f5", "--bogus"],
             ["sweep", "f5", "--samples", "0"], ["identify-synth", "x.csv", "--profile", "no"],
             ["serve", "--bogus"], ["bench", "bus", "--bogus"], ["log", "--help"],
             ["run", "nosuch"], ["sweep", "nosuch"], ["sweep", "f5"]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:  # --help ends in argparse's exit
            code = exc.code
    mistakes[" ".join(argv)] = [code, err.getvalue()]
out = io.StringIO()
with contextlib.redirect_stdout(out):
    info = [main(["log", "info", sys.argv[1]]), out.getvalue()]
heavy = sorted(m for m in ("numba", "llvmlite", "scipy", "pandas") if m in sys.modules)
print(json.dumps({"helps": helps, "help_packages": help_packages, "mistakes": mistakes,
                  "info": info, "heavy": heavy}))
"""

#: Libraries no help has a use for, each a noticeable part of a start of the console script
#: (numpy is not one of them: the configuration and the identification's effect names, which
#: the root's help lists, are made with it).
_HEAVY = {"numba", "llvmlite", "scipy", "pandas", "pyarrow", "dask", "matplotlib",
          "can", "serial", "mcap", "dpkt", "unicorn"}
#: A log the probe's ``log info`` reads.
_LOG = Path(__file__).parents[1] / "data" / "replay" / "recipe3_robot.mcap"


def test_helps_mistakes_and_a_log_summary_load_no_kernels():
    """No help, mistake or log summary loads numba; no help python-can, pyserial, pandas
    or the log's library either; a log's summary needs its reader, not the writer's
    compiled byte planes."""
    out = subprocess.run([sys.executable, "-c", _PROBE, str(_LOG)], capture_output=True,
                         text=True, check=True, timeout=120)
    probe = json.loads(out.stdout)
    assert probe["helps"] > 50  # every command's parser was built and printed
    assert sorted(_HEAVY & set(probe["help_packages"])) == []
    assert probe["heavy"] == [], probe["heavy"]
    for argv, (code, err) in probe["mistakes"].items():
        if argv.endswith("--help"):
            assert code == 0 and err == "", argv
            continue
        assert code == 2, (argv, code, err)
        assert err.count("\n") == 1 and err.startswith("eha-hil "), (argv, err)
    code, text = probe["info"]
    assert code == 0 and _LOG.name in text


def test_the_root_help_lists_the_shipped_presets():
    """The root finds the presets without the configuration module; the same list."""
    from hil.cli.root import build_parser
    from plant.config import preset_names

    assert build_parser().epilog.startswith(f"Presets: {', '.join(preset_names())}. ")


def test_every_listed_scenario_runs_and_every_runner_is_listed():
    """The help lists the catalogue (hil.scenarios.catalog); the runners register under its
    names (hil.scenarios.register takes the summary and settings from it)."""
    from hil.scenarios import SCENARIOS
    from hil.scenarios import names as registered
    from hil.scenarios.catalog import CATALOG

    assert registered() == sorted(CATALOG)  # registered() loads every scenario module
    assert all(SCENARIOS[n].summary == e.summary and SCENARIOS[n].knobs == e.knobs
               for n, e in CATALOG.items())


def test_a_runner_under_a_name_not_listed_is_refused():
    from hil.scenarios import register

    with pytest.raises(KeyError, match="f99"):
        register("f99")
