"""A raw block message as decoded by a stock protobuf reader (mcap-protobuf-support), turned
into times and frames with numpy alone, from the fields as docs/framelog.md describes them
(no project code): what a user's script does with a block."""

from __future__ import annotations

import numpy as np


def block_rows(m) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001 - a decoded protobuf message
    """``(t_ns (count,) int64, frames (count, width))`` of a decoded ``...Block`` message."""
    dt = np.dtype(m.dtype).newbyteorder("<")
    if len(m.t_ns) or not m.count:
        t = np.asarray(m.t_ns, np.int64)
    else:  # evenly spaced: the first time and the spacing
        t = m.t0_ns + m.dt_ns * np.arange(m.count, dtype=np.int64)
    if len(m.frame_deltas):  # byte planes of the zigzag-coded frame-to-frame differences
        u = np.dtype(f"<u{dt.itemsize}")
        raw = np.frombuffer(m.frame_deltas, np.uint8).reshape(dt.itemsize, m.width, m.count)
        z = np.ascontiguousarray(raw.transpose(2, 1, 0)).view(u).reshape(m.count, m.width)
        d = (z >> 1) ^ (0 - (z & 1)).astype(u)  # the signed differences, modulo 2^bits
        return t, np.cumsum(d, axis=0, dtype=u).view(dt)
    raw = np.frombuffer(m.frames, np.uint8)
    if m.byte_planes:  # byte b of element j of frame i at (b * width + j) * count + i
        rows = raw.reshape(dt.itemsize, m.width, m.count).transpose(2, 1, 0)
        return t, np.ascontiguousarray(rows).view(dt).reshape(m.count, m.width)
    return t, raw.view(dt).reshape(m.count, m.width)
