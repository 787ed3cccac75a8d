"""CAN traffic logs in python-can's file formats: BLF (Vector), ASC (Vector text) and
candump ``.log`` (Linux can-utils).

:class:`CanLogRecorder` is a listener on the bus, like a CAN logger plugged into the
cable: it opens its own python-can bus on the transport's interface and channel (the
``virtual`` interface and SocketCAN both deliver every frame to every other bus object on
the channel), and writes each message it hears with ``can.Logger``, which picks
``BLFWriter``, ``ASCWriter`` or ``CanutilsLogWriter`` from the file name. Timestamps are
what the interface stamps: wall time of the send (virtual) or the kernel's receive time
(SocketCAN).

:func:`read_can_log` reads such a file back through ``can.LogReader``;
:func:`write_sidecar` / :func:`read_sidecar`: what the formats have no place for (the
run's topology, box model and configuration) in ``<log>.eha-hil.json`` beside the log,
where ``log info`` and ``replay`` find it;
:func:`reassemble` turns the segments of one CAN ID back into the frames
(:class:`~hil.transports.canbus.Reassembler`), counting what does not reassemble.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from hil.transports.base import TransportError, TransportStats
from hil.transports.canbus import Reassembler

#: File name endings of the formats, as ``can.Logger`` and ``can.LogReader`` choose them.
CAN_LOG_SUFFIXES = (".blf", ".asc", ".log")


def check_log_name(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if p.suffix.lower() not in CAN_LOG_SUFFIXES:
        raise TransportError(f"{path}: a CAN log file name ends .blf, .asc or .log")
    return p


class CanLogRecorder:
    """Write every message on a CAN channel to ``path`` until :meth:`close`."""

    def __init__(self, path: str | os.PathLike[str], interface: str, channel: str | int,
                 fd: bool = True, bus_options: dict[str, Any] | None = None) -> None:
        self.path = check_log_name(path)
        self.messages = 0
        try:
            self._bus = can.Bus(interface=interface, channel=channel, fd=fd,
                                **(bus_options or {}))
        except (can.CanError, ImportError, OSError, ValueError, TypeError) as exc:
            raise TransportError(f"can log: cannot open {interface} channel {channel!r}: "
                                 f"{' '.join(str(exc).split())}") from None
        try:
            self._writer = can.Logger(str(self.path))
        except (OSError, ValueError) as exc:
            self._bus.shutdown()
            raise TransportError(f"{path}: cannot write: "
                                 f"{getattr(exc, 'strerror', None) or exc}") from None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, name="can-log", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            msg = self._bus.recv(0.05)
            if msg is not None:
                self._write(msg)

    def _write(self, msg: can.Message) -> None:
        # the file is one cable: the writer's own channel, not the bus's name, which on the
        # virtual interface is private and random (BLF would read its trailing digits as a
        # 16-bit channel number, and "eha-hil-...96191" does not fit)
        msg.channel = None
        self._writer.on_message_received(msg)
        self.messages += 1

    def close(self) -> None:
        """Stop listening, write what is still queued, close the file."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join()
        while (msg := self._bus.recv(0.05)) is not None:
            self._write(msg)
        self._writer.stop()
        self._bus.shutdown()

    def __enter__(self) -> CanLogRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CanLogError(Exception):
    """A CAN log that cannot be read (one line)."""


#: Ending of the metadata file written beside a CAN log (``run.blf.eha-hil.json``).
SIDECAR_SUFFIX = ".eha-hil.json"


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """Where the run's metadata of the CAN log ``path`` lives."""
    return Path(str(path) + SIDECAR_SUFFIX)


def write_sidecar(path: str | os.PathLike[str], meta: dict[str, str]) -> Path:
    """Write ``meta`` (the run's topology, model, configuration: strings) beside the log."""
    import json

    side = sidecar_path(path)
    side.write_text(json.dumps({"eha-hil": "bus run", **meta}, indent=1, sort_keys=True)
                    + "\n")
    return side


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, str]:
    """The metadata beside the CAN log ``path`` ({} if there is none); CanLogError (one
    line) if the file is there but is not one."""
    import json

    side = sidecar_path(path)
    if not side.is_file():
        return {}
    try:
        data = json.loads(side.read_text())
    except (OSError, ValueError) as exc:
        raise CanLogError(f"{side}: not the metadata of a CAN log "
                          f"({getattr(exc, 'strerror', None) or exc})") from None
    if not isinstance(data, dict) or "eha-hil" not in data:
        raise CanLogError(f"{side}: not the metadata of a CAN log (no \"eha-hil\" key)")
    return {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in data.items()}


