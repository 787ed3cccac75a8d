"""Where a run's decoded signals go: the log's protobuf channels and/or a live view."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hil.framelog import FrameLogWriter
from hil.framelog.protobuf import MessageType


class SignalOut:
    """Where the decoded signals go: the log's protobuf channels and/or a live view (an
    object with ``add(topic, message)`` -> handle and ``log(handle, t_ns, payloads)``, e.g.
    :class:`hil.framelog.live.FoxgloveLive`). Each block of samples is encoded once for both."""

    def __init__(self, log: FrameLogWriter | None, live: object = None) -> None:
        self.log = log
        self.live = live
        self._channels: list[tuple[MessageType, int | None, object]] = []

    def add(self, topic: str, message: MessageType) -> int:
        cid = None if self.log is None else self.log.add_protobuf_channel(topic, message)
        handle = None if self.live is None else self.live.add(topic, message)
        self._channels.append((message, cid, handle))
        return len(self._channels) - 1

    def message(self, channel: int) -> MessageType:
        """The message type of ``channel``."""
        return self._channels[channel][0]

    def write(self, channel: int, t_ns: np.ndarray, columns: dict[str, np.ndarray]) -> None:
        message, cid, handle = self._channels[channel]
        n = len(t_ns)
        if not n:
            return
        payloads = message.encode_array(columns, n)  # (n, size): no bytes object each
        if cid is not None:
            self.log.write_messages(cid, t_ns, payloads)
        if handle is not None:
            self.live.log(handle, t_ns, [bytes(m) for m in payloads])

    def write_split(self, channels: list[int], t_ns: np.ndarray,
                    columns: dict[str, np.ndarray]) -> None:
        """The same ``k`` times ``t_ns`` on each of ``channels`` (all of one message type):
        ``columns`` hold ``len(channels) * k`` samples, channel-major; encoded in one go."""
        if not channels:
            return
        k = len(t_ns)
        if not k:
            return
        message = self._channels[channels[0]][0]
        self.write_filled(channels, t_ns, message.size,
                          lambda out: message.encode_into(columns, out))

    def write_filled(self, channels: list[int], t_ns: np.ndarray, size: int,
                     fill: Callable[[np.ndarray], None]) -> None:
        """:meth:`write_encoded` of the messages ``fill(out)`` encodes into ``out``
        ((``len(channels) * k``, ``size``) uint8, channel-major, rows of any stride): into
        their records in the log's chunk when only the log takes them
        (:meth:`~hil.framelog.writer.FrameLogWriter.write_messages_filled`: no copy)."""
        k = len(t_ns)
        if not channels or not k:
            return
        if self.log is not None and all(self._channels[c][2] is None for c in channels):
            c_n = len(channels)
            self.log.write_messages_filled([self._channels[c][1] for c in channels], t_ns,
                                           size, lambda out: fill(out.reshape(c_n * k, size)))
            return
        payloads = np.empty((len(channels) * k, size), np.uint8)
        fill(payloads)
        self.write_encoded(channels, t_ns, payloads)

    def write_encoded(self, channels: list[int], t_ns: np.ndarray,
                      payloads: np.ndarray) -> None:
        """:meth:`write_split` of messages already encoded: ``payloads``
        (``len(channels) * k``, size) uint8, channel-major."""
        k = len(t_ns)
        if not channels or not k:
            return
        if self.log is not None:  # one record array for all channels
            self.log.write_messages_many([self._channels[c][1] for c in channels], t_ns,
                                         payloads.reshape(len(channels), k, -1))
        for j, channel in enumerate(channels):
            handle = self._channels[channel][2]
            if handle is not None:
                self.live.log(handle, t_ns, [bytes(m) for m in payloads[j * k:(j + 1) * k]])
