"""Process data: SI -> counts -> SI within half an LSB, saturation beyond the range."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.fieldbus import pdo
from hil.fieldbus.boxes import EchoBox
from hil.fieldbus.master import Master
from hil.fieldbus.topology import load_topology
from plant.config import load_config

TOPO = load_topology("bench_one_box")
CFG = load_config("hydra_default")
I4 = np.iinfo(np.int32)
FINITE = st.floats(-1e12, 1e12, allow_nan=False)


def _out_of_master(mode, value, kp_pos=0.0, kp_f=0.0, enable=True, clear=False):
    m = Master(TOPO)
    m.set_actuator(0, mode, value, enable=enable, clear_fault=clear, kp_position=kp_pos,
                   kp_force=kp_f)
    box = EchoBox(TOPO.boxes[0], CFG)
    o = m.act_offsets[0][0]
    return box.decode(bytes(m.image[o:o + pdo.ACTUATOR_OUT_DTYPE.itemsize]))[0]


def _expect(value, lsb, dtype):
    info = np.iinfo(np.dtype(dtype))
    return min(max(value, info.min * lsb), info.max * lsb)


@settings(max_examples=200, deadline=None)
@given(mode=st.sampled_from(["force", "position", "off"]), value=FINITE,
       kp_pos=st.floats(0, 1e7), kp_f=st.floats(0, 100), enable=st.booleans(),
       clear=st.booleans())
def test_outputs_round_trip(mode, value, kp_pos, kp_f, enable, clear):
    got_mode, got, flags, got_kpos, got_kf = _out_of_master(mode, value, kp_pos, kp_f, enable,
                                                            clear)
    assert got_mode == mode
    lsb = pdo.POSITION_CMD_LSB if mode == "position" else pdo.FORCE_CMD_LSB
    assert abs(got - _expect(value, lsb, "i4")) <= lsb / 2 * (1 + 1e-9)
    assert abs(got_kpos - _expect(kp_pos, 10.0, "u2")) <= 10.0 / 2 * (1 + 1e-9)
    assert abs(got_kf - _expect(kp_f, 1e-3, "u2")) <= 1e-3 / 2 * (1 + 1e-9)
    assert flags == (pdo.FLAG_ENABLE if enable else 0) | (pdo.FLAG_CLEAR_FAULT if clear else 0)


def test_outputs_saturate():
    assert _out_of_master("force", 1e12)[1] == I4.max * pdo.FORCE_CMD_LSB
    assert _out_of_master("force", -1e12)[1] == I4.min * pdo.FORCE_CMD_LSB
    assert _out_of_master("force", 1500.0)[1] == 1500.0


NUM_FIELDS = [f for f in pdo.ACTUATOR_IN if f.lsb not in (0, 1) or f.unit]


@settings(max_examples=200, deadline=None)
@given(values=st.tuples(*[FINITE for _ in NUM_FIELDS]),
       status=st.integers(0, 0xFFFF), err=st.integers(0, 10**6))
def test_inputs_round_trip(values, status, err):
    box = EchoBox(TOPO.boxes[0], CFG)
    kw = dict(zip(["x", "v", "f_pres", "f_strain", "f_fil", "iq", "temp"], values, strict=True))
    box._pack_actuator(0, **kw, status=status, err_down=err, err_up=3)
    m = Master(TOPO)
    i = m.act_offsets[0][1]
    m.image[i:i + pdo.ACTUATOR_IN_DTYPE.itemsize] = box.inputs()
    got = m.actuator_inputs(0)
    for f, v in zip(NUM_FIELDS, values, strict=True):
        assert abs(got[f.name] - _expect(v, f.lsb, f.dtype)) <= f.lsb / 2 * (1 + 1e-9), f.name
    assert got["status"] == status
    assert got["err_link_down"] == min(err, 0xFFFF)
    assert got["err_link_up"] == 3


def test_to_counts_rounding():
    assert pdo.to_counts(0.005, 0.01, "i4") == 1  # half away from zero
    assert pdo.to_counts(-0.005, 0.01, "i4") == -1
    assert pdo.to_counts(1e9, 0.1, "i2") == 32767
    assert pdo.to_counts(-1e9, 0.1, "i2") == -32768
    assert pdo.to_counts(-5.0, 1.0, "u2") == 0
