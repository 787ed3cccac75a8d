"""The live view: a plain WebSocket client (``websockets``) speaking Foxglove's protocol
subscribes to a decoded channel of a run and gets the messages the log holds."""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

from hil.fieldbus.topology import load_topology
from hil.framelog.live import FoxgloveLive, parse_address
from hil.replay.record import run_logged
from hil.sim.pc import demo_pc
from plant.config import load_config

#: The SDK's server speaks foxglove.sdk.v1 (the protocol's current name); offer both.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
TOPIC = "/signals/actuator/0.0"
CYCLES = 60


def _client(url: str, got: list, errors: list, done: threading.Event) -> None:
    """Subscribe to TOPIC and keep what arrives until CYCLES - 1 messages came or the run is
    over (``done``) and nothing more came for a second: no deadline on the run itself, which
    takes what the machine's load makes it take."""
    import websockets

    async def run() -> None:
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS) as ws:
            channel = None
            while channel is None:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 30))
                if msg.get("op") == "advertise":
                    channel = next((c for c in msg["channels"] if c["topic"] == TOPIC), None)
            got.append(("channel", channel))
            subscribe = json.dumps({"op": "subscribe",
                                    "subscriptions": [{"id": 3, "channelId": channel["id"]}]})
            await ws.send(subscribe)
            quiet = 0
            while True:
                try:
                    data = await asyncio.wait_for(ws.recv(), 1)
                    quiet = 0
                except TimeoutError:
                    quiet = quiet + 1 if done.is_set() else 0
                    if quiet >= 2:
                        return
                    continue
                if isinstance(data, str):
                    # the server may get the subscription before it can serve the channel it
                    # just advertised ("unknown channel"): ask again
                    if json.loads(data).get("op") == "status":
                        await asyncio.sleep(0.1)
                        await ws.send(subscribe)
                elif data[0] == 1:  # message data
                    sub, t = struct.unpack_from("<IQ", data, 1)
                    got.append((sub, t, data[13:]))
                    if len([g for g in got if g[0] == 3]) >= CYCLES - 1:
                        return

    try:
        asyncio.run(run())
    except Exception as exc:  # noqa: BLE001 - reported by the test
        errors.append(exc)


def test_live_messages_decode_to_the_logged_values(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    got: list = []
    errors: list = []
    sine = demo_pc()

    def pc(cycle, m):  # noqa: ANN001
        if cycle == 1:  # the channels exist (advertised) once the run has started
            for _ in range(300):  # wait (30 s at most) until the client has subscribed
                if live.subscribed(TOPIC) or errors:
                    break
                time.sleep(0.1)
        sine(cycle, m)

    done = threading.Event()
    with FoxgloveLive(port=0) as live:
        th = threading.Thread(target=_client, args=(live.url, got, errors, done))
        th.start()
        # the first block of signals goes out at the first flush (every 100 cycles) or at
        # the end of the run: the client is subscribed long before
        try:
            run_logged(load_topology("bench_one_box"), load_config(None), CYCLES, pc, log,
                       live=live)
        finally:
            done.set()
        th.join(60)
    assert not errors, errors
    channel = got[0][1]
    assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
    decode = DecoderFactory().decoder_for("protobuf", Schema(
        id=1, name=channel["schemaName"], encoding="protobuf",
        data=base64.b64decode(channel["schema"])))
    live_msgs = {t: (data, decode(data)) for sub, t, data in got[1:]}
    with open(log, "rb") as f:
        logged = {m.log_time: (m.data, d) for _, _, m, d in make_reader(
            f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[TOPIC])}
    assert len(live_msgs) >= CYCLES - 1 and set(live_msgs) == set(logged)
    for t, (data, d) in logged.items():
        assert live_msgs[t][0] == data  # the very bytes the log holds
        mine = live_msgs[t][1]
        for fd in d.DESCRIPTOR.fields:  # and what the stock decoder makes of them
            a, b = getattr(mine, fd.name), getattr(d, fd.name)
            assert a == b or (a != a and b != b), fd.name


@pytest.mark.parametrize(("text", "want"), [(None, ("127.0.0.1", 8765)),
                                            ("", ("127.0.0.1", 8765)),
                                            (":9000", ("127.0.0.1", 9000)),
                                            ("0.0.0.0:1", ("0.0.0.0", 1)),
                                            ("localhost", ("localhost", 8765))])
def test_parse_address(text, want) -> None:  # noqa: ANN001
    assert parse_address(text) == want


@pytest.mark.parametrize("text", ["h:x", "h:70000", "h:-1"])
def test_parse_address_rejects(text) -> None:  # noqa: ANN001
    with pytest.raises(ValueError, match="--foxglove"):
        parse_address(text)


class _Collect:
    """A stand-in live view: keeps what it is given."""

    def __init__(self) -> None:
        self.channels: list = []
        self.messages: list = []

    def add(self, topic, message):  # noqa: ANN001, ANN201
        self.channels.append((topic, message))
        return len(self.channels) - 1

    def log(self, handle, t_ns, payloads):  # noqa: ANN001, ANN201
        self.messages += [(self.channels[handle][0], t, p)
                          for t, p in zip(t_ns.tolist(), payloads, strict=True)]


def test_serve_chain_sends_decoded_signals() -> None:
    """What ``serve --foxglove`` wires: the paced chain's stack boxes send their signals."""
    from hil.fieldbus.chain import Chain
    from hil.fieldbus.master import Master
    from hil.replay.record import signal_boxes

    topo = load_topology("bench_one_box")
    cfg = load_config(None)
    chain = Chain(topo, cfg, "stack", paced=True)
    live = _Collect()
    boxes = signal_boxes(chain, cfg, live)
    assert len(boxes) == 1 and {t for t, _ in live.channels} == {
        "/signals/box/0/outputs", "/signals/box/0/inputs", "/signals/actuator/0.0"}
    master = Master(topo)
    for _ in range(150):
        master.set_actuator(0, "force", 100.0)
        for f in master.frames():
            master.receive(chain.handle(f))
        master.end_cycle()
        chain.advance()
    for b in boxes:
        b.flush()
    act = [(t, p) for topic, t, p in live.messages if topic == "/signals/actuator/0.0"]
    assert len(act) == 150
    out = [(t, p) for topic, t, p in live.messages if topic == "/signals/box/0/outputs"]

    def last(topic, msgs):  # noqa: ANN001, ANN202
        message = dict(live.channels)[topic]
        decode = DecoderFactory().decoder_for("protobuf", Schema(
            id=1, name=message.full_name, encoding="protobuf", data=message.schema))
        return decode(msgs[-1][1])

    assert last("/signals/actuator/0.0", act).enabled
    assert last("/signals/box/0/outputs", out).s0_force_command_n == pytest.approx(100.0)


def test_serve_foxglove_bad_address_is_one_line(capsys) -> None:  # noqa: ANN001
    from hil.cli import main

    assert main(["serve", "--transport", "udp", "--port", "0", "--seconds", "0.01",
                 "--foxglove", "host:port"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--foxglove" in err[0] and "Traceback" not in err[0]
