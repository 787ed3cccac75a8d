"""``eha-hil identify-check``: the identification judged on the independent rig's matrix.

::

    eha-hil identify-check [--seeds 1 2] [--load L] [--case TEXT] [--jobs N]
                           [--markdown FILE] [--rows FILE.jsonl] [--json]

Runs :func:`hil.identify.rigcheck.run_matrix` (a line of progress per case on stderr), prints
the markdown table (or JSON) and exits 0 when every case is right, 1 otherwise. ``--rows``
writes each case's JSON as it finishes, so a run stopped part way keeps what it judged.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys

from hil.cli.args import int_range, output_file
from hil.cli.contract import EXIT_FAILED, EXIT_OK, Context, Outcome, UsageError, standalone


def configure_check(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``eha-hil identify-check``."""
    from hil.identify.rigcheck import LOADS

    parser.add_argument("--seeds", type=int_range(0, 2**31 - 1), nargs="+", default=[1, 2],
                        help="rig seeds (parameters, phases, noise); default 1 2")
    parser.add_argument("--load", choices=LOADS, action="append", default=None,
                        help="only cases of this load (repeatable)")
    parser.add_argument("--case", action="append", default=None, metavar="TEXT",
                        help="only cases whose label contains TEXT (repeatable), e.g. "
                             "'null' or 'seal_friction'")
    parser.add_argument("--jobs", type=int_range(1, 64), default=min(2, os.cpu_count() or 1),
                        help="worker processes (default: up to 2)")
    parser.add_argument("--markdown", type=output_file((".md",), text=True), default=None,
                        metavar="FILE.md", help="also write the table to this file")
    parser.add_argument("--rows", type=output_file((".jsonl",), text=True), default=None,
                        metavar="FILE.jsonl",
                        help="write each case's result (the --json row) to this file as a "
                             "line as soon as it is judged: a run stopped part way keeps them")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")


@standalone("eha-hil identify-check")
def run_check(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Run the matrix; 0 when every case is right, 1 when one is not, 2 for no case."""
    from hil.identify.rigcheck import CaseResult, default_cases, markdown, run_matrix

    cases = default_cases()
    if args.load:
        cases = [c for c in cases if c.load in args.load]
    if args.case:
        cases = [c for c in cases if any(s in c.label for s in args.case)]
    if not cases:
        raise UsageError("no case matches --load/--case")

    from hil.cli import outputs

    rows = open(args.rows, "w", encoding="utf-8") if args.rows else None  # noqa: SIM115

    def drop_rows(exc: OSError) -> None:
        # A full disk stops the rows file, not the matrix: the file is removed (no torn
        # line passed off as the run's rows), the failure is named at the end (exit 1)
        # and the table still reaches stdout.
        nonlocal rows
        with contextlib.suppress(OSError):
            rows.close()
        with contextlib.suppress(OSError):
            os.remove(args.rows)
        outputs.failed("rows", args.rows, exc)
        rows = None

    def progress(r: CaseResult, i: int, n: int) -> None:
        mark = "ok " if r.right else "NO "
        sys.stderr.write(f"[{i}/{n}] {mark} seed {r.seed} {r.case.label}: {r.why} "
                         f"({r.wall_s:.0f} s wall, {r.cpu_s:.0f} s CPU)\n")  # one write a line
        sys.stderr.flush()
        if rows is not None:
            try:
                rows.write(json.dumps(r.as_dict(), sort_keys=True) + "\n")
                rows.flush()
            except OSError as exc:
                drop_rows(exc)

    try:
        results = run_matrix(cases, args.seeds, jobs=args.jobs, progress=progress)
    finally:
        if rows is not None:
            try:
                rows.close()
            except OSError as exc:
                drop_rows(exc)
    table = markdown(results)
    files = ()
    if args.markdown:  # written after the result is printed: an interruption keeps it
        from pathlib import Path

        from hil.cli.outputs import Later

        files = (Later("table", args.markdown,
                       lambda tmp: Path(tmp).write_text(table + "\n", encoding="utf-8")),)
    return Outcome(table, [r.as_dict() for r in results],
                   EXIT_OK if all(r.right for r in results) else EXIT_FAILED, files=files)


__all__ = ["configure_check", "run_check"]
