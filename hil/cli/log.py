"""``eha-hil log info|export``: the frame-log verbs, to be hung under the main parser.

``configure_log(parser)`` adds the subcommands to a (sub)parser; ``run_log(args)`` runs the
chosen one and returns the exit code: 0 for a complete log; 1 for a truncated one (the
summary, or the CSV of what is readable, is still written) after one line on stderr saying
where it ends; 2 after one line ``eha-hil log: ...`` on stderr for a missing, foreign or
damaged file or a bad option. Never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hil.framelog.export import export_csv, export_parquet, summary_text
from hil.framelog.reader import FrameLogError, FrameLogReader, LogInfo

EXIT_TRUNCATED = 1
EXIT_USAGE = 2


def configure_log(parser: argparse.ArgumentParser) -> None:
    """Add ``info LOG [--json]`` and ``export LOG OUT [--format frames|identify]
    [--topic T ...] [--field F ...] [--board B]``."""
    sub = parser.add_subparsers(dest="log_command", metavar="ACTION", required=True)
    p = sub.add_parser("info", help="summarise a frame log (channels, counts, time range, "
                       "whether it is complete)")
    p.add_argument("log", metavar="LOG", help="MCAP frame log, or a capture (.pcapng, "
                   ".pcap) or CAN log (.blf, .asc, .log) of the fieldbus")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
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


def _truncated(info: LogInfo) -> int:
    """0 for a complete log; for a truncated one, the one stderr line and EXIT_TRUNCATED.

    A cut log is what a killed run leaves: it is read up to its last complete record, but a
    script must not take it for a whole one, hence the exit code."""
    if info.complete:
        return 0
    from hil.cli import cutfiles

    return cutfiles.report("log", info.path, info.stop_reason,
                           None if info.readable_until_ns is None
                           else info.readable_until_ns / 1e9)


def _traffic_info(args: argparse.Namespace) -> int:
    """A capture or CAN log (hil.fieldbus.traffic): 1 if it is cut or damaged."""
    from hil.fieldbus.traffic import TrafficError, read_traffic, summary, summary_text

    try:
        traffic = read_traffic(args.log)
    except TrafficError as exc:
        raise FrameLogError(str(exc)) from None
    s = summary(traffic)
    print(json.dumps(s, indent=2) if args.json else summary_text(s))
    if traffic.cut is None:
        return 0
    from hil.cli import cutfiles

    return cutfiles.report("log", args.log, traffic.cut, traffic.read_until_s)


def _info(args: argparse.Namespace) -> int:
    from hil.fieldbus.traffic import is_traffic_file

    if is_traffic_file(args.log):
        return _traffic_info(args)
    info = FrameLogReader(args.log).info()
    if args.json:
        print(json.dumps(info.to_dict(), indent=2))
    else:
        print(summary_text(info))
    return _truncated(info)


def _export(args: argparse.Namespace) -> int:
    out = Path(args.out)  # checked by its argument type (directory, writable, not the LOG)
    fmt = getattr(args, "format", "frames")
    if fmt == "identify":
        for opt in ("topic", "field"):
            if getattr(args, opt, None):
                raise FrameLogError(f"--{opt}: only with --format frames (--format identify "
                                    "writes its own columns; choose the board with --board)")
    elif getattr(args, "board", None):
        raise FrameLogError("--board: only with --format identify")
    info = FrameLogReader(args.log).info()
    if fmt == "identify":
        from hil.framelog.identify_export import export_identify

        got = []
        if not _written(args.out, lambda out: got.append(export_identify(
                args.log, out, board=args.board, info=info))):
            return _truncated(info)
        res = got[0]
        if args.out != "-":
            print(f"wrote {res.rows} samples of board {res.board} ({res.load}, "
                  f"{res.sample_rate_hz:g} Hz; {res.skipped} leading frame(s) from before the "
                  f"first upstream sweep left out) to {args.out}")
        return _truncated(info)
    if out.suffix.lower() == ".parquet":
        if args.out == "-":
            raise FrameLogError("Parquet cannot go to stdout: give a .parquet file name")
        export = export_parquet
    else:
        export = export_csv
    rows = []
    if _written(args.out, lambda out: rows.append(export(
            args.log, out, topics=args.topic, fields=args.field, info=info))) \
            and args.out != "-":
        print(f"wrote {rows[0]} rows to {args.out}")
    return _truncated(info)


def _written(out: str, fn) -> bool:  # noqa: ANN001 - fn(path) writes the export
    """Write the export to ``out`` whole or not at all (:func:`hil.cli.outputs.write`; stdout
    as it comes). False: it failed, and the root's line says so."""
    from hil.cli import outputs

    if out == "-":
        fn(out)
        return True
    return outputs.write("export", out, fn)


def run_log(args: argparse.Namespace) -> int:
    """Run ``args.log_command``; 0 on success, 1 for a truncated log, 2 for a file that
    cannot be read or a bad option; each non-zero code with one line on stderr."""
    try:
        if args.log_command == "info":
            return _info(args)
        if args.log_command == "export":
            return _export(args)
        raise FrameLogError(f"unknown action {args.log_command!r}")
    except FrameLogError as exc:
        print(f"eha-hil log: {exc}", file=sys.stderr)
    except BrokenPipeError:  # e.g. piped into head: not an error
        return 0
    except OSError as exc:  # e.g. the CSV cannot be written
        name = exc.filename if exc.filename is not None else ""
        print(f"eha-hil log: {name}: {exc.strerror or exc}", file=sys.stderr)
    return EXIT_USAGE
