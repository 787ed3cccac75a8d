"""Topology files and the cycle plan (frame split, expected working counters)."""

from __future__ import annotations

import pytest

from hil.fieldbus.chain import MAX_DATAGRAM_DATA, CyclePlan
from hil.fieldbus.topology import TopologyError, load_topology, topology_names
from protocols import ethercat as ec


def test_shipped_topologies(full, bench):
    assert {"hydra_full", "bench_one_box"} <= set(topology_names())
    assert len(full.boxes) == 16
    assert full.n_actuators == 47
    assert len(set(full.actuator_names())) == 47
    kinds = [s.kind for b in full.boxes for s in b.slots]
    assert kinds.count("foot_sensor") == 2 and kinds.count("imu") == 1
    assert bench.n_actuators == 1 and len(bench.boxes) == 1


BAD = [
    ("[[box]]\nid = 0\nslots = []\n", "box #0", "slots"),
    ("[[box]]\nid = 0\nslots = ['a']\n[[box]]\nid = 5\nslots = ['b']\n", "box #1", "id"),
    ("[[box]]\nid = 0\nslots = ['a', 'b', 'c', 'd', 'e', 'f']\n", "box #0", "1..5"),
    ("[[box]]\nid = 0\nslots = [{ name = 'x', kind = 'laser' }]\n", "box #0", "laser"),
    ("[[box]]\nid = 0\nslots = ['a']\n[[box]]\nid = 1\nslots = ['a']\n", "box #1", "twice"),
    ("[[box]]\nid = 0\nslots = ['a']\ncolour = 1\n", "box #0", "colour"),
    ("[[box]]\nid = 0\nslots = ['a'\n", "not valid TOML", ""),
    ("name = 'x'\n", "at least one", ""),
]


@pytest.mark.parametrize(("text", "where", "what"), BAD)
def test_bad_topology_files(tmp_path, text, where, what):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(TopologyError) as err:
        load_topology(path)
    msg = str(err.value)
    assert str(path) in msg and where in msg and what in msg
    assert "\n" not in msg


def test_missing_topology():
    with pytest.raises(TopologyError, match="no_such_thing"):
        load_topology("no_such_thing")


def test_plan_fits_ethernet_and_wkc(full):
    plan = CyclePlan.build(full)
    assert len(plan.frames) >= 2  # the full image does not fit one frame
    covered = 0
    for lad, n, wkc in plan.frames:
        assert lad == covered
        covered += n
        assert 2 + ec.DATAGRAM_OVERHEAD + n <= ec.ETH_MAX_PAYLOAD
        assert n <= MAX_DATAGRAM_DATA
        boxes = [w for w in plan.windows if lad <= w.lad and w.end <= lad + n]
        expected = sum(3 if w.out_len and w.in_len else 1 for w in boxes)
        assert wkc == expected
    assert covered == plan.image_bytes
    # Every box in exactly one frame; the IMU box is input-only (WKC 1).
    imu = plan.windows[6]
    assert imu.out_len == 0 and imu.in_len > 0 and imu.wkc == 1
    assert sum(w for _, _, w in plan.frames) == 3 * 15 + 1


def test_plan_split_small_frames(full):
    plan = CyclePlan.build(full, max_data=300)
    assert len(plan.frames) > 2
    for lad, n, _ in plan.frames:
        assert n <= 300
        # no box straddles two frames
        for w in plan.windows:
            assert w.end <= lad or w.lad >= lad + n or (lad <= w.lad and w.end <= lad + n)
