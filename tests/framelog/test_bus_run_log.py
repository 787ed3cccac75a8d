"""A real ``eha-hil bus run --log`` file, read with what we did not write: the mcap library's
reader, its protobuf decoder factory, pandas; and docs/framelog.md compared with it."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from firmware_model.mcu.measure import Measurements
from plant.config import load_config

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "framelog.md").read_text()
#: Schema encodings Foxglove Studio decodes (its documentation's list for MCAP).
FOXGLOVE_SCHEMA_ENCODINGS = {"protobuf", "jsonschema", "ros1msg", "ros2msg", "ros2idl",
                             "omgidl", "flatbuffer"}


def _cli(*argv: str) -> tuple[int, str]:
    """``eha-hil ARGV`` in this process: (exit code, stdout)."""
    from hil.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    assert code == 0, err.getvalue()
    return code, out.getvalue()


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    """Level -> (log, the run's --json report): a 0.3 s run at mcu, 0.02 s at full."""
    d = tmp_path_factory.mktemp("bus_run_log")
    out = {}
    for level, seconds in (("mcu", "0.3"), ("full", "0.02")):
        path = d / f"{level}.mcap"
        _, stdout = _cli("bus", "run", "--seconds", seconds, "--log", str(path), "--level",
                         level, "--json")
        out[level] = (path, json.loads(stdout))
    return out


def _doc_topics() -> list[dict[str, str]]:
    """The rows of the table under "What `eha-hil bus run --log` writes"."""
    sec = DOC.split("## What `eha-hil bus run --log` writes", 1)[1].split("\n### ", 1)[0]
    lines = [ln for ln in sec.splitlines() if ln.startswith("|")]
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    rows = []
    for ln in lines[2:]:
        cells = [c.strip().strip("`") for c in ln.strip("|").split("|")]
        rows.append(dict(zip(head, cells, strict=True)))
    return rows


def _pattern(topic: str) -> re.Pattern:
    return re.compile("^" + re.escape(topic).replace("<b>", r"\d+").replace("<k>", r"\d+")
                      + "$")


def _doc_fields() -> dict[str, list[tuple[str, str]]]:
    """Message name -> [(field, unit)] from the tables of "Decoded signals (protobuf)"."""
    sec = DOC.split("### Decoded signals (protobuf)", 1)[1].split("### Byte layouts", 1)[0]
    out: dict[str, list[tuple[str, str]]] = {}
    for block in sec.split("\n### ")[1:]:
        name = block.splitlines()[0].strip()
        rows = [ln for ln in block.splitlines() if ln.startswith("| ") and "`" in ln]
        out[name] = [(c[1].strip().strip("`"), c[3].strip()) for c in
                     (ln.strip("|").split("|") for ln in rows)]
    return out


def _channels(path: Path):
    with open(path, "rb") as f:
        summary = make_reader(f, validate_crcs=True).get_summary()
    return summary


def test_every_decoded_message_decodes_with_the_stock_decoder(logs):
    path, _ = logs["mcu"]
    summary = _channels(path)
    counts = summary.statistics.channel_message_counts
    proto = {cid: ch for cid, ch in summary.channels.items()
             if summary.schemas[ch.schema_id].encoding == "protobuf"}
    assert {ch.topic for ch in proto.values()} >= {
        "/signals/actuator/0.0", "/signals/box/0/outputs", "/signals/box/0/inputs",
        "/signals/bus"}
    seen: dict[int, int] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        for _schema, ch, _msg, dec in reader.iter_decoded_messages(
                topics=[c.topic for c in proto.values()]):
            assert dec.DESCRIPTOR.full_name == summary.schemas[ch.schema_id].name
            seen[ch.id] = seen.get(ch.id, 0) + 1
    assert seen == {cid: counts[cid] for cid in proto} and all(seen.values())


def _decoded(path: Path, topic: str) -> list[tuple[int, object]]:
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=[topic])]


