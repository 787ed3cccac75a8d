"""The master's batched output records equal the per-actuator ones byte for byte."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.fieldbus.master import Master
from hil.fieldbus.topology import load_topology

TOPO = load_topology("hydra_full")
N = TOPO.n_actuators
# Around the rounding half-way points and beyond the i4 range (saturation), both signs.
VALUE = st.one_of(st.floats(-3e7, 3e7, allow_nan=False),
                  st.integers(-10**6, 10**6).map(lambda k: k * 0.005),
                  st.sampled_from([0.0, -0.0, 0.005, -0.005, 2.2e7, -2.2e7, 1e10, -1e10]))


@settings(max_examples=30, deadline=None)
@given(values=st.lists(VALUE, min_size=N, max_size=N),
       mode=st.sampled_from(["off", "force", "position"]), enable=st.booleans())
def test_set_actuators_writes_what_set_actuator_writes(values, mode, enable):
    one, many = Master(TOPO), Master(TOPO)
    for j, v in enumerate(values):
        one.set_actuator(j, mode, v, enable=enable)
    many.set_actuators(mode, np.array(values), enable=enable)
    assert many.image == one.image


def test_set_actuators_refuses_bad_input():
    m = Master(TOPO)
    with pytest.raises(ValueError, match="unknown mode"):
        m.set_actuators("torque", np.zeros(N))
    with pytest.raises(ValueError, match=f"expected {N}"):
        m.set_actuators("force", np.zeros(N - 1))
    with pytest.raises(ValueError, match="not finite"):
        m.set_actuators("force", np.full(N, np.nan))
    assert m.image == Master(TOPO).image  # nothing written
