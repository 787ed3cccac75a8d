"""CSV export, the info summary and the `log` subcommands (through a throwaway parser)."""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
import pytest

from firmware_model.fpga.layout import D_IQ_REF, UP_REGISTERS
from hil.cli.log import configure_log, run_log
from hil.framelog import decoders as D
from hil.framelog.export import export_csv, summary_text
from hil.framelog.formats import ENC_ETHERCAT, ENC_LVDS_DOWN, ENC_LVDS_UP
from hil.framelog.reader import FrameLogError, FrameLogReader
from hil.framelog.writer import FrameLogWriter
from protocols import ethercat


@pytest.fixture()
def log(tmp_path: Path) -> Path:
    path = tmp_path / "run.mcap"
    frame = ethercat.encode_frame([ethercat.Datagram(ethercat.Command.BRD, idx=4, ado=0x130,
                                                     data=bytes(2), wkc=2)])
    with FrameLogWriter(path, level="mcu", metadata={"config": "x = 1\n" * 30, "seed": 5}) as w:
        bus = w.add_channel("/fieldbus/frames", ENC_ETHERCAT, schema_name="")
        up = w.add_block_channel("/lvds/0/up", ENC_LVDS_UP, dtype=np.uint16,
                                 width=len(UP_REGISTERS))
        down = w.add_channel("/lvds/0/down", ENC_LVDS_DOWN, schema_name="")
        sig = w.add_json_channel("/signals/piston", {"x_mm": "number"})
        other = w.add_channel("/misc/blob", "application/x-unknown", schema_name="")
        w.write(bus, 1_000_000, frame)
        w.write(bus, 2_000_000, b"\x01\x02")  # not a frame: a decode error row
        regs = np.zeros((2, len(UP_REGISTERS)), np.uint16)
        regs[:, 8] = [0xFFFF, 5]  # iq, s16
        w.write_block(up, np.array([1_200_000, 1_400_000]), regs)
        w.write(down, 1_500_000, D.encode_lvds_down([(D_IQ_REF, 300)]))
        w.write_json(sig, 500_000, {"x_mm": 1.25})
        w.write(other, 3_000_000, b"abcd")
    return path


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="eha-hil log")
    configure_log(parser)
    return parser.parse_args(argv)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_export_all(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "all.csv"
    assert export_csv(log, out) == 7
    rows = _rows(out)
    assert [r["t_s"] for r in rows] == ["0.000500000", "0.001000000", "0.001200000",
                                        "0.001400000", "0.001500000", "0.002000000",
                                        "0.003000000"]
    assert rows[0]["topic"] == "/signals/piston" and rows[0]["x_mm"] == "1.25"
    bus = rows[1]
    assert (bus["datagrams"], bus["dg0.cmd"], bus["dg0.idx"], bus["dg0.address"],
            bus["dg0.wkc"]) == ("1", str(int(ethercat.Command.BRD)), "4", str(0x130 << 16), "2")
    assert rows[2]["iq"] == "-1" and rows[3]["iq"] == "5" and rows[2]["x_mm"] == ""
    assert rows[4]["iq_ref"] == "300"
    assert rows[5]["decode_error"].startswith("EtherCAT frame") and rows[5]["datagrams"] == ""
    assert rows[6]["length"] == "4"  # no decoder for this encoding
    assert list(rows[0])[:2] == ["t_s", "topic"] and list(rows[0])[-1] == "decode_error"


def test_export_topics_and_fields(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "sel.csv"
    assert export_csv(log, out, topics=["/lvds/0/up"], fields=["iq", "tick"]) == 2
    with open(out) as f:
        assert f.read() == "t_s,topic,iq,tick\n0.001200000,/lvds/0/up,-1,0\n" \
                           "0.001400000,/lvds/0/up,5,0\n"
    # fields across topics: only frames that have one of them
    assert export_csv(log, out, fields=["iq_ref", "x_mm"]) == 2
    with pytest.raises(FrameLogError, match="field 'nope' occurs in no frame"):
        export_csv(log, out, fields=["nope"])
    with pytest.raises(FrameLogError, match="no topic '/lvds/9/up'"):
        export_csv(log, out, topics=["/lvds/9/up"])


def test_summary_text(log: Path) -> None:
    text = summary_text(FrameLogReader(log).info())
    assert "state: complete" in text and "level mcu" in text
    assert "config=<180 characters, 31 lines>" in text and "seed=5" in text
    assert "/lvds/0/up" in text and f"block {len(UP_REGISTERS)} x uint16" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("/lvds/0/up"))
    assert line.split()[-4:] == ["1", "2", "0.001200", "0.001400"]


def test_cli_info(log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_log(_parse(["info", str(log)])) == 0
    assert "state: complete" in capsys.readouterr().out
    assert run_log(_parse(["info", str(log), "--json"])) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["complete"] and (data["message_count"], data["frame_count"]) == (6, 7)
    assert {c["topic"] for c in data["channels"]} >= {"/fieldbus/frames", "/lvds/0/up"}


def test_cli_info_truncated(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
                            ) -> None:
    # A cut log is summarised, but exits 1 with one line on stderr: it is not a whole log.
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[:-40])
    assert run_log(_parse(["info", str(cut)])) == 1
    out, err = capsys.readouterr()
    assert "state: TRUNCATED" in out
    assert err.startswith(f"eha-hil log: {cut}: truncated: file ends inside")
    assert err.count("\n") == 1
    csv_out = tmp_path / "cut.csv"
    assert run_log(_parse(["export", str(cut), str(csv_out)])) == 1
    out, err = capsys.readouterr()
    assert "wrote 7 rows" in out and "truncated" in err and err.count("\n") == 1


def test_cli_export(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.csv"
    assert run_log(_parse(["export", str(log), str(out), "--topic", "/signals/piston"])) == 0
    assert "wrote 1 rows" in capsys.readouterr().out
    assert _rows(out)[0]["x_mm"] == "1.25"
    assert run_log(_parse(["export", str(log), "-", "--field", "iq_ref"])) == 0
    assert capsys.readouterr().out == "t_s,topic,iq_ref\n0.001500000,/lvds/0/down,300\n"


@pytest.mark.parametrize(("argv", "match"), [
    (["info", "{missing}"], "no such file"),
    (["info", "{empty}"], "empty file"),
    (["info", "{text}"], "not an MCAP file"),
    (["export", "{log}", "{tmp}/y.csv", "--topic", "/x"], "no topic '/x'"),
    (["export", "{log}", "{tmp}/y.csv", "--field", "zz"], "field 'zz'"),
])
def test_cli_errors_are_one_line(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 argv: list[str], match: str) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "text.mcap").write_text("hello\n")
    names = {"missing": tmp_path / "missing.mcap", "empty": tmp_path / "empty.mcap",
             "text": tmp_path / "text.mcap", "log": log, "tmp": tmp_path}
    args = [a.format(**{k: str(v) for k, v in names.items()}) for a in argv]
    assert run_log(_parse(args)) == 2
    err = capsys.readouterr().err
    assert err.startswith("eha-hil log: ") and match in err
    assert err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize(("out", "match"), [
    ("{tmp}/nodir/x.csv", "does not exist"),
    ("{tmp}", "is a directory"),
    ("{log}", "is also an input"),  # the log itself: never overwritten with its CSV
    ("{tmp}/./{logname}", "is also an input"),  # another spelling of the same file
])
def test_export_output_checked_by_the_command_line(
        log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], out: str,
        match: str) -> None:
    from hil.cli import main

    (tmp_path / log.name).write_bytes(log.read_bytes())
    log = tmp_path / log.name
    before = log.read_bytes()
    try:
        code = main(["log", "export", str(log),
                     out.format(tmp=tmp_path, log=log, logname=log.name)])
    except SystemExit as exc:  # argparse's own exit for a bad argument
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and match in err and err.count("\n") == 1, err
    assert log.read_bytes() == before


def test_cli_damaged_file(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
                          ) -> None:
    data = bytearray(log.read_bytes())
    data[len(data) // 3] ^= 0xFF  # somewhere in the chunk
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert run_log(_parse(["info", str(bad)])) == 2
    err = capsys.readouterr().err
    assert err.startswith("eha-hil log: ") and "damaged at byte" in err and err.count("\n") == 1
