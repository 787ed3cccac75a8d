"""In-process transport: two ends sharing two ``collections.deque`` (one per direction).

Deterministic and the fastest backend: a frame is appended to the peer's deque and popped
by the peer, with no copy beyond ``bytes()`` (none at all when the frame already is
``bytes``), no framing and no loss. It is what the simulator uses when the master and the
slaves run in one process, and the reference the other backends are compared with.

Ends find each other either through :func:`~hil.transports.transport_pair` or, like
python-can's virtual bus, by opening the same ``channel`` name once as master and once as
slave. Blocking waits (``recv`` with a timeout on an empty deque) use a condition variable,
so an end can be served by another thread; the single-threaded fast path takes no lock
(``deque.append``/``popleft`` are atomic in CPython).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

from hil.transports.base import (
    DEFAULT_MAX_FRAME,
    Transport,
    TransportError,
    deadline_of,
    remaining,
)


class _Direction:
    """One direction of a link: the frames in flight and a way to wait for one."""

    __slots__ = ("frames", "cond", "waiting", "closed")

    def __init__(self) -> None:
        self.frames: deque[bytes] = deque()
        self.cond = threading.Condition(threading.Lock())
        #: True while a receiver sleeps in cond.wait; lets the sender skip the lock otherwise
        self.waiting = False
        #: True once the receiving end is closed: frames sent to it are dropped
        self.closed = False

    def put(self, frame: bytes) -> None:
        if self.closed:
            return
        self.frames.append(frame)
        # The receiver sets `waiting` under the lock *before* it looks at the deque, so if
        # we read False here it will see our frame when it looks.
        if self.waiting:
            with self.cond:
                self.cond.notify_all()

    def get(self, timeout: float | None) -> bytes | None:
        frames = self.frames
        if frames:
            return frames.popleft()
        if timeout == 0:
            return None
        deadline = deadline_of(timeout)
        with self.cond:
            self.waiting = True
            try:
                while not frames:
                    left = remaining(deadline)
                    if left == 0.0:
                        return None
                    self.cond.wait(left)
                return frames.popleft()
            finally:
                self.waiting = False


class _Link:
    """The two directions between one master end and one slave end."""

    def __init__(self) -> None:
        self.to_slave = _Direction()
        self.to_master = _Direction()
        self.ends: dict[str, InprocTransport] = {}


#: Named links for ends opened separately with ``channel=``; a link is removed when both
#: of its ends are closed.
_channels: dict[str, _Link] = {}
_channels_lock = threading.Lock()


class InprocTransport(Transport):
    """One end of an in-process link.

    Options:
        channel: name of the link; a master and a slave opened with the same name are
            connected (default ``"default"``). Each channel holds one master and one slave.
        max_frame: largest frame [bytes] (default 4096).

    Frames sent to an end that has been closed are dropped, as on a wire.
    """

    name = "inproc"
    in_memory = True

    def __init__(self, role: str, channel: str = "default",
                 max_frame: int = DEFAULT_MAX_FRAME) -> None:
        super().__init__(role, max_frame)
        if not isinstance(channel, str) or not channel:
            raise TransportError(f"inproc: channel must be a non-empty string, got {channel!r}")
        self.channel = channel
        with _channels_lock:
            link = _channels.setdefault(channel, _Link())
            if role in link.ends:
                raise TransportError(
                    f"inproc: channel {channel!r} already has a {role}; close it first or "
                    "use another channel name"
                )
            link.ends[role] = self
        self._attach(link)

    def _attach(self, link: _Link) -> None:
        self._link = link
        if self.role == "master":
            self._out, self._in = link.to_slave, link.to_master
        else:
            self._out, self._in = link.to_master, link.to_slave

    def _send(self, frame: bytes) -> None:
        self._out.put(frame)

    def _recv(self, timeout: float | None) -> bytes | None:
        return self._in.get(timeout)

    def _close(self) -> None:
        with _channels_lock:
            link = self._link
            if link.ends.get(self.role) is self:
                del link.ends[self.role]
            if not link.ends and _channels.get(self.channel) is link:
                del _channels[self.channel]
            # A closed end receives nothing more: forget what was in flight to it.
            self._in.closed = True
            self._in.frames.clear()

    @classmethod
    def _pair(cls, max_frame: int = DEFAULT_MAX_FRAME) -> tuple[Transport, Transport]:
        """A private link (not registered under any channel name)."""
        link = _Link()
        master = cls.__new__(cls)
        slave = cls.__new__(cls)
        for end, role in ((master, "master"), (slave, "slave")):
            Transport.__init__(end, role, max_frame)
            end.channel = ""
            link.ends[role] = end
            end._attach(link)
        return master, slave

    def pending(self) -> int:
        """Frames that have arrived at this end and not yet been received."""
        return len(self._in.frames)

    def __getstate__(self) -> Any:  # pragma: no cover - guard
        raise TransportError("inproc: an in-process transport cannot be pickled or shared "
                             "between processes; use udp")
