"""The decoded signals' field types (docs/framelog.md, "Float or double"): a ``float`` field
holds every value its source word can take, distinct words distinct floats; the compiled
encoder writes either layout (today's floats, the all-double one of older logs) byte for
byte as the numpy reference; exports keep each file's types."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from firmware_model.calibration import calibration
from firmware_model.fpga import layout as B
from firmware_model.mcu import measure
from hil.fieldbus import pdo
from hil.fieldbus.topology import load_topology
from hil.framelog import FrameLogWriter
from hil.framelog.export import export_csv, export_parquet
from hil.framelog.protobuf import Field, MessageType
from hil.replay import signals as SG
from plant.config import load_config

WORDS = np.arange(1 << 16, dtype=np.int64)


def _distinct_as_float32(values: np.ndarray) -> bool:
    """Whether the float32 of ``values`` (float64, one per distinct source word) are as
    many distinct numbers as the values (NaN counted as none)."""
    v = values[np.isfinite(values)]
    return len(np.unique(v.astype(np.float32))) == len(np.unique(v)) == len(v)


def test_every_float_field_of_the_actuator_keeps_every_word():
    """Each of the 65,536 words in every register (the 24-bit strain code gets the word
    in its low 16 bits and the low byte in its high 8): each float field's decoded
    values stay distinct as float32. The double fields are the ones whose source is
    wider (the piston's two words, the 32-bit command, a difference of two words)."""
    cal = calibration(load_config(None))
    up = np.repeat(WORDS.astype(np.uint16)[:, None], B.UP_WORDS + 2, axis=1)
    up[:, B.U_PISTON_HI] = 0x0002  # the piston near mid-stroke, moving by the word
    down = np.repeat(WORDS.astype(np.uint16)[:, None], B.DOWN_WORDS, axis=1)
    cols = SG.actuator_columns(cal, up, down, np.zeros(len(WORDS)), 200e-6)
    floats = [f.name for f in SG.ACTUATOR.fields if f.kind == "float"]
    assert {"p_cyl_a_pa", "temperature_c", "iq_a", "f_strain_n", "omega_m_rad_s",
            "iq_ref_a"} <= set(floats)
    for name in floats:
        if name != "f_pressure_n":  # two words: below
            assert _distinct_as_float32(np.asarray(cols[name], np.float64)), name
    doubles = {f.name for f in SG.ACTUATOR.fields if f.kind == "double"}
    assert doubles == {"x_piston_m", "v_piston_m_s"}


def test_the_pressure_force_as_float_is_far_finer_than_one_pressure_word():
    """``f_pressure_n`` = k_c (p_cyl_a - p_cyl_b) comes from two words, both fields of the
    same message (each exact as a float): its float32 is off by less than a hundredth of
    what one word of either pressure moves it (0.7 N), up to the largest forces."""
    cal = calibration(load_config(None))
    up = np.zeros((len(WORDS), B.UP_WORDS + 2), np.uint16)
    reg = {a.si_name: a.register for a in B.ANALOG_INPUTS}
    up[:, reg["p_cyl_a"]] = WORDS
    up[:, reg["p_cyl_b"]] = WORDS[::-1]  # every word against a far one, the largest forces
    down = np.zeros((len(WORDS), B.DOWN_WORDS), np.uint16)
    cols = SG.actuator_columns(cal, up, down, np.zeros(len(WORDS)), 200e-6)
    f = cols["f_pressure_n"]
    step = np.abs(np.diff(cols["p_cyl_a_pa"])).min() * cal.kc_m2  # N per pressure word
    assert np.abs(f.astype(np.float32) - f).max() < 1e-2 * step


def test_the_strain_force_keeps_all_24_bit_codes():
    """One code is more newtons than float32's spacing at the largest force, so no two
    codes meet; and the codes of the largest forces (where the spacing is widest), each
    end's 2^20, give strictly increasing float32s."""
    mid, n_per_count = measure.strain_decoder(calibration(load_config(None)))
    top = np.concatenate([np.arange(1 << 20), np.arange((1 << 24) - (1 << 20), 1 << 24)])
    f = (top - mid) * n_per_count
    assert np.spacing(np.float32(np.abs(f).max())) < n_per_count
    assert np.all(np.diff(f[:1 << 20].astype(np.float32)) > 0)
    assert np.all(np.diff(f[1 << 20:].astype(np.float32)) > 0)


@pytest.mark.parametrize("direction", ["outputs", "inputs"])
def test_every_float_field_of_a_box_record_keeps_every_word(direction):
    box = load_topology("bench_one_box").boxes[0]
    msg = SG.record_message(box, direction)
    decl = pdo.SLOT_FIELDS["actuator"][0 if direction == "outputs" else 1]
    rec = np.zeros(len(WORDS), pdo.record_dtype(decl))
    for f in decl:
        info = np.iinfo(np.dtype(f.dtype))
        rec[f.name] = (WORDS % (info.max - info.min + 1) + info.min).astype(f.dtype)
    if direction == "outputs":
        rec["mode"] = 1  # the force command decoded
    piston = (np.ones((1, len(WORDS)), bool),) * 2 if direction == "inputs" else None
    cols = SG.record_columns(box, direction, rec.view(np.uint8).reshape(len(WORDS), -1),
                             piston)
    floats = [f.name for f in msg.fields if f.kind == "float"]
    assert floats
    for name in floats:
        assert _distinct_as_float32(np.asarray(cols[name], np.float64)), name
    # the fields of 32-bit words stay double
    assert {f.name for f in msg.fields if f.kind == "double"} == (
        {"s0_force_command_n", "s0_position_command_m"} if direction == "outputs"
        else {"s0_x_piston_m"})


def test_the_kernel_refuses_a_field_of_a_kind_it_does_not_write():
    from hil.replay.signal_kernel import ActuatorEncoder

    bad = MessageType("eha_hil.Bad", (Field("iq_a", "fixed32"),))
    with pytest.raises(ValueError, match="iq_a is fixed32"):
        ActuatorEncoder(calibration(load_config(None)), bad, 200e-6, 5, [], [], [], 0)


def test_the_old_all_double_layout_is_still_the_references_bytes():
    """The compiled encoder takes its stores from the message type: given the layout of
    older logs it writes that one, the same bytes as the numpy reference."""
    from hil.replay.signal_kernel import ActuatorEncoder

    cal = calibration(load_config(None))
    msg = SG.ACTUATOR_ALL_DOUBLE
    assert msg.size > SG.ACTUATOR.size and not any(f.kind == "float" for f in msg.fields)
    assert {"pc_mode", "force_command_n"} <= {f.name for f in msg.fields}
    slot = pdo.ACTUATOR_OUT_DTYPE.itemsize
    rng = np.random.default_rng(2)
    a, n = 2, 20
    # views into longer rows, as the recorder's tap hands them (the compiled types)
    up = np.zeros((a, n + 1, B.UP_WORDS + 2), np.uint16)[:, :n]
    up[:] = rng.integers(0, 1 << 16, up.shape)
    down = np.zeros((a, n + 1, B.DOWN_WORDS), np.uint16)[:, :n]
    down[:] = rng.integers(0, 1 << 16, down.shape)
    t_steps = 4 * np.arange(1, n + 1, dtype=np.int64)
    out_t = 4 * np.arange(n, dtype=np.int64)
    out_rows = rng.integers(0, 256, (n, 2 * slot)).astype(np.uint8)
    out_rows[:, 0::slot] = 1  # force mode
    got = np.ones((n, 2), bool)
    enc = ActuatorEncoder(cal, msg, 200e-6, 1, [0, 1], [0, slot], [(0, slot), (slot, 2 * slot)],
                          2 * slot)
    keep, mine = enc.encode(up, down, SG.PistonCarry.start(a), t_steps, out_t, out_rows, got)
    _, cols = SG.actuator_block(cal, up, down, 1, 200e-6, SG.PistonCarry.start(a))
    cols.update(SG.pc_command_block([(out_t, out_rows[:, :slot], _Box, 0),
                                     (out_t, out_rows[:, slot:], _Box, 0)], t_steps[keep]))
    assert np.array_equal(mine, msg.encode_array(cols, a * len(keep)))


class _Slot:
    sizes = (pdo.ACTUATOR_OUT_DTYPE.itemsize, 0)


class _Box:
    slots = [_Slot()]


def _log(path, message: MessageType, cols: dict, n: int) -> None:
    with FrameLogWriter(path) as w:
        ch = w.add_protobuf_channel("/signals/actuator/0.0", message)
        w.write_messages(ch, 1000 * np.arange(1, n + 1), message.encode_array(cols, n))


def test_exports_keep_each_files_types(tmp_path):
    """A log of today's layout exports its float fields as float32 (Parquet ``float``, CSV
    text that reads back to the same float32, and short), its doubles as float64, and so
    does one of the field order before; the same values in the old all-double layout
    export as float64 throughout."""
    rng = np.random.default_rng(1)
    n = 40
    cols = {f.name: (rng.integers(-30000, 30000, n) * 1e-3 if f.kind in ("float", "double")
                     else rng.integers(0, 2, n)) for f in SG.ACTUATOR_ALL_DOUBLE.fields}
    cols["x_piston_m"] = (rng.integers(0, 1 << 30, n) - (1 << 29)) * 5e-9  # 30 bits
    for layout, message in (("new", SG.ACTUATOR), ("source order", SG.ACTUATOR_SOURCE_ORDER),
                            ("old", SG.ACTUATOR_ALL_DOUBLE)):
        path = tmp_path / f"{layout}.mcap"
        _log(path, message, cols, n)
        export_parquet(path, tmp_path / f"{layout}.parquet")
        export_csv(path, tmp_path / f"{layout}.csv")
        schema = pq.read_schema(tmp_path / f"{layout}.parquet")
        df = pd.read_parquet(tmp_path / f"{layout}.parquet")
        csv = pd.read_csv(tmp_path / f"{layout}.csv", dtype=str)
        for f in message.fields:
            col = f"{f.name} [{f.unit}]" if f.unit else f.name
            if f.kind == "float":
                assert str(schema.field(f.name).type) == "float", f.name
                want = np.asarray(cols[f.name]).astype(np.float32)
                assert np.array_equal(df[f.name].to_numpy(), want), f.name
                text = csv[col].to_numpy()
                assert np.array_equal(text.astype(np.float32), want), f.name
                assert max(len(t) for t in text) <= 10, f.name  # "-29.999", not 17 digits
            elif f.kind == "double":
                assert str(schema.field(f.name).type) == "double", f.name
                assert np.array_equal(df[f.name].to_numpy(), cols[f.name]), f.name
                assert np.array_equal(csv[col].to_numpy().astype(np.float64), cols[f.name])


def test_a_column_float32_in_one_channel_and_wider_in_another_exports_as_double(tmp_path):
    one = MessageType("eha_hil.A", (Field("v", "float"), Field("w", "float")))
    two = MessageType("eha_hil.B", (Field("v", "double"), Field("w", "fixed32")))
    path = tmp_path / "mixed.mcap"
    with FrameLogWriter(path) as w:
        a = w.add_protobuf_channel("/a", one)
        b = w.add_protobuf_channel("/b", two)
        w.write_messages(a, [1, 3], one.encode_array({"v": [0.1, 0.2], "w": [1.5, 2.5]}, 2))
        w.write_messages(b, [2, 4], two.encode_array({"v": [0.1, 0.2], "w": [7, 1 << 30]}, 2))
    export_parquet(path, tmp_path / "mixed.parquet")
    df = pd.read_parquet(tmp_path / "mixed.parquet")
    assert df["v"].dtype == df["w"].dtype == np.float64
    assert df["v"].tolist() == [float(np.float32(0.1)), 0.1, float(np.float32(0.2)), 0.2]
    assert df["w"].tolist() == [1.5, 7.0, 2.5, float(1 << 30)]


def test_a_committed_log_of_the_all_double_layout_exports_and_decodes(tmp_path):
    """``tests/data/replay/recipe3_robot.mcap`` was written before the float fields: its
    signal channels export as float64 and decode with the stock protobuf decoder, as a
    log of today's layout does with its floats."""
    from pathlib import Path

    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    old = Path(__file__).resolve().parents[1] / "data" / "replay" / "recipe3_robot.mcap"
    export_parquet(old, tmp_path / "old.parquet", topics=["/signals/actuator/0.0",
                                                          "/signals/box/0/inputs"])
    df = pd.read_parquet(tmp_path / "old.parquet")
    assert df["iq_a"].dtype == df["s0_iq_a"].dtype == df["x_piston_m"].dtype == np.float64
    with open(old, "rb") as f:
        msgs = [d for _, _, _, d in make_reader(f, decoder_factories=[DecoderFactory()])
                .iter_decoded_messages(topics=["/signals/actuator/0.0"])]
    iq = df.loc[df["topic"] == "/signals/actuator/0.0", "iq_a"].to_numpy()
    assert len(msgs) == len(iq) == 39 and [m.iq_a for m in msgs] == iq.tolist()
    # the values are doubles of the words: not all of them float32-exact
    assert any(v != float(np.float32(v)) for v in iq)


def test_adjacent_slots_decoded_together_are_each_slot_decoded_alone():
    """``record_columns`` decodes a run of slots of one kind at once: each slot's columns
    are those of a one-slot box given that slot's bytes."""
    topo = load_topology("hydra_full")
    box = next(b for b in topo.boxes if sum(s.kind == "actuator" for s in b.slots) >= 3)
    one = load_topology("bench_one_box").boxes[0]
    rng = np.random.default_rng(7)
    for which, d in enumerate(("outputs", "inputs")):
        sizes = [s.sizes[which] for s in box.slots]
        rec = rng.integers(0, 256, (50, sum(sizes))).astype(np.uint8)
        acts = [k for k, s in enumerate(box.slots) if s.kind == "actuator"]
        if d == "outputs":
            for k in acts:
                rec[:, sum(sizes[:k])] = rng.integers(0, 3, 50)  # modes 0..2
        flags = rng.random((len(acts), 50)) < 0.5
        piston = (flags, ~flags) if d == "inputs" else None
        cols = SG.record_columns(box, d, rec, piston)
        for i, k in enumerate(acts):
            part = rec[:, sum(sizes[:k]):sum(sizes[:k + 1])]
            alone = SG.record_columns(one, d, part, (flags[i:i + 1], ~flags[i:i + 1])
                                      if d == "inputs" else None)
            for name, v in alone.items():
                np.testing.assert_array_equal(cols[f"s{k}_" + name[3:]], v, name)
