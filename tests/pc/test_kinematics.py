"""The universal joint's cylinder <-> joint conversion against independent counterparts:
round trips, finite differences of the closed form, and 3-D statics of the rods."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.pc.geometry import UJointGeometry, hip_geometry, waist_geometry
from firmware_model.pc.kinematics import UJointKinematics
from firmware_model.pc.strain import piston_force, rod_force

GEOMETRIES = {"hip": hip_geometry(), "waist": waist_geometry()}


def _poses(geom: UJointGeometry):
    (plo, phi), (rlo, rhi) = geom.pitch_range_rad, geom.roll_range_rad
    return st.tuples(st.floats(plo, phi), st.floats(rlo, rhi))


forces = st.floats(-1500.0, 1500.0)


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _points(geom: UJointGeometry, tp: float, tr: float) -> np.ndarray:
    """p_i by matrix products (Eq. 6.1), independent of the kernel's expanded form."""
    rot = (_rot_x(-tr) @ _rot_y(-tp) if geom.guides_on_child else _rot_y(tp) @ _rot_x(tr))
    return np.array([rot @ np.array(p) for p in geom.p0])


@pytest.mark.parametrize("name", GEOMETRIES)
def test_forward_inverts_inverse_over_the_range(name):
    geom = GEOMETRIES[name]

    @settings(max_examples=150, deadline=None)
    @given(_poses(geom))
    def check(pose):
        kin = UJointKinematics(geom)  # cold start: Newton from the middle of the range
        x = kin.inverse(*pose)
        theta = kin.forward(*x)
        assert theta == pytest.approx(pose, abs=1e-9)

    check()


@pytest.mark.parametrize("name", GEOMETRIES)
def test_rods_keep_their_length_on_their_guides(name):
    """Eq. 6.2 from the pose by matrix products: |p_i - z_i| = l with z_i on its guide."""
    geom = GEOMETRIES[name]

    @settings(max_examples=100, deadline=None)
    @given(_poses(geom))
    def check(pose):
        kin = UJointKinematics(geom)
        x = kin.inverse(*pose)
        for i, p in enumerate(_points(geom, *pose)):
            z = np.array([*geom.guide_xy[i], x[i] + geom.z_mid_m[i]])
            assert np.linalg.norm(p - z) == pytest.approx(geom.rod_length_m, rel=1e-12)

    check()


@pytest.mark.parametrize("name", GEOMETRIES)
def test_torque_is_virtual_work_of_the_pistons(name):
    """tau = G^T f (Eq. 6.4) against virtual work: tau_j dtheta_j = f . dz for a small
    joint move, dz from the inverse map by central differences."""
    geom = GEOMETRIES[name]
    h = 1e-6

    @settings(max_examples=100, deadline=None)
    @given(_poses(geom), forces, forces)
    def check(pose, f1, f2):
        kin = UJointKinematics(geom)
        kin.inverse(*pose)
        tau = kin.torque(f1, f2)
        f = np.array([f1, f2])
        for j in range(2):
            step = np.zeros(2)
            step[j] = h
            dz = kin.inverse(*(np.array(pose) + step)) - kin.inverse(*(np.array(pose) - step))
            assert tau[j] == pytest.approx(f @ dz / (2 * h), abs=1e-6 * 1500)

    check()


@pytest.mark.parametrize("name", GEOMETRIES)
def test_joint_motion_from_piston_motion_is_g_inverse(name):
    """Eq. 6.3: finite differences of the forward map (Newton) against G^-1."""
    geom = GEOMETRIES[name]
    h = 1e-7

    @settings(max_examples=60, deadline=None)
    @given(_poses(geom))
    def check(pose):
        kin = UJointKinematics(geom)
        x = kin.inverse(*pose)
        g_inv = np.linalg.inv(kin.G)
        for j in range(2):
            step = np.zeros(2)
            step[j] = h
            d_theta = kin.forward(*(x + step)) - kin.forward(*(x - step))
            assert d_theta / (2 * h) == pytest.approx(g_inv[:, j], rel=1e-5, abs=1e-3)

    check()


