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
    if len(m.low_widths):  # the differences' noisy low bits as bit planes, the rest bytes
        u = np.dtype(f"<u{dt.itemsize}")
        bits, per_plane = 8 * dt.itemsize, (m.count + 7) // 8
        low = np.frombuffer(m.low_bits, np.uint8)
        high = np.frombuffer(m.high_deltas, np.uint8)
        # byte planes of z >> w kept per element (trimmed blocks), else all of them
        planes = (list(m.high_planes) if len(m.high_planes)
                  else [(bits - w + 7) // 8 for w in m.low_widths])
        z = np.zeros((m.count, m.width), np.uint64)
        lo = hi = 0
        for j, w in enumerate(m.low_widths):  # bytes: one int per element
            for b in range(w):  # bit b of frame i: bit i % 8 of byte i // 8 of the plane
                plane = np.unpackbits(low[lo:lo + per_plane], bitorder="little")
                z[:, j] |= plane[:m.count].astype(np.uint64) << np.uint64(b)
                lo += per_plane
            for b in range(planes[j]):  # byte b of z >> w
                z[:, j] |= high[hi:hi + m.count].astype(np.uint64) << np.uint64(w + 8 * b)
                hi += m.count
        z = z.astype(u)
        d = (z >> 1) ^ (0 - (z & 1)).astype(u)  # the signed differences, modulo 2^bits
        # frame -1 of the differences: first_frame where the block has one, else 0
        first = np.frombuffer(m.first_frame, u) if len(m.first_frame) else np.zeros(1, u)
        return t, (np.cumsum(d, axis=0, dtype=u) + first).view(dt)
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
