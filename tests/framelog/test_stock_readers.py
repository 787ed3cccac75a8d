"""Every channel of a ``bus run --log`` file opens with stock readers alone: the mcap
library and mcap-protobuf-support's decoder factory (what Foxglove's and PlotJuggler's
protobuf support does), no project code in the decoding. A one-box log at ``full`` (every
raw channel kind) and a ``hydra_full`` log (every box kind of the robot)."""

from __future__ import annotations

import contextlib
import io
import zlib
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tests.framelog.stock_blocks import block_rows

#: MCAP's well-known message encodings and the schema encodings Foxglove decodes.
STOCK_MESSAGE_ENCODINGS = {"ros1", "cdr", "protobuf", "flatbuffer", "cbor", "json"}
FOXGLOVE_SCHEMA_ENCODINGS = {"protobuf", "jsonschema", "ros1msg", "ros2msg", "ros2idl",
                             "omgidl", "flatbuffer"}


def _bus_run(path: Path, *argv: str) -> None:
    from hil.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["bus", "run", "--log", str(path), *argv])
    assert code == 0, err.getvalue()


def _check_every_message_decodes(path: Path) -> dict[str, list]:
    """Decode every message with the stock reader; topic -> decoded messages."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        for ch in summary.channels.values():
            schema = summary.schemas.get(ch.schema_id)
            assert ch.message_encoding in STOCK_MESSAGE_ENCODINGS, ch.topic
            assert schema is not None and schema.encoding in FOXGLOVE_SCHEMA_ENCODINGS, ch.topic
        out: dict[str, list] = {ch.topic: [] for ch in summary.channels.values()}
        for _, ch, _, decoded in reader.iter_decoded_messages():
            out[ch.topic].append(decoded)
        counts = summary.statistics.channel_message_counts
        for cid, ch in summary.channels.items():
            assert len(out[ch.topic]) == counts.get(cid, 0), ch.topic
    return out


def _check_raw_content(path: Path, decoded: dict[str, list]) -> None:
    """The raw channels carry what the replay reads, bit for bit: compare the stock
    decoder's bytes with the project's reader (which must agree), and the EtherCAT frames'
    header fields with the bytes of the frame they sit beside."""
    from hil.framelog import FrameLogReader

    r = FrameLogReader(path)
    blocks = {t: m for t, m in decoded.items()
              if m and m[0].DESCRIPTOR.full_name.startswith("eha_hil.raw.") and
              m[0].DESCRIPTOR.full_name.endswith("Block")}
    assert blocks, "no block channels"
    ours = r.blocks_many(blocks)
    for topic, msgs in blocks.items():
        rows = [block_rows(m) for m in msgs]
        t = np.concatenate([r[0] for r in rows])
        frames = np.concatenate([r[1] for r in rows])
        assert np.array_equal(t, ours[topic].t_ns), topic
        assert np.array_equal(frames, ours[topic].frames), topic
    frames = decoded["/fieldbus/frames"]
    assert frames
    for m in frames:
        pdu = m.frame[:-4]
        assert m.fcs_ok == ((zlib.crc32(pdu) & 0xFFFFFFFF).to_bytes(4, "little") == m.frame[-4:])
        assert m.pdu_ok and m.datagrams == len(m.wkc) >= 1
        # the last datagram's working counter is the two bytes before the FCS
        assert m.wkc[-1] == int.from_bytes(m.frame[-6:-4], "little")
        assert m.cmd[0] == m.frame[2] and m.length[-1] <= len(m.frame)


def test_one_box_full_log_decodes_with_stock_readers(tmp_path: Path) -> None:
    path = tmp_path / "one.mcap"
    _bus_run(path, "--seconds", "0.02", "--level", "full")
    decoded = _check_every_message_decodes(path)
    assert len(decoded) == 13  # every channel kind of the topic table
    _check_raw_content(path, decoded)


def test_hydra_full_log_decodes_with_stock_readers(tmp_path: Path) -> None:
    path = tmp_path / "hydra.mcap"
    _bus_run(path, "--topology", "hydra_full", "--model", "stack", "--seconds", "0.01")
    decoded = _check_every_message_decodes(path)
    assert len(decoded) > 100
    _check_raw_content(path, decoded)