@pytest.mark.parametrize("name", GEOMETRIES)
def test_forces_from_torque_invert_eq_6_4(name):
    geom = GEOMETRIES[name]

    @settings(max_examples=60, deadline=None)
    @given(_poses(geom), forces, forces)
    def check(pose, f1, f2):
        kin = UJointKinematics(geom)
        kin.inverse(*pose)
        assert kin.forces(*kin.torque(f1, f2)) == pytest.approx([f1, f2], abs=1e-6)

    check()


@pytest.mark.parametrize("name", GEOMETRIES)
def test_strain_gauge_force_against_rod_statics(name):
    """Eq. 6.5-6.6 against the rods in 3-D: a rod carries its gauge force along its axis,
    F_i = f_i^strain (p_i - z_i) / l. Its component along the guide is the piston force
    f_i, and the moments of F_i about the joint axes are the joint torques G^T f."""
    geom = GEOMETRIES[name]

    @settings(max_examples=100, deadline=None)
    @given(_poses(geom), forces, forces)
    def check(pose, s1, s2):
        tp, tr = pose
        kin = UJointKinematics(geom)
        x = kin.inverse(tp, tr)
        pts = _points(geom, tp, tr)
        moment = np.zeros(3)
        f = np.zeros(2)
        for i, s in enumerate((s1, s2)):
            z = np.array([*geom.guide_xy[i], x[i] + geom.z_mid_m[i]])
            axis = (pts[i] - z) / geom.rod_length_m
            rod = s * axis
            f[i] = rod[2]
            assert piston_force(kin.cos_alpha[i], s) == pytest.approx(f[i], abs=1e-9)
            assert rod_force(kin.cos_alpha[i], f[i]) == pytest.approx(s, abs=1e-9)
            moment += np.cross(pts[i], rod)
        # Joint axes in the guides' frame: the generalised force on theta_j is the moment
        # about the axis of rotation that moving theta_j turns p about, d p / d theta_j =
        # w_j x p.
        if geom.guides_on_child:
            w_roll = np.array([-1.0, 0.0, 0.0])
            w_pitch = _rot_x(-tr) @ np.array([0.0, -1.0, 0.0])
        else:
            w_pitch = np.array([0.0, 1.0, 0.0])
            w_roll = _rot_y(tp) @ np.array([1.0, 0.0, 0.0])
        tau = kin.torque(*f)
        assert tau[0] == pytest.approx(moment @ w_pitch, abs=1e-6)
        assert tau[1] == pytest.approx(moment @ w_roll, abs=1e-6)

    check()


def test_thesis_torques_from_the_derived_geometry():
    """The geometry's derivation, checked through the kinematics: 2 x 1500 N give the
    roll torque at theta = 0 and the pitch torque at its peak over the pitch range."""
    geom = hip_geometry()
    kin = UJointKinematics(geom)
    kin.inverse(0.0, 0.0)
    roll = abs(kin.torque(1500.0, -1500.0)[1])
    pitch = 0.0
    for a in np.linspace(*geom.pitch_range_rad, 237):
        kin.inverse(a, 0.0)
        pitch = max(pitch, abs(kin.torque(1500.0, 1500.0)[0]))
    assert roll == pytest.approx(135.0, rel=1e-3)
    assert pitch == pytest.approx(80.0, rel=1e-3)


def test_outside_the_workspace_is_a_clear_error():
    # A 10 mm rod cannot span the 13 mm the spherical joint swings off its guide by at the
    # end of the pitch range.
    with pytest.raises(ValueError, match="cannot reach"):
        UJointKinematics(hip_geometry(rod_length_m=0.010)).inverse(math.radians(-13.0), 0.0)
    kin = UJointKinematics(hip_geometry())
    with pytest.raises(ValueError, match="no joint angle"):
        kin.forward(1.0, -1.0)
