"""Decoders against the protocol codecs: encode with protocols, log, read back, decode."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.fpga.layout import (
    D_IQ_REF,
    D_SEQUENCE,
    FIRST_N_RAW,
    FIRST_N_UP,
    RAW_NAMES,
    U_IQ,
    U_TICK,
    UP_REGISTERS,
)
from hil.framelog import decoders as D
from hil.framelog.formats import (
    ENC_ETHERCAT,
    ENC_JSON,
    ENC_LVDS_DOWN,
    ENC_LVDS_UP,
    ENC_LVDS_WORD,
    ENC_SENSOR_RAW,
)
from hil.framelog.reader import FrameLogReader
from hil.framelog.writer import FrameLogWriter
from protocols import ethercat, lvds


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 255), st.integers(0, 0xFFFF))
def test_lvds_word_matches_protocol(addr: int, data: int) -> None:
    frame = D.encode_lvds_word(addr, data)
    assert int.from_bytes(frame, "little") == lvds.encode_word(addr, data)
    assert D.decode(ENC_LVDS_WORD, frame) == {"addr": addr, "data": data, "frame_ok": 1,
                                              "crc_ok": 1}


def test_lvds_word_with_bad_crc_or_framing() -> None:
    word = lvds.encode_word(0x1D, 0xBEEF)
    bad_crc = D.decode(ENC_LVDS_WORD, (word ^ 1).to_bytes(8, "little"))
    assert bad_crc["frame_ok"] == 1 and bad_crc["crc_ok"] == 0
    bad_start = D.decode(ENC_LVDS_WORD, (word ^ (1 << 44)).to_bytes(8, "little"))
    assert bad_start["frame_ok"] == 0 and bad_start["crc_ok"] == 0
    too_wide = D.decode(ENC_LVDS_WORD, (word | 1 << 50).to_bytes(8, "little"))
    assert too_wide["frame_ok"] == 0
    with pytest.raises(D.DecodeError, match="8 bytes"):
        D.decode(ENC_LVDS_WORD, b"\x00" * 6)


def test_lvds_up_names_and_signs() -> None:
    regs = np.arange(len(UP_REGISTERS), dtype=np.int64) * 3
    regs[U_IQ] = -1234  # s16 register
    regs[U_TICK] = 0xFFFF  # u16 register
    d = D.decode(ENC_LVDS_UP, D.encode_lvds_up(regs))
    assert list(d) == [r[1] for r in UP_REGISTERS]
    assert d["iq"] == -1234 and d["tick"] == 0xFFFF and d["state"] == 3
    with pytest.raises(D.DecodeError, match=f"{2 * len(UP_REGISTERS)} bytes"):
        D.decode(ENC_LVDS_UP, bytes(2 * len(UP_REGISTERS) + 2))
    with pytest.raises(D.DecodeError, match="lvds-up frame"):
        D.decode(ENC_LVDS_UP, bytes(2 * FIRST_N_UP - 2))


def test_frames_of_the_first_layout_decode_by_todays_names() -> None:
    """A log written before registers or raw words were appended holds the first ones."""
    regs = D.decode(ENC_LVDS_UP, bytes(range(2 * FIRST_N_UP)))
    assert list(regs) == [r[1] for r in UP_REGISTERS[:FIRST_N_UP]]
    assert regs["tick"] == int.from_bytes(bytes((60, 61)), "little")
    raw = D.decode(ENC_SENSOR_RAW, np.arange(FIRST_N_RAW, dtype="<u4").tobytes())
    assert list(raw) == list(RAW_NAMES[:FIRST_N_RAW]) and raw["hall"] == FIRST_N_RAW - 1


def test_lvds_down_names_signs_and_unknown_addresses() -> None:
    frame = D.encode_lvds_down([(D_IQ_REF, -500), (D_SEQUENCE, 7), (0x0F, 0x1234)])
    assert len(frame) == 9
    assert D.decode(ENC_LVDS_DOWN, frame) == {"iq_ref": -500, "sequence": 7,
                                              "addr_0x0f": 0x1234}
    with pytest.raises(D.DecodeError, match="triplets"):
        D.decode(ENC_LVDS_DOWN, b"\x00\x01")
    addr, data = D.down_writes(np.frombuffer(frame, np.uint8).reshape(3, 3))
    assert addr.tolist() == [D_IQ_REF, D_SEQUENCE, 0x0F]
    assert data.tolist() == [(-500) & 0xFFFF, 7, 0x1234]


def _datagrams() -> list[ethercat.Datagram]:
    return [ethercat.Datagram.logical(ethercat.Command.LRW, 0x00010000, bytes(32), idx=1, wkc=3),
            ethercat.Datagram(ethercat.Command.FPRD, idx=2, adp=0x1001, ado=0x0130,
                              data=bytes(2), wkc=1)]


@pytest.mark.parametrize("encode", [ethercat.encode_frame, ethercat.encode_udp_frame])
def test_ethercat_frames(encode) -> None:
    frame = encode(_datagrams())
    d = D.decode(ENC_ETHERCAT, frame)
    assert d["datagrams"] == 2 and d["frame_bytes"] == len(frame)
    assert (d["dg0.cmd"], d["dg0.idx"], d["dg0.address"], d["dg0.length"], d["dg0.wkc"]) == (
        ethercat.Command.LRW, 1, 0x00010000, 32, 3)
    assert (d["dg1.cmd"], d["dg1.address"], d["dg1.length"], d["dg1.wkc"]) == (
        ethercat.Command.FPRD, 0x1001 | 0x0130 << 16, 2, 1)
    with pytest.raises(D.DecodeError, match="EtherCAT"):
        D.decode(ENC_ETHERCAT, frame[:20])


def test_sensor_raw_and_json() -> None:
    raw = np.arange(len(RAW_NAMES)) * 1000
    raw[5] = (1 << 24) - 1
    d = D.decode(ENC_SENSOR_RAW, D.encode_sensor_raw(raw))
    assert list(d) == list(RAW_NAMES) and d["strain_code"] == (1 << 24) - 1
    j = D.decode(ENC_JSON, b'{"a": 1, "b": {"c": 2.5, "d": true}, "s": "x", "n": null}')
    assert j["a"] == 1 and j["b.c"] == 2.5 and j["b.d"] == 1 and "s" not in j
    assert math.isnan(j["n"])
    with pytest.raises(D.DecodeError, match="not JSON"):
        D.decode(ENC_JSON, b"{")
    with pytest.raises(D.DecodeError, match="not an object"):
        D.decode(ENC_JSON, b"[1]")


def test_registry() -> None:
    with pytest.raises(KeyError, match="no decoder"):
        D.decode("nobody/knows", b"")
    D.register_decoder("test/len", lambda b: {"n": len(b)})
    try:
        assert D.decode("test/len", b"abc") == {"n": 3} and "test/len" in D.decoders()
        assert D.decode_block("test/len", np.zeros((1, 1))) is None
    finally:
        D._DECODERS.pop("test/len")


def test_batch_decoders_agree_with_single(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    up = rng.integers(0, 1 << 16, (50, len(UP_REGISTERS)), dtype=np.uint16)
    words = np.array([lvds.encode_word(int(a), int(d)) for a, d in
                      zip(rng.integers(0, 256, 50), rng.integers(0, 1 << 16, 50), strict=True)],
                     dtype=np.uint64)
    words[::7] ^= np.uint64(1 << 3)  # some CRC failures
    raw = rng.integers(0, 1 << 32, (50, len(RAW_NAMES)), dtype=np.uint32)
    for enc, frames in ((ENC_LVDS_UP, up), (ENC_LVDS_WORD, words.reshape(-1, 1)),
                        (ENC_SENSOR_RAW, raw)):
        cols = D.decode_block(enc, frames)
        assert cols is not None
        for i in range(frames.shape[0]):
            single = D.decode(enc, frames[i].astype(frames.dtype.newbyteorder("<")).tobytes())
            assert single == {k: int(v[i]) for k, v in cols.items()}, enc


def test_log_protocol_frames_and_decode(tmp_path: Path) -> None:
    """The chain the issue asks for: protocol encoders -> log -> reader -> decoders."""
    path = tmp_path / "proto.mcap"
    frame = ethercat.encode_frame(_datagrams())
    with FrameLogWriter(path, level="mcu") as w:
        bus = w.add_channel("/fieldbus/frames", ENC_ETHERCAT, schema_name="")
        words = w.add_block_channel("/lvds/0/down/words", ENC_LVDS_WORD, dtype=np.uint64,
                                    width=1)
        down = w.add_block_channel("/lvds/0/down", ENC_LVDS_DOWN, dtype=np.uint8, width=3)
        w.write(bus, 1000, frame)
        line = np.array([lvds.encode_word(D_IQ_REF, 0x8000), lvds.encode_word(D_SEQUENCE, 9)],
                        dtype=np.uint64)
        w.write_block(words, np.array([4500, 9000]), line)
        w.write_block(down, np.array([9000, 9000]), np.frombuffer(
            D.encode_lvds_down([(D_IQ_REF, 0x8000), (D_SEQUENCE, 9)]), np.uint8).reshape(2, 3))
    r = FrameLogReader(path)
    enc = {c.topic: c.encoding for c in r.info().channels}
    out = [(topic, t, D.decode(enc[topic], data)) for topic, t, data in r.frames()]
    assert out[0] == ("/fieldbus/frames", 1000, D.decode(ENC_ETHERCAT, frame))
    assert out[1] == ("/lvds/0/down/words", 4500,
                      {"addr": D_IQ_REF, "data": 0x8000, "frame_ok": 1, "crc_ok": 1})
    assert out[2][2]["addr"] == D_SEQUENCE and out[2][2]["data"] == 9
    assert {k: v for _, t, d in out[3:] for k, v in d.items()} == {"iq_ref": -32768,
                                                                   "sequence": 9}
