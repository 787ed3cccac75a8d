"""Working-counter checks: a box that does not answer, a tampered reply. The frame is
counted as a WKC error and none of its inputs are applied."""

from __future__ import annotations

import dataclasses

import numpy as np

from hil.fieldbus import wire
from hil.fieldbus.system import BusSystem
from hil.transports import Transport
from protocols import ethercat as ec

from .conftest import full_robot_pc


def _frame_of_box(plan, box):
    w = plan.windows[box]
    return next(k for k, (lad, n, _) in enumerate(plan.frames) if lad <= w.lad < lad + n)


def _input_slices(plan, k):
    """Offsets in Master.input_image() of the windows inside frame k."""
    lad, n, _ = plan.frames[k]
    out, pos = [], 0
    for w in plan.windows:
        if lad <= w.lad < lad + n:
            out.append(slice(pos, pos + w.in_len))
        pos += w.in_len
    return out


def test_silent_box_is_a_wkc_error(cfg, full):
    with BusSystem(full, cfg, "inproc", model="echo") as bs:
        bs.run(10, full_robot_pc)
        plan = bs.master.plan
        silent = 3
        k = _frame_of_box(plan, silent)
        # Box 3 stops answering: its window is no longer where the frames address it.
        windows = list(bs.chain.plan.windows)
        windows[silent] = dataclasses.replace(windows[silent], lad=1 << 30)
        bs.chain.plan = dataclasses.replace(bs.chain.plan, windows=tuple(windows))
        rec = bs.run(20, full_robot_pc)
        names = bs.master.names
        fresh = {names[j]: bs.master.actuator_inputs(j)["fresh"] for j in range(len(names))}
    assert rec.master["wkc_errors"] == 20
    assert rec.master["frames_ok"] == 10 * 2 + 20 * (len(plan.frames) - 1)
    assert rec.master["frames_sent"] == rec.master["frames_ok"] + rec.master["wkc_errors"]
    # The frame's inputs (every box in it, not only the silent one) stay as they were.
    for sl in _input_slices(plan, k):
        assert (rec.inputs[:, sl] == rec.inputs[0, sl]).all()
    others = [s for kk in range(len(plan.frames)) if kk != k for s in _input_slices(plan, kk)]
    assert any(not (rec.inputs[:, s] == rec.inputs[0, s]).all() for s in others)
    box_names = {s.name for s in full.boxes[silent].slots}
    assert not any(fresh[n] for n in box_names if n in fresh)
    assert sum(fresh.values()) > 0


class _Tamper(Transport):
    """The master's end, with every reply's working counter raised by one (FCS resealed)."""

    name = "tamper"

    def __init__(self, inner: Transport) -> None:
        super().__init__("master", inner.max_frame)
        self.inner = inner

    def _send(self, frame: bytes) -> None:
        self.inner.send(frame)

    def _recv(self, timeout):
        frame = self.inner.recv(timeout)
        if frame is None:
            return None
        dgs = wire.open_frame(frame)
        dgs = [dataclasses.replace(d, wkc=d.wkc + 1) for d in dgs]
        return wire.seal(ec.encode_pdu(dgs))

    def _close(self) -> None:
        self.inner.close()


def test_tampered_reply_not_applied(cfg, full):
    with BusSystem(full, cfg, "inproc", model="echo") as bs:
        bs.m_end = _Tamper(bs.m_end)
        rec = bs.run(15, full_robot_pc)
        applied = [bs.master.actuator_inputs(j)["fresh"] for j in range(47)]
    n = 15 * 2
    assert rec.master["wkc_errors"] == n
    assert rec.master["frames_ok"] == 0 and rec.master["lost_frames"] == 0
    assert not np.any(rec.inputs)  # nothing of any reply reached the image
    assert not any(applied)
