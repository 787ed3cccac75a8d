"""Logs written before the raw channels became protobuf containers (block messages
``eha-hil/block``, bare frames, the byte layout as an ``eha-hil/layout`` schema) still
read and export, and the writer's old form reads back the same as the new one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hil.framelog import FrameLogReader, FrameLogWriter
from hil.framelog.export import export_csv, export_parquet
from hil.framelog.layout import SCHEMA_ENCODING, words

OLD_LOG = Path(__file__).resolve().parents[1] / "data" / "replay" / "before_layout.mcap"


def test_committed_old_log_exports_every_channel_by_its_layout(tmp_path: Path) -> None:
    info = FrameLogReader(OLD_LOG).info()
    assert {c.message_encoding for c in info.channels if c.framing == "block"} == \
        {"eha-hil/block"}
    out = tmp_path / "old.csv"
    assert export_csv(OLD_LOG, out) == info.frame_count
    df = pd.read_csv(out)
    assert "decode_error" not in df.columns
    # that log predates the layout schemas: the channels with a decoder are decoded (the
    # sensor frames, the LVDS line words, the EtherCAT frames), the others give a length
    for topic, field in (("/sensors/0.0/raw", "hall"), ("/lvds/0.0/up_words", "crc_ok"),
                         ("/fieldbus/frames", "dg0.wkc"), ("/lvds/0.0/up", "length")):
        rows = df[df["topic"] == topic]
        assert len(rows) == info.channel(topic).frame_count > 0, topic
        assert rows[field].notna().all(), topic
    assert (df.loc[df["topic"] == "/lvds/0.0/up_words", "crc_ok"] == 1).all()


def test_old_and_new_containers_read_and_export_the_same(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    lay = words("eha-hil/test-words", [("a", "u16"), ("b", "s16"), ("c", "u32")], 4)
    t = np.cumsum(rng.integers(1, 1000, 300))
    frames = rng.integers(0, 2**31, (300, 3)).astype(np.uint32)
    paths = {}
    for container in ("protobuf", "eha-hil/block"):
        p = paths[container] = tmp_path / f"{container.replace('/', '_')}.mcap"
        with FrameLogWriter(p, chunk_size=2000) as w:
            ch = w.add_block_channel("/w", lay.encoding, dtype=np.uint32, width=3,
                                     schema_name=lay.encoding, schema_encoding=SCHEMA_ENCODING,
                                     schema_data=lay.schema(), container=container)
            for k in range(0, 300, 50):
                w.write_block(ch, t[k:k + 50], frames[k:k + 50])
            bus = w.add_channel("/bus", "eha-hil/ethercat-fcs") if container == "protobuf" \
                else None
            if bus is not None:
                w.write(bus, int(t[-1]), b"\x01\x02\x03")
    new, old = FrameLogReader(paths["protobuf"]), FrameLogReader(paths["eha-hil/block"])
    for r in (new, old):
        b = r.blocks("/w")
        assert np.array_equal(b.t_ns, t) and np.array_equal(b.frames, frames)
    assert [f for _, _, f in new.frames(["/bus"])] == [b"\x01\x02\x03"]  # unwrapped
    out = {}
    for name, p in paths.items():
        export_parquet(p, tmp_path / f"{p.stem}.parquet", topics=["/w"])
        out[name] = pd.read_parquet(tmp_path / f"{p.stem}.parquet")
    pd.testing.assert_frame_equal(out["protobuf"], out["eha-hil/block"])
    b = (frames[:, 1] & 0xFFFF).astype(np.uint16).view(np.int16)  # s16 in word 1
    assert out["protobuf"]["b"].tolist() == b.tolist()
