"""Frame logs: every frame that crosses a link, with its simulated time, in an MCAP file.

See ``docs/framelog.md``. Writing: :class:`FrameLogWriter`; reading: :class:`FrameLogReader`
(``info``, ``frames``, ``blocks``); decoding: :mod:`hil.framelog.decoders`; the CLI verbs
``eha-hil log info|export``: :mod:`hil.cli.log`.
"""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
from hil.framelog.formats import LEVELS, level_includes, lvds_topic, sensor_topic, signal_topic
from hil.framelog.reader import Blocks, ChannelInfo, FrameLogError, FrameLogReader, LogInfo


def __getattr__(name: str):  # noqa: ANN202 - the module attribute asked for
    """``FrameLogWriter`` on first use: the writer loads the byte-plane kernels (numba), which
    a command that only reads a log (``eha-hil log info``) has no use for."""
    if name == "FrameLogWriter":
        from hil.framelog.writer import FrameLogWriter

        return FrameLogWriter
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "LEVELS", "Blocks", "ChannelInfo", "FrameLogError", "FrameLogReader", "FrameLogWriter",
    "LogInfo", "level_includes", "lvds_topic", "sensor_topic", "signal_topic",
]
