"""Live view: the decoded-signal channels streamed to Foxglove Studio (``--foxglove``).

The official ``foxglove-sdk`` runs the WebSocket server (protocol ``foxglove.websocket.v1``)
in its own threads; we give it one channel per decoded-signal topic with the same protobuf
schema and the same message bytes as the log (:class:`hil.replay.signal_out.SignalOut` encodes
once for both). Log times are the samples' simulated times. Each live view has its own SDK
context, so two in one process do not share channels.
"""

from __future__ import annotations

import numpy as np

from hil.framelog.protobuf import SCHEMA_ENCODING, MessageType

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


class LiveError(Exception):
    """The server cannot start (address in use, bad host); one line."""


def parse_address(text: str | None) -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT``, ``HOST`` or None -> (host, port); loopback by default.
    ValueError with one line for anything else."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = text, str(DEFAULT_PORT)
    host = host.strip("[]") or DEFAULT_HOST
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"--foxglove {text!r}: the port must be a number (HOST:PORT)") \
            from None
    if not 0 <= p <= 65535:
        raise ValueError(f"--foxglove {text!r}: port {p} is not in 0..65535")
    return host, p


class FoxgloveLive:
    """A Foxglove WebSocket server with one channel per :meth:`add`; port 0: any free one
    (:attr:`port` says which)."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 name: str = "eha-hil") -> None:
        import foxglove

        self._foxglove = foxglove
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port,
                                                context=self.context)
        except Exception as exc:  # noqa: BLE001 - the SDK raises its own error types
            raise LiveError(f"--foxglove {host}:{port}: cannot start the server "
                            f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
                            ) from None
        self.host = host
        self.port = self.server.port
        self._channels: list = []

    def add(self, topic: str, message: MessageType) -> int:
        fg = self._foxglove
        ch = fg.Channel(topic, schema=fg.Schema(name=message.full_name,
                                                encoding=SCHEMA_ENCODING,
                                                data=message.schema),
                        message_encoding="protobuf", context=self.context,
                        metadata={"eha-hil.units": _units_json(message)})
        self._channels.append(ch)
        return len(self._channels) - 1

    def log(self, handle: int, t_ns: np.ndarray, payloads: list[bytes]) -> None:
        ch = self._channels[handle]
        if not ch.has_sinks():  # nobody subscribed: nothing to send
            return
        for t, data in zip(t_ns.tolist(), payloads, strict=True):
            ch.log(data, log_time=t)

    def subscribed(self, topic: str) -> bool:
        """True if a client is subscribed to ``topic``."""
        return any(ch.topic() == topic and ch.has_sinks() for ch in self._channels)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def close(self) -> None:
        for ch in self._channels:
            ch.close()
        self.server.stop()

    def __enter__(self) -> FoxgloveLive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _units_json(message: MessageType) -> str:
    import json

    return json.dumps(message.units(), sort_keys=True)
