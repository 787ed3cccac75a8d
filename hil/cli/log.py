"""``eha-hil log info|export``: the frame-log verbs, to be hung under the main parser.

``configure_log(parser)`` adds the subcommands to a (sub)parser; ``run_log(args)`` runs the
chosen one: exit 0 for a complete log; 1 for a truncated one (the summary, or the CSV of
what is readable, is still written) after one line on stderr saying where it ends; 2 after
one line ``eha-hil log: ...`` on stderr for a missing, foreign or damaged file
or a bad option. Never a traceback.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from hil.cli.contract import (
    EXIT_FAILED,
    Context,
    Outcome,
    StdoutError,
    UsageError,
    command,
    standalone,
)

if TYPE_CHECKING:  # hil.framelog loads its compiled kernels (numba): imported by the commands
    from hil.framelog.reader import LogInfo


def configure_log(parser: argparse.ArgumentParser) -> None:
    """Add ``info LOG [--json]`` and ``export LOG OUT [--format frames|identify]
    [--topic T ...] [--field F ...] [--board B]``."""
    sub = parser.add_subparsers(dest="log_command", metavar="ACTION", required=True)
    p = sub.add_parser("info", help="summarise a frame log (channels, counts, time range, "
                       "whether it is complete)")
    p.add_argument("log", metavar="LOG", help="MCAP frame log, or a capture (.pcapng, "
                   ".pcap) or CAN log (.blf, .asc, .log) of the fieldbus")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    command(p, run_log, verb="eha-hil log")
    p = sub.add_parser("export", help="decode frames to CSV (t_s, topic, decoded fields), "
                       "or one board's measurements as an identification CSV")
    p.add_argument("log", metavar="LOG", help="MCAP frame log")
    from hil.cli.args import output_file

    p.add_argument("out", metavar="OUT", type=output_file(None, stdout=True),
                   help="file to write: .parquet for Parquet, else CSV ('-': stdout); never "
                   "the LOG itself")
    p.add_argument("--format", choices=("frames", "identify"), default="frames",
                   help="frames (default): one row per frame with its decoded fields; "
                   "identify: what the MCU read from one board, in SI units, as the input of "
                   "eha-hil identify (docs/framelog.md)")
    p.add_argument("--topic", action="append", metavar="T",
                   help="export only this topic (repeatable; default all; --format frames)")
    p.add_argument("--field", action="append", metavar="F",
                   help="export only this decoded field (repeatable; default all; "
                   "--format frames)")
    p.add_argument("--board", metavar="B",
                   help="--format identify: the board, e.g. 0.0 (needed when the log has "
                   "several)")
    command(p, run_log, verb="eha-hil log")


def _truncated(info: LogInfo, text: str | None, data: object = None) -> Outcome:
    """The outcome: exit 0 for a complete log; for a truncated one, exit 1 and one line
    saying where it ends.

    A cut log is what a killed run leaves: it is read up to its last complete record, but a
    script must not take it for a whole one, hence the exit code."""
    if info.complete:
        return Outcome(text, data)
    from hil.cli import cutfiles

    return Outcome(text, data, EXIT_FAILED, error=cutfiles.message(
        info.path, info.stop_reason,
        None if info.readable_until_ns is None else info.readable_until_ns / 1e9))


def _traffic_info(args: argparse.Namespace) -> Outcome:
    """A capture or CAN log (hil.fieldbus.traffic): 1 if it is cut or damaged."""
    from hil.fieldbus.traffic import TrafficError, read_traffic, summary, summary_text
    from hil.framelog.reader import FrameLogError

    try:
        traffic = read_traffic(args.log)
    except TrafficError as exc:
        raise FrameLogError(str(exc)) from None
    s = summary(traffic)
    if traffic.cut is None:
        return Outcome(summary_text(s), s)
    from hil.cli import cutfiles

    return Outcome(summary_text(s), s, EXIT_FAILED,
                   error=cutfiles.message(args.log, traffic.cut, traffic.read_until_s))


def _info(args: argparse.Namespace) -> Outcome:
    from hil.fieldbus.traffic import is_traffic_file
    from hil.framelog.export import summary_text
    from hil.framelog.reader import FrameLogReader

    if is_traffic_file(args.log):
        return _traffic_info(args)
    info = FrameLogReader(args.log).info()
    return _truncated(info, summary_text(info), info.to_dict())


def _export(args: argparse.Namespace) -> Outcome:
    from hil.framelog.export import export_csv, export_parquet
    from hil.framelog.reader import FrameLogError, FrameLogReader

    out = Path(args.out)  # checked by its argument type (directory, writable, not the LOG)
    fmt = args.format
    if fmt == "identify":
        for opt in ("topic", "field"):
            if vars(args)[opt]:
                raise FrameLogError(f"--{opt}: only with --format frames (--format identify "
                                    "writes its own columns; choose the board with --board)")
    elif args.board:
        raise FrameLogError("--board: only with --format identify")
    if fmt == "identify":
        info = FrameLogReader(args.log).info()
        from hil.framelog.identify_export import export_identify

        got: list = []
        if not _written(args.out, lambda o: got.append(export_identify(
                args.log, o, board=args.board, info=info))):
            return _truncated(info, None)
        res = got[0]
        text = None if args.out == "-" else (
            f"wrote {res.rows} samples of board {res.board} ({res.load}, "
            f"{res.sample_rate_hz:g} Hz; {res.skipped} leading frame(s) from before the "
            f"first upstream sweep left out) to {args.out}")
        return _truncated(info, text)
    if out.suffix.lower() == ".parquet":
        if args.out == "-":
            raise FrameLogError("Parquet cannot go to stdout: give a .parquet file name")
        export = export_parquet
    else:
        export = export_csv
    rows: list[int] = []
    read: list[LogInfo] = []  # the export's planning pass summarises the log too
    if not _written(args.out, lambda o: rows.append(export(
            args.log, o, topics=args.topic, fields=args.field, summary=read))):
        return _truncated(read[0] if read else FrameLogReader(args.log).info(), None)
    return _truncated(read[0], None if args.out == "-" else f"wrote {rows[0]} rows to {args.out}")


def _written(out: str, fn) -> bool:  # noqa: ANN001 - fn(path) writes the export
    """Write the export to ``out`` whole or not at all (:func:`hil.cli.outputs.write`; stdout
    as it comes). False: it failed, and the root's line says so (exit 1)."""
    from hil.cli import outputs

    if out == "-":
        fn(out)
        return True
    return outputs.write("export", out, fn)


@standalone("eha-hil log")
def run_log(args: argparse.Namespace, ctx: Context) -> Outcome:
    """Run ``args.log_command``: exit 0 on success, 1 for a truncated log, 2 for a file
    that cannot be read or a bad option; each non-zero code with one line on stderr."""
    from hil.framelog.reader import FrameLogError

    try:
        if args.log_command == "info":
            return _info(args)
        return _export(args)
    except FrameLogError as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:  # e.g. the CSV cannot be written
        if isinstance(exc, StdoutError):  # stdout itself: the root's to say
            raise
        name = exc.filename if exc.filename is not None else ""
        raise UsageError(f"{name}: {exc.strerror or exc}") from None
