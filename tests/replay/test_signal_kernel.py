"""The compiled actuator signals (:mod:`hil.replay.signal_kernel`) against the numpy
reference (:func:`hil.replay.signals.actuator_block`, ``pc_command_block``,
``MessageType.encode_array``): the same message bytes and the same carried state, over
blocks with torn reads, real jumps, steps before the first upstream sweep and boxes that
received no output record in a block."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from hil.fieldbus import pdo
from hil.replay import signals as SG
from hil.replay.signal_kernel import ActuatorEncoder
from plant.config import load_config

SLOT = pdo.ACTUATOR_OUT_DTYPE.itemsize
#: Three actuators: two in box 0 (slots 0 and 1), one in box 1.
BOX_OF, SLOT_OFF = [0, 0, 1], [0, SLOT, 2 * SLOT]
SPANS = [(0, 2 * SLOT), (2 * SLOT, 3 * SLOT)]


class _Slot:
    sizes = (SLOT, 0)


class _Box:
    slots = [_Slot(), _Slot()]


def _block(rng, blk: int, tick0: int, a: int, n: int, every: int):
    """Random words of ``n`` steps, with a torn read, a real jump, the first sweeps
    missing (block 0) and no output record at all (block 2)."""
    room = np.zeros((a, n + 7, B.UP_WORDS + 2), np.uint16)  # a view, as the recorder's tap
    up = room[:, :n]
    up[:] = rng.integers(0, 1 << 16, up.shape)
    cnt = 0x20000 + np.cumsum(rng.integers(-3000, 3000, (a, n)), axis=1)
    if blk == 1:
        cnt[0, 10] -= SG.TEAR_COUNTS  # torn
        cnt[1, 20:] += 0x800000  # a real jump
        cnt[2, 30] += SG.TEAR_COUNTS  # torn the other way
    up[:, :, B.U_PISTON_LO] = cnt & 0xFFFF
    up[:, :, B.U_PISTON_HI] = (cnt >> 16) & 0xFFFF
    if blk == 0:
        up[:, :7] = 0  # no sweep yet
        up[2, :, B.U_TICK] = 0  # this board's not in the whole block
    up[:, :, B.UP_WORDS + 1] = rng.integers(0, 3, (a, n))  # CRC count's high half
    down = np.zeros((a, n + 3, 16), np.uint16)[:, :n]
    down[:] = rng.integers(0, 1 << 16, down.shape)
    t_steps = tick0 + 4 * np.arange(1, n + 1, dtype=np.int64)
    out_t = tick0 + 4 * every * np.arange(n // every + (blk == 3), dtype=np.int64)
    out_rows = rng.integers(0, 256, (len(out_t), 3 * SLOT)).astype(np.uint8)
    out_rows[:, 0::SLOT] = rng.integers(0, 3, (len(out_t), 3))  # modes 0..2
    out_got = rng.random((len(out_t), 2)) < (0.0 if blk == 2 else 0.7)
    return up, down, t_steps, out_t, out_rows, out_got


@pytest.mark.parametrize("layout", ["today", "source order", "all double"])
@pytest.mark.parametrize("unfitted", [(), ("rod_temperature",)])
@pytest.mark.parametrize("every", [1, 5])
def test_the_compiled_signals_are_the_reference_byte_for_byte(unfitted, every, layout):
    """Today's layout (float fields, no PC command, the changing values first), the same
    fields in the order before, and that of older logs (every value a double, the PC's
    command first: its look-up of the boxes' output records)."""
    cal = calibration(load_config(None))
    msg = SG.actuator_message(unfitted, {"today": SG.ACTUATOR,
                                         "source order": SG.ACTUATOR_SOURCE_ORDER,
                                         "all double": SG.ACTUATOR_ALL_DOUBLE}[layout])
    a, n = 3, 50
    enc = ActuatorEncoder(cal, msg, 200e-6, every, BOX_OF, SLOT_OFF, SPANS, 3 * SLOT)
    own = ActuatorEncoder(cal, msg, 200e-6, every, BOX_OF, SLOT_OFF, SPANS, 3 * SLOT)
    ref_carry, carry = SG.PistonCarry.start(a), SG.PistonCarry.start(a)
    own_carry = SG.PistonCarry.start(a)
    last = [(np.zeros(0, np.int64), np.zeros((0, hi - lo), np.uint8)) for lo, hi in SPANS]
    rng = np.random.default_rng(5)
    tick0 = 0
    seen = set()
    for blk in range(4):
        up, down, t_steps, out_t, out_rows, out_got = _block(rng, blk, tick0, a, n, every)
        tick0 = int(t_steps[-1])
        keep, cols = SG.actuator_block(cal, up, down, every, 200e-6, ref_carry)
        box_out = []
        for e, (lo, hi) in enumerate(SPANS):  # as the per-actuator path keeps them
            got = out_got[:, e]
            if got.any():
                last[e] = (out_t[got][-1:], out_rows[got, lo:hi][-1:])
                box_out.append((out_t[got], out_rows[got, lo:hi]))
            else:
                box_out.append(last[e])
        cols.update(SG.pc_command_block([(*box_out[0], _Box, 0), (*box_out[0], _Box, 1),
                                         (*box_out[1], _Box, 0)], t_steps[keep]))
        want = msg.encode_array(cols, a * len(keep))
        # behind a 7-byte head in rows of 9 more bytes, as in their MCAP records
        rows = np.full((a * len(keep), 7 + msg.size + 2), 0xEE, np.uint8)
        got_keep, got = enc.encode(up, down, carry, t_steps, out_t, out_rows, out_got,
                                   out=rows[:, 7:7 + msg.size])
        assert got_keep.tolist() == keep.tolist()
        assert np.array_equal(got, want) and np.array_equal(rows[:, 7:7 + msg.size], want)
        assert (rows[:, :7] == 0xEE).all() and (rows[:, -2:] == 0xEE).all()
        # into an array of its own (a second encoder in step with the first)
        assert np.array_equal(own.encode(up, down, own_carry, t_steps, out_t, out_rows,
                                         out_got)[1], want)
        for name in ("x", "count", "offset", "valid", "started", "valid_in", "step_valid"):
            assert np.array_equal(getattr(carry, name), getattr(ref_carry, name),
                                  equal_nan=True), (blk, name)
        if not ref_carry.step_valid[:2].all():
            seen.add(("torn", blk))
        if not cols["upstream_valid"].all():
            seen.add("unread")
        seen |= {f"mode {m}" for m in np.unique(cols["pc_mode"]).tolist()}
        for x, y in zip(SG.report_flags(carry, t_steps, out_t),
                        SG.report_flags(ref_carry, t_steps, out_t), strict=True):
            assert np.array_equal(x, y)
    # the blocks held what they are there for
    assert {("torn", 1), "unread", "mode 0", "mode 1", "mode 2"} <= seen


def test_a_message_type_with_foreign_fields_is_refused():
    from hil.framelog.protobuf import Field, MessageType

    other = MessageType("eha_hil.Other", (Field("speed", "double"),))
    with pytest.raises(ValueError, match="speed"):
        ActuatorEncoder(calibration(load_config(None)), other, 200e-6, 5, [], [], [], 0)


def test_messages_encoded_into_records_are_the_stock_decoders_messages():
    """``MessageType.encode_into`` rows of a wider array (as the messages' places in their
    MCAP records): the protobuf runtime parses each row back to the values, and the bytes
    around the rows are left alone."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    rng = np.random.default_rng(4)
    msg = SG.BUS
    n = 6
    cols = {f.name: rng.integers(0, 1000, n) for f in msg.fields}
    room = np.full((n, msg.size + 11), 0xEE, np.uint8)
    msg.encode_into(cols, room[:, 5:5 + msg.size])
    assert (room[:, :5] == 0xEE).all() and (room[:, 5 + msg.size:] == 0xEE).all()
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(msg.schema).file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(msg.full_name))
    for i in range(n):
        parsed = cls.FromString(room[i, 5:5 + msg.size].tobytes())
        assert [getattr(parsed, f.name) for f in msg.fields] == \
            [int(cols[f.name][i]) for f in msg.fields]
    with pytest.raises(ValueError, match="rows"):
        msg.encode_into(cols, np.zeros((n, msg.size + 1), np.uint8))
