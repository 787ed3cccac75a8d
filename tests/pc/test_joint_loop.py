"""The PC's joint loop: limits, saturation, gravity model and the torque layer's round
trip through the rods' gauges."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.pc.geometry import hip_geometry
from firmware_model.pc.joint_loop import GravityModel, JointController, JointLimits
from firmware_model.pc.kinematics import UJointKinematics
from firmware_model.pc.strain import rod_force

GEOM = hip_geometry()
(PLO, PHI), (RLO, RHI) = GEOM.pitch_range_rad, GEOM.roll_range_rad
poses = st.tuples(st.floats(PLO, PHI), st.floats(RLO, RHI))


def _at(pose: tuple[float, float], tau: tuple[float, float] = (0.0, 0.0)) -> JointController:
    """A controller that measured the joint at ``pose`` carrying ``tau`` in its rods."""
    kin = UJointKinematics(GEOM)
    x = kin.inverse(*pose)
    f = kin.forces(*tau)
    ctl = JointController(GEOM)
    ctl.measure((x[0], x[1]), (rod_force(kin.cos_alpha[0], f[0]),
                               rod_force(kin.cos_alpha[1], f[1])))
    return ctl


@settings(max_examples=40, deadline=None)
@given(poses, st.floats(-60.0, 60.0), st.floats(-100.0, 100.0))
def test_measured_torque_is_what_the_rods_carry(pose, tp, tr):
    """Gauge forces along the leaning rods (Eq. 6.5 inverted) come back as the torque."""
    assert _at(pose, (tp, tr)).tau == pytest.approx([tp, tr], abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(poses, st.tuples(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0)))
def test_commands_respect_range_and_ratings(pose, ref):
    ctl = _at(pose)
    f = ctl.command(ref)
    lim = JointLimits()
    assert PLO <= ctl.theta_ref[0] <= PHI and RLO <= ctl.theta_ref[1] <= RHI
    assert all(abs(t) <= m + 1e-9 for t, m in zip(ctl.tau_cmd, lim.torque_nm, strict=True))
    assert all(abs(x) <= lim.force_n for x in f)


@settings(max_examples=40, deadline=None)
@given(poses)
def test_holding_the_pose_commands_the_gravity_torque(pose):
    """At rest on its reference, the loop asks for -dV/dtheta of the link (finite
    differences of V = -m g c cos(theta_p) cos(theta_r)) and no more."""
    ctl = _at(pose)
    f = ctl.command(pose)
    mgc = GravityModel().mgc_nm
    h = 1e-6

    def v(tp: float, tr: float) -> float:
        return -mgc * math.cos(tp) * math.cos(tr)

    tp, tr = pose
    grad = ((v(tp + h, tr) - v(tp - h, tr)) / (2 * h), (v(tp, tr + h) - v(tp, tr - h)) / (2 * h))
    assert ctl.tau_cmd == pytest.approx([-grad[0], -grad[1]], abs=1e-6)
    assert ctl.kin.torque(*f) == pytest.approx(ctl.tau_cmd, abs=1e-6)
