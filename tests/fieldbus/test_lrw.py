"""The plan frames' templates (hil.fieldbus.lrw) against the general codec: the same bytes
out, the same reading in; the master and the chain answer the same through either path."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.fieldbus import lrw, wire
from hil.fieldbus.chain import Chain
from hil.fieldbus.master import Master
from hil.fieldbus.topology import load_topology
from plant.config import load_config
from protocols import ethercat as ec

TOPO = load_topology("hydra_full")


@settings(max_examples=60, deadline=None)
@given(lad=st.integers(0, 0xFFFFFFFF), n=st.integers(1, 64), idx=st.integers(0, 255),
       wkc=st.integers(0, 0xFFFF), crc=st.booleans(), data=st.data())
def test_a_built_frame_is_the_codecs(lad, n, idx, wkc, crc, data):
    image = data.draw(st.binary(min_size=lad % 97 + n, max_size=lad % 97 + n))
    t = lrw.LrwTemplate(lad % 97, n, crc)
    d = ec.Datagram.logical(ec.Command.LRW, lad % 97, image[lad % 97:], idx=idx, wkc=wkc)
    assert t.build(idx, image, wkc) == wire.seal(ec.encode_pdu([d]), crc)


@settings(max_examples=100, deadline=None)
@given(crc=st.booleans(), data=st.data())
def test_a_matched_frame_reads_as_the_codec_reads_it(crc, data):
    """Damaged, shortened, lengthened frames and frames of other datagrams: whatever the
    template takes, the codec reads as one LRW datagram at its address and length, with
    the idx, data and working counter at the template's offsets."""
    n = data.draw(st.integers(1, 40))
    t = lrw.LrwTemplate(300, n, crc)
    frame = bytearray(t.build(data.draw(st.integers(0, 255)),
                              data.draw(st.binary(min_size=300 + n, max_size=300 + n)),
                              data.draw(st.integers(0, 0xFFFF))))
    how = data.draw(st.sampled_from(["none", "byte", "cut", "add", "irq", "other"]))
    if how == "byte":
        at = data.draw(st.integers(0, len(frame) - 1))
        frame[at] = data.draw(st.integers(0, 255))
    elif how == "cut":
        frame = frame[:data.draw(st.integers(0, len(frame) - 1))]
    elif how == "add":
        frame += data.draw(st.binary(min_size=1, max_size=4))
    elif how == "irq":  # the IRQ word is the slaves' to set: still the plan's frame
        frame[lrw.IDX_AT + 7] = data.draw(st.integers(0, 255))
        frame = bytearray(wire.seal(bytes(frame[:t.pdu_size]), crc))
    elif how == "other":
        d = ec.Datagram.logical(data.draw(st.sampled_from([ec.Command.LRD, ec.Command.LRW])),
                                data.draw(st.sampled_from([299, 300])), bytes(n),
                                wkc=3)
        extra = [ec.Datagram(ec.Command.BRD, data=b"\0\0")] if data.draw(st.booleans()) else []
        frame = bytearray(wire.seal(ec.encode_pdu([d, *extra]), crc))
    frame = bytes(frame)
    dgs = wire.open_frame(frame, crc)
    if how in ("none", "irq"):
        assert t.match(frame)
    if t.match(frame):
        assert dgs is not None and len(dgs) == 1
        d = dgs[0]
        assert (d.cmd, d.lad, len(d.data), d.circulating) == (ec.Command.LRW, 300, n, False)
        assert (frame[lrw.IDX_AT], frame[lrw.DATA_AT:lrw.DATA_AT + n], t.wkc(frame)) == (
            d.idx, d.data, d.wkc)


def _general(end: Master | Chain) -> Master | Chain:
    """``end`` reading every frame with the general codec (no template matches)."""
    end._templates = {}
    if isinstance(end, Chain):
        end._plan_of_caches = end.plan
    return end


def test_the_chain_and_the_master_answer_the_same_through_the_templates():
    """Two master/chain pairs (echo boxes, the whole robot), one reading every frame with
    the codec: the same replies, images and counters over cycles with commands, lost,
    repeated, late and damaged frames."""
    cfg = load_config()
    rng = np.random.default_rng(7)
    fast = (Master(TOPO), Chain(TOPO, cfg, "echo"))
    slow = (_general(Master(TOPO)), _general(Chain(TOPO, cfg, "echo")))
    late: list[bytes] = []
    late_replies: list[bytes] = []
    for cycle in range(40):
        values = rng.normal(0.0, 500.0, TOPO.n_actuators)
        replies, built = [], []
        for m, c in (fast, slow):
            m.set_actuators("force", values, enable=cycle > 2)
            frames = m.frames()
            built.append(frames)
            sent = list(frames)
            if cycle % 7 == 3:
                sent = sent[1:]                                   # lost
            if cycle % 5 == 1:
                sent.append(frames[0])                            # repeated
            if cycle % 6 == 2:
                f = bytearray(frames[-1])
                f[len(f) // 2] ^= 0x10                            # damaged
                sent.append(bytes(f))
            if cycle % 9 == 4 and late:
                sent.append(late[0])                              # from an older cycle
            out = [c.handle(f) for f in sent]
            for r in out:
                if r is not None:
                    m.receive(r)
                    if cycle % 4 == 0:
                        m.receive(r)                              # a duplicated reply
            if cycle % 3 == 0:
                m.receive(wire.seal(b"\x01\x10junk", True))       # garbage
            if cycle % 4 == 1 and late_replies:
                m.receive(late_replies[0])                        # a late reply
            m.end_cycle()
            replies.append(out)
        late = built[0]
        late_replies = [r for r in replies[0] if r is not None]
        assert built[0] == built[1] and replies[0] == replies[1]
        assert fast[0].image == slow[0].image
        assert fast[0].stats == slow[0].stats and fast[0].fresh == slow[0].fresh
        assert fast[1].stats == slow[1].stats
    assert fast[0].stats.frames_ok > 0 and fast[0].stats.stale_frames > 0
    assert fast[0].stats.bad_frames > 0 and fast[1].stats.bad_frames > 0


@pytest.mark.parametrize("crc", [True, False])
def test_master_frames_are_the_codecs(crc):
    m = Master(TOPO, crc)
    m.set_actuators("position", np.linspace(-0.01, 0.01, TOPO.n_actuators))
    m.cycle = 300
    want = [wire.seal(ec.encode_pdu([ec.Datagram.logical(
        ec.Command.LRW, lad, bytes(m.image[lad:lad + n]), idx=300 & 0xFF)]), crc)
        for lad, n, _ in m.plan.frames]
    assert m.frames() == want
