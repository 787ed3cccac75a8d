"""``eha-hil run NAME --series FILE``: a scenario's series out to CSV, Parquet and MCAP, read
back with pandas, pyarrow and the mcap library's protobuf decoder."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from hil.framelog.series_export import tables, unit_of, write_series
from hil.scenarios import Metric, ScenarioResult


@dataclass
class _Point:
    force_n: float
    velocity_m_s: float
    label: str = "x"


def _result() -> ScenarioResult:
    t = np.linspace(0.0, 0.01, 11)
    f = np.array([1.0, 10.0, 100.0])
    h = np.array([1.0 + 0j, 1j, -0.1 + 0j])
    series = {"t_s": t, "iq_a": np.sin(t * 100), "target_a": 10.0,
              "bode": {"freq_hz": f, "h": h},
              "curve": [_Point(1700.0, 0.0), _Point(0.0, 0.15)],
              "bodes": [("current based", f, h)]}
    return ScenarioResult("demo", "a demo", [Metric("peak", 60.0, "Hz")], series)


def test_tables_flatten_every_shape() -> None:
    tabs, scalars = tables(_result().series, "demo")
    by = {t.name: t for t in tabs}
    assert scalars == {"target_a": 10.0}
    assert set(by["demo"].columns) == {"t_s", "iq_a"} and by["demo"].rows == 11
    bode = by["bode"].columns
    assert set(bode) == {"bode.freq_hz", "bode.h.gain_db", "bode.h.phase_deg"}
    assert bode["bode.h.gain_db"] == pytest.approx([0.0, 0.0, -20.0])
    assert bode["bode.h.phase_deg"] == pytest.approx([0.0, 90.0, 180.0])
    assert list(by["curve"].columns["curve.force_n"]) == [1700.0, 0.0]
    assert "bodes" in by and by["bodes"].rows == 3
    assert (unit_of("bode.freq_hz"), unit_of("curve.velocity_m_s"), unit_of("t"),
            unit_of("t_c"), unit_of("efficiency")) == ("Hz", "m/s", "s", "", "")


def test_csv_parquet_mcap_read_back(tmp_path: Path) -> None:
    res = _result()
    n = write_series(res, tmp_path / "s.csv")
    df = pd.read_csv(tmp_path / "s.csv", comment="#")
    assert len(df) == n == 11 + 3 + 2 + 3
    demo = df[df["table"] == "demo"]
    assert demo["iq_a [A]"].to_numpy() == pytest.approx(res.series["iq_a"])
    head = (tmp_path / "s.csv").read_text().splitlines()
    assert "# metric peak: 60 Hz" in head and "# target_a: 10" in head

    write_series(res, tmp_path / "s.parquet")
    pdf = pd.read_parquet(tmp_path / "s.parquet")
    assert pdf[pdf["table"] == "demo"]["t_s"].to_numpy() == pytest.approx(res.series["t_s"])
    schema = pq.read_schema(tmp_path / "s.parquet")
    assert schema.field("bode.freq_hz").metadata[b"unit"] == b"Hz"
    assert schema.metadata[b"eha-hil.scenario"] == b"demo"

    write_series(res, tmp_path / "s.mcap")
    with open(tmp_path / "s.mcap", "rb") as f:
        msgs = [(c.topic, m.log_time, d) for _, c, m, d in make_reader(
            f, validate_crcs=True, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    demo_msgs = [(t, d) for topic, t, d in msgs if topic == "/series/demo"]
    assert [t for t, _ in demo_msgs] == [round(x * 1e9) for x in res.series["t_s"]]
    assert [d.iq_a for _, d in demo_msgs] == pytest.approx(res.series["iq_a"])
    assert {topic for topic, _, _ in msgs} == {"/series/demo", "/series/bode",
                                               "/series/curve", "/series/bodes"}


def test_bad_output_and_empty_series(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="csv, .parquet or .mcap"):
        write_series(_result(), tmp_path / "s.txt")
    with pytest.raises(ValueError, match="no time series"):
        write_series(ScenarioResult("x", "x", [], {"a": "text"}), tmp_path / "s.csv")


def test_cli_current_step_series(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    from hil.cli import main

    out = tmp_path / "step.parquet"
    assert main(["run", "current-step", "--series", str(out)]) == 0
    df = pd.read_parquet(out)
    assert {"t_s", "iq_a", "id_a"} <= set(df.columns)
    # the step's target current is reached: what the metrics were computed from
    assert df["iq_a"].iloc[-50:].mean() == pytest.approx(10.0, abs=0.3)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # argparse's usage error
        main(["run", "current-step", "--series", str(tmp_path / "x.txt")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--series" in err[0]


@pytest.mark.slow
def test_series_live_to_a_websocket_client() -> None:
    """``run --foxglove``: a client subscribes, gets every row, decodes it with the schema
    the server advertised."""
    import asyncio
    import base64
    import json
    import struct
    import threading

    import websockets
    from mcap.records import Schema

    from hil.framelog.live import FoxgloveLive
    from hil.framelog.series_export import publish_live

    res = _result()
    got: list = []

    async def client(url: str) -> None:
        async with websockets.connect(url, subprotocols=["foxglove.sdk.v1",
                                                         "foxglove.websocket.v1"]) as ws:
            channel = None
            while channel is None:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 30))
                if msg.get("op") == "advertise":
                    channel = next((c for c in msg["channels"]
                                    if c["topic"] == "/series/demo"), None)
            got.append(channel)
            sub = json.dumps({"op": "subscribe",
                              "subscriptions": [{"id": 1, "channelId": channel["id"]}]})
            await ws.send(sub)
            while len(got) < 1 + 11:
                data = await asyncio.wait_for(ws.recv(), 30)
                if isinstance(data, str):  # "unknown channel": subscribed too early
                    if json.loads(data).get("op") == "status":
                        await asyncio.sleep(0.1)
                        await ws.send(sub)
                elif data[0] == 1:
                    got.append((struct.unpack_from("<IQ", data, 1)[1], data[13:]))

    with FoxgloveLive(port=0) as live:
        th = threading.Thread(target=lambda: asyncio.run(client(live.url)))
        th.start()
        assert publish_live(res, live, wait_s=30, linger_s=0.5)
        th.join(30)
    channel, rows = got[0], got[1:]
    decode = DecoderFactory().decoder_for("protobuf", Schema(
        id=1, name=channel["schemaName"], encoding="protobuf",
        data=base64.b64decode(channel["schema"])))
    assert [t for t, _ in rows] == [round(x * 1e9) for x in res.series["t_s"]]
    assert [decode(d).iq_a for _, d in rows] == pytest.approx(res.series["iq_a"])