def _raw_blocks(path: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    from hil.framelog import FrameLogReader

    return FrameLogReader(path).blocks(topic)


def test_actuator_values_are_what_the_mcu_decodes(logs):
    """The decoded actuator channel against the MCU's own float32 decoding of the raw
    upstream words logged beside it (firmware_model.mcu.measure, not our export code)."""
    path, _ = logs["mcu"]
    t_up, up = _raw_blocks(path, "/lvds/0.0/up")
    rows = {int(t): r for t, r in zip(t_up, up, strict=True)}
    meas = Measurements(calibration(load_config(None)))
    msgs = _decoded(path, "/signals/actuator/0.0")
    # one per fieldbus cycle at level mcu: the cycle's last MCU step (the fifth, 0.8 ms in)
    assert len(msgs) == len(t_up) // 5 >= 299
    assert all(t % 1_000_000 == 800_000 for t, _ in msgs)
    checked = 0
    for t, d in msgs:
        meas.update(rows[t][:B.UP_WORDS])
        for mine, theirs, tol in ((d.p_cyl_a_pa, meas.p_cyl_a, 1.0), (d.iq_a, meas.iq, 1e-6),
                                  (d.f_strain_n, meas.f_strain_raw, 1e-3),
                                  (d.x_piston_m, meas.x_piston, 1e-9),
                                  (d.omega_m_rad_s, meas.omega_m, 1e-3),
                                  (d.temperature_c, meas.temperature_c, 1e-3)):
            assert math.isclose(mine, float(theirs), rel_tol=1e-6, abs_tol=tol)
        assert d.status == rows[t][B.U_STATUS] and d.link_ok == bool(
            rows[t][B.U_STATUS] & B.ST_LINK_OK)
        checked += 1
    assert checked == len(msgs) and msgs[-1][1].enabled
    # the command it worked to is the box's outputs channel's: the demo sine (300 N, 2 Hz)
    # as the PC sent it, in force mode
    outs = _decoded(path, "/signals/box/0/outputs")
    assert outs[-1][1].s0_mode == 1
    forces = np.array([d.s0_force_command_n for _, d in outs])
    assert 200 < np.nanmax(np.abs(forces)) <= 300


def test_bus_channel_matches_the_masters_report(logs):
    path, report = logs["mcu"]
    msgs = _decoded(path, "/signals/bus")
    assert [d.cycle for _, d in msgs] == list(range(300))
    last = msgs[-1][1]
    for name, value in report["master"].items():
        if hasattr(last, name):
            assert getattr(last, name) == value, name
    assert all(d.wkc == d.wkc_expected > 0 for _, d in msgs)


def test_schemas_are_foxglove_encodings_and_raw_ones_documented(logs):
    doc = _doc_topics()
    for level in ("mcu", "full"):
        summary = _channels(logs[level][0])
        for ch in summary.channels.values():
            enc = summary.schemas[ch.schema_id].encoding if ch.schema_id else ""
            rows = [r for r in doc if _pattern(r["topic"]).match(ch.topic)]
            assert len(rows) == 1, ch.topic
            assert enc in FOXGLOVE_SCHEMA_ENCODINGS and ch.message_encoding == enc, ch.topic
            raw = ch.metadata.get("eha-hil.container") == "protobuf"
            assert rows[0]["viewer"] == ("raw" if raw else "decoded"), ch.topic


def test_doc_topic_table_matches_real_logs(logs):
    doc = _doc_topics()
    for level in ("mcu", "full"):
        summary = _channels(logs[level][0])
        matched = set()
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            row = next(r for r in doc if _pattern(r["topic"]).match(ch.topic))
            assert (ch.message_encoding, ch.metadata.get("eha-hil.frame_encoding"),
                    schema.encoding) == (row["message encoding"], row["frame encoding"],
                                         row["schema encoding"]), ch.topic
            assert level in row["levels"], ch.topic
            matched.add(row["topic"])
        wanted = {r["topic"] for r in doc if level in r["levels"]}
        assert matched == wanted, level


def test_doc_field_tables_match_the_code():
    from hil.fieldbus.topology import load_topology
    from hil.framelog.protobuf import markdown_table
    from hil.replay import signals as SG

    box = load_topology("bench_one_box").boxes[0]
    messages = [SG.ACTUATOR, SG.BUS, SG.record_message(box, "outputs"),
                SG.record_message(box, "inputs")]
    for m in messages:
        assert f"### {m.full_name}\n\n{markdown_table(m)}\n" in DOC, m.full_name


@pytest.fixture(scope="module")
def exported(logs, tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("export")
    out = {}
    for suffix in ("csv", "parquet"):
        out[suffix] = d / f"run.{suffix}"
        _cli("log", "export", str(logs["mcu"][0]), str(out[suffix]))
    return out


def test_csv_export_has_a_numeric_column_for_every_documented_field(logs, exported):
    topic_of = {"eha_hil.ActuatorSignals": "/signals/actuator/0.0",
                "eha_hil.BusCycle": "/signals/bus",
                "eha_hil.BoxOutputs_actuator": "/signals/box/0/outputs",
                "eha_hil.BoxInputs_actuator": "/signals/box/0/inputs"}
    with open(exported["csv"], newline="") as f:
        rows = list(csv.DictReader(f))
    fields = _doc_fields()
    assert set(fields) == set(topic_of)
    # the default configuration has no rod temperature sensor: its field is left out
    from hil.replay import signals as SG

    unfitted = {f.name for f in SG.ACTUATOR.fields} - {
        f.name for f in SG.actuator_message(SG.unfitted_inputs(load_config(None).get(
            "sensors"))).fields}
    assert unfitted == {"rod_temperature_c"}
    for message, cols in fields.items():
        mine = [r for r in rows if r["topic"] == topic_of[message]]
        assert mine, message
        for name, unit in cols:
            head = f"{name} [{unit}]" if unit != "-" else name
            if message == "eha_hil.ActuatorSignals" and name in unfitted:
                assert head not in mine[0] and name not in mine[0], head
                continue
            values = [r[head] for r in mine]
            assert all(v != "" for v in values), head
            nums = [float(v) for v in values]  # every one a number
            if name not in ("position_command_m", "s0_position_command_m"):
                assert not all(math.isnan(v) for v in nums), head
    # raw channels are decoded too: registers by name, the fieldbus frames' datagrams
    up = [r for r in rows if r["topic"] == "/lvds/0.0/up"]
    assert up and all(r["iq"] != "" and r["up_crc_errors"] != "" for r in up)
    bus = [r for r in rows if r["topic"] == "/fieldbus/frames"]
    assert bus and all(r["fcs_ok"] == "1" and r["dg0.wkc"] != "" for r in bus)


def test_parquet_export_loads_with_pandas(exported):
    df = pd.read_parquet(exported["parquet"])
    with open(exported["csv"], newline="") as f:
        n_csv = sum(1 for _ in f) - 1
    assert len(df) == n_csv and list(df.columns[:3]) == ["t_ns", "t_s", "topic"]
    act = df[df["topic"] == "/signals/actuator/0.0"]
    # the schema's types: a word-sized float field float32, the piston's two words float64
    assert act["p_cyl_a_pa"].notna().all() and act["p_cyl_a_pa"].dtype == np.float32
    assert act["x_piston_m"].dtype == np.float64
    assert (act["t_ns"].diff().dropna() == 1_000_000).all()
    schema = pq.read_schema(exported["parquet"])
    unit = {f.name: (f.metadata or {}).get(b"unit", b"").decode() for f in schema}
    assert unit["p_cyl_a_pa"] == "Pa" and unit["f_strain_n"] == "N" and unit["t_ns"] == "ns"
    assert unit["status"] == ""


def test_two_boards_each_decoded_from_its_own_words(tmp_path) -> None:  # noqa: ANN001
    """A box with two actuators: each actuator channel holds its own board's values."""
    from hil.fieldbus.topology import load_topology
    from hil.framelog import FrameLogReader
    from hil.replay.record import run_logged
    from hil.sim.pc import demo_pc

    topo_file = tmp_path / "two.toml"
    topo_file.write_text('[[box]]\nid = 0\nslots = ["a", "b"]\n')
    log = tmp_path / "two.mcap"
    run_logged(load_topology(str(topo_file)), load_config(None), 60, demo_pc(400.0, 20.0),
               log)
    reader = FrameLogReader(log)
    iq = {}
    for k in (0, 1):
        t, up = reader.blocks(f"/lvds/0.{k}/up")
        rows = dict(zip(t.tolist(), up, strict=True))
        msgs = _decoded(log, f"/signals/actuator/0.{k}")
        assert len(msgs) >= 59
        for tt, d in msgs:
            # a float field: the float32 nearest the word's value, exactly
            assert d.iq_a == float(np.float32(int(np.int16(rows[tt][B.U_IQ])) * 1e-3))
        iq[k] = [d.iq_a for _, d in msgs]
    assert iq[0] != iq[1]  # the demo sine is phase-shifted per actuator