def read_can_log(path: str | os.PathLike[str]) -> list[can.Message]:
    """Every message of a BLF, ASC or candump file, through ``can.LogReader``."""
    p = check_log_name(path) if Path(path).suffix else Path(path)
    try:
        if p.suffix.lower() in (".asc", ".log") and _last_line_cut(p):
            # a cut text log: its readers stop at the partial line with an error; read the
            # complete lines (cut_reason reports the cut)
            import io

            text = p.read_text(errors="replace")
            text = text[: text.rfind("\n") + 1]
            reader = can.ASCReader if p.suffix.lower() == ".asc" else can.CanutilsLogReader
            return list(reader(io.StringIO(text)))
        return list(can.LogReader(str(p)))
    except (OSError, ValueError, EOFError, IndexError, KeyError, can.CanError) as exc:
        raise CanLogError(f"{path}: not a readable CAN log: "
                          f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
    except Exception as exc:  # a reader's own parse failure (struct.error, zlib.error...)
        raise CanLogError(f"{path}: not a readable CAN log: {type(exc).__name__}: "
                          f"{' '.join(str(exc).split())}") from None


def _last_line_cut(p: Path) -> bool:
    size = p.stat().st_size
    if not size:
        return False
    with open(p, "rb") as fh:
        fh.seek(size - 1)
        return fh.read(1) != b"\n"


def cut_reason(path: str | os.PathLike[str], messages: int) -> str | None:
    """Why a CAN log read back with ``messages`` messages ends early, or None if whole.

    python-can's readers stop quietly at a cut; each format says it another way: a BLF
    header declares the file size and the object count (both 0 when the writer was never
    closed), an ASC file ends with ``End TriggerBlock``, a candump line with a newline."""
    p = Path(path)
    size = p.stat().st_size
    suffix = p.suffix.lower()
    if suffix == ".blf":
        try:
            reader = can.BLFReader(str(p))
            declared_size, declared = reader.file_size, reader.object_count
            reader.stop()
        except Exception:  # noqa: BLE001 - read_can_log has reported a broken header
            return None
        if declared_size == 0 and declared == 0:
            return f"not finalised (the writer was not closed; {size} bytes)"
        if size < declared_size:
            return f"the file ends at byte {size} of {declared_size}"
        if messages < declared:
            return f"{messages} of the {declared} objects its header declares"
        return None
    with open(p, "rb") as fh:
        fh.seek(max(0, size - 4096))
        tail = fh.read()
    if suffix == ".asc" and b"End TriggerBlock" not in tail:
        return f"no 'End TriggerBlock' line (the file ends at byte {size})"
    if tail and not tail.endswith(b"\n"):
        return f"the last line is cut (the file ends at byte {size})"
    return None


@dataclass(frozen=True)
class LoggedFrame:
    """One frame rebuilt from a CAN log: when its last segment was logged, its CAN ID."""

    timestamp: float
    arbitration_id: int
    frame: bytes


def reassemble(messages: list[can.Message], ids: tuple[int, ...], fd: bool | None = None,
               stats: dict[int, TransportStats] | None = None) -> Iterator[LoggedFrame]:
    """The frames carried on each of ``ids``, in log order. ``fd``: CAN-FD segments
    (None: from the messages: FD if any message on those IDs is). ``stats`` (if given)
    gets a :class:`TransportStats` per ID with the reassembly's error counts."""
    mine = [m for m in messages if m.arbitration_id in ids and not m.is_error_frame
            and not m.is_remote_frame]
    if fd is None:
        fd = any(m.is_fd for m in mine)
    stats = {} if stats is None else stats
    asm = {}
    for i in ids:
        stats[i] = TransportStats()
        asm[i] = Reassembler(fd, max_frame=63_482 if fd else 6_138, stats=stats[i])
    for m in mine:
        frame = asm[m.arbitration_id].feed(bytes(m.data))
        if frame is not None:
            stats[m.arbitration_id].frames_received += 1
            yield LoggedFrame(m.timestamp, m.arbitration_id, frame)
