"""The PC's joint loop: limits, saturation, gravity model and the torque layer's round
trip through the rods' gauges."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.pc.geometry import hip_geometry
from firmware_model.pc.joint_loop import (
    GravityModel,
    JointController,
    JointLimits,
    reference_acceleration,
)
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


@settings(max_examples=40, deadline=None)
@given(st.floats(1.0, 80.0), st.floats(0.002, 1.0), st.floats(0.005, 0.5))
def test_reference_acceleration_of_a_sine(f_hz, t, amp_deg):
    """The PC's second difference of its planned sine agrees with the analytic -A w^2
    sin(w t), to the O(w^2 h^2) error of central differences."""
    w, a = 2 * math.pi * f_hz, math.radians(amp_deg)

    def ref(s: float) -> tuple[float, float]:
        return a * math.sin(w * (s + 0.01)), -a * math.cos(w * (s + 0.01))

    acc = reference_acceleration(ref, t, 1e-3)
    exact = (-a * w * w * math.sin(w * (t + 0.01)), a * w * w * math.cos(w * (t + 0.01)))
    tol = a * w * w * (w * 1e-3) ** 2 / 12 * 1.01 + 1e-9
    assert acc == pytest.approx(exact, abs=tol)


def test_feed_forward_is_the_thigh_inertia_the_plant_assumes():
    """The PC's own I_hat (from its figures for the thigh) is the plant thigh's inertia
    about the joint, so its inverse dynamics cancel the rigid thigh's I theta_ddot."""
    from plant.hip.thigh import ThighParams

    inertia = ThighParams().inertia()
    assert GravityModel().feed_forward((2.0, -3.0)) == pytest.approx(
        (2.0 * inertia, -3.0 * inertia), rel=1e-12)
    assert GravityModel().mgc_nm == pytest.approx(
        ThighParams().mass_kg * 9.80665 * ThighParams().com_m, rel=1e-12)
