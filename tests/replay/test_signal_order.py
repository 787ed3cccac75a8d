"""The actuator message's field order (docs/framelog.md, "Field order"): the values that
change every sample first, with one-byte keys, the steady fields after them; and a log
written in the order before (``signals.ACTUATOR_SOURCE_ORDER``) still replays, exports
and decodes to the same values.

``tests/data/replay/floats_by_source.mcap`` was written by ``run_logged`` at level "mcu"
(hip_one_box, the robot engine, the default configuration with sensor noise on, 40
cycles of ``test_recipe_log._pc``) by the code as it stood before the field order: float fields,
numbered in source order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import zstandard
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from hil.fieldbus.topology import load_topology
from hil.framelog import FrameLogReader
from hil.framelog.columnar import decode_channel
from hil.replay import signals as SG
from hil.replay.record import run_logged
from hil.replay.replay import _metadata, replay_mcu
from tests.replay.test_recipe_log import _pc

LOG = Path(__file__).resolve().parents[1] / "data" / "replay" / "floats_by_source.mcap"
CYCLES = 40


def _stock(path) -> dict[str, list[tuple[int, dict[str, object], dict[str, int]]]]:
    """Every decoded-signal message of ``path`` by the stock protobuf decoder: per topic
    (log time, every field's value (set or not), field name -> number)."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, msg, d in reader.iter_decoded_messages():
            if ch.topic.startswith("/signals/"):
                fields = d.DESCRIPTOR.fields
                out.setdefault(ch.topic, []).append((
                    msg.log_time, {fd.name: getattr(d, fd.name) for fd in fields},
                    {fd.name: fd.number for fd in fields}))
    return out


def test_the_log_before_the_field_order_replays_bit_for_bit():
    res = replay_mcu(LOG)
    assert res.ok, res.divergence
    assert res.boxes == 1 and res.mcu_steps == 5 * (CYCLES - 1)


def test_the_same_run_today_decodes_to_the_values_of_the_log_before(tmp_path):
    """Today's run with the log's configuration: every decoded-signal message, read by the
    stock decoder, holds the same value in every field as the old log's (the actuator's
    now under other field numbers)."""
    cfg, _, _ = _metadata(LOG, FrameLogReader(LOG).info())
    today = tmp_path / "today.mcap"
    run_logged(load_topology("hip_one_box"), cfg, CYCLES, _pc, today, level="mcu",
               model="robot")
    old, new = _stock(LOG), _stock(today)
    assert old.keys() == new.keys() and "/signals/actuator/0.1" in old
    renumbered = set()
    for topic, msgs in old.items():
        assert len(msgs) == len(new[topic]) > 30, topic
        for (t0, v0, n0), (t1, v1, n1) in zip(msgs, new[topic], strict=True):
            assert t0 == t1 and v0.keys() == v1.keys(), topic
            for name, v in v0.items():
                assert v == v1[name] or (v != v and v1[name] != v1[name]), (topic, name)
            if n0 != n1:
                renumbered.add(topic)
    assert renumbered == {t for t in old if t.startswith("/signals/actuator/")}


def test_the_values_that_change_come_first_with_one_byte_keys():
    """Fields 1-15 (one-byte keys) are :data:`~hil.replay.signals.EVERY_SAMPLE`, then
    :data:`~hil.replay.signals.SLOW_VALUES`; in the old log's real (noisy) messages every
    field after those is the same in every sample, and today's order compresses the same
    messages at zstd's fastest level (the signal chunks') by over 5 % better than the
    source order."""
    msg = SG.ACTUATOR
    names = [f.name for f in msg.fields]
    assert names[:15] == list(SG.EVERY_SAMPLE)
    assert names[15:15 + len(SG.SLOW_VALUES)] == list(SG.SLOW_VALUES)
    assert sorted(names) == sorted(f.name for f in SG.ACTUATOR_SOURCE_ORDER.fields)
    keys = [msg.record.fields[f"k{n}"][0].itemsize for n in range(1, len(names) + 1)]
    assert keys[:15] == [1] * 15 and set(keys[15:]) == {2}
    reader = FrameLogReader(LOG)
    info = reader.info()
    topics = [c.topic for c in info.channels if c.topic.startswith("/signals/actuator/")]
    raws = reader.raw_channels(topics)
    cols = [decode_channel(c, raws[c.topic]) for c in info.channels if c.topic in topics]
    assert len(cols) == 2 and all(c.n > 30 for c in cols)
    tail = names[15 + len(SG.SLOW_VALUES):]
    held = ("x_piston_m", "v_piston_m_s")  # this log's piston does not move

    def changes(c, name):
        v = c.columns[name]
        return np.mean(v[1:] != v[:-1])

    for c in cols:
        for name in (*tail, *held):
            assert changes(c, name) == 0, name
        every = min(changes(c, n) for n in SG.EVERY_SAMPLE if n not in held)
        slow = max(changes(c, n) for n in SG.SLOW_VALUES if n in c.columns)
        assert every > slow > 0.3, (every, slow)
    unfitted = ("rod_temperature",)
    size = {}
    for order, base in (("today", SG.ACTUATOR), ("source", SG.ACTUATOR_SOURCE_ORDER)):
        m = SG.actuator_message(unfitted, base)
        assert {c.schema_name for c in info.channels if c.topic in topics} == {m.full_name}
        data = b"".join(m.encode_array(c.columns, c.n).tobytes() for c in cols)
        size[order] = len(zstandard.ZstdCompressor(level=-7).compress(data))
    assert size["today"] < 0.95 * size["source"], size
