"""The compiled box-record signals (:mod:`hil.replay.signal_records`) against the numpy
reference (:func:`hil.replay.signals.record_columns` + ``MessageType.encode_into``): the
same message bytes for every slot layout of the whole robot, both directions, random
record bytes (every mode, negative counts, NaN commands) and piston flags, written into
an array of its own and into places with a stride (as in the log's records)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.fieldbus.topology import load_topology
from hil.replay import signals as SG
from hil.replay.signal_records import RecordEncoder


def _layouts() -> list:
    """One box of each slot layout of hydra_full and bench_one_box."""
    seen = {}
    for name in ("hydra_full", "bench_one_box"):
        for box in load_topology(name).boxes:
            seen.setdefault(tuple(s.kind for s in box.slots), box)
    return list(seen.values())


@pytest.mark.parametrize("direction", ["outputs", "inputs"])
def test_the_compiled_records_are_the_references_byte_for_byte(direction: str) -> None:
    rng = np.random.default_rng(7)
    for box in _layouts():
        message = SG.record_message(box, direction)
        if not message.fields:
            continue  # (no channel for such a record)
        enc = RecordEncoder(box, direction, message)
        m, c = 3, 9
        rows = rng.integers(0, 256, (m, c, enc.bytes)).astype(np.uint8)
        for at in set(enc.plan[:, 5]) - {-1}:  # every mode, and a code no mode has
            rows[:, :, at] = rng.integers(0, 4, (m, c))
        slots = SG._actuator_slots(box)  # noqa: SLF001
        a = len(slots) * m + 2
        flags = (rng.random((a, c)) < 0.5, rng.random((a, c)) < 0.5)
        pick = rng.permutation(a)[:len(slots) * m].reshape(len(slots), m)
        piston = tuple(f[pick].reshape(len(slots), -1) for f in flags)
        want = message.encode_array(SG.record_columns(
            box, direction, rows.reshape(m * c, -1),
            piston if direction == "inputs" else None), m * c)
        got = enc.encode(rows, np.empty_like(want), flags, pick)
        assert got.tobytes() == want.tobytes(), (box.id, direction)
        room = np.full((m * c, message.size + 5), 0xAA, np.uint8)  # places with a stride
        enc.encode(rows, room[:, 3:3 + message.size], flags, pick)
        assert room[:, 3:3 + message.size].tobytes() == want.tobytes()
        assert (room[:, :3] == 0xAA).all() and (room[:, 3 + message.size:] == 0xAA).all()


def test_a_message_that_is_not_the_records_is_refused() -> None:
    box = load_topology("hydra_full").boxes[0]
    inputs = SG.record_message(box, "inputs")
    with pytest.raises(ValueError, match="expected"):
        RecordEncoder(box, "outputs", inputs)
    enc = RecordEncoder(box, "inputs", inputs)
    rows = np.zeros((1, 2, enc.bytes), np.uint8)
    with pytest.raises(ValueError, match="piston flags"):
        enc.encode(rows, np.empty((2, inputs.size), np.uint8))


def test_the_log_warm_up_compiles_the_layouts_a_logged_run_passes() -> None:
    """A full block hands the encoders C-contiguous rows, a partial one views, and the
    messages go into strided places: the warm-up leaves each of these compiled."""
    from hil.replay import signal_kernel, signal_records
    from hil.replay.robot_record import warm_up
    from plant.config import load_config

    warm_up(load_config(None))
    acts = {(str(s[0].layout), str(s[3].layout)) for s in signal_kernel._encode.signatures}  # noqa: SLF001
    assert {("C", "A"), ("A", "A")} <= acts
    recs = {str(s[7].layout) for s in signal_records._encode.signatures}  # noqa: SLF001
    assert "A" in recs
