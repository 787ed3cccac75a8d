"""The thigh's coupling to the cylinders against the linearised joint: with the pistons
held, the thigh swings on the rods' stiffness at sqrt((k G^T G + m g c) / I)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_model.pc.geometry import hip_geometry
from firmware_model.pc.kinematics import UJointKinematics
from plant import layout as L
from plant.hip.thigh import (
    GRAVITY,
    H_I_PITCH,
    H_MGC,
    J_CA1,
    J_CA2,
    J_TP,
    N_J,
    LegBelow,
    ThighParams,
    couple_tick,
    place_anchors,
    set_pose,
)

K_ROD = 2.0e6
DT = 50e-6


def _held_pistons_swing(theta0: float, kick: float, ticks: int,
                        leg: LegBelow | None = None) -> np.ndarray:
    geom = hip_geometry()
    g = geom.as_array()
    thigh = ThighParams(damping_nms_per_rad=0.0, leg=leg)
    h = thigh.as_array()
    kin = UJointKinematics(geom)
    x_c = kin.inverse(theta0, 0.0)             # pistons held where the rods end at theta0
    js = np.zeros(N_J)
    set_pose(g, js, theta0 + kick, 0.0, 0.0, 0.0)
    p = [np.zeros(L.N_PARAMS) for _ in range(2)]
    y = [np.zeros(L.N_OUTPUTS) for _ in range(2)]
    for q in p:
        q[L.P_K_ROD] = K_ROD
    place_anchors(js, p[0], p[1])
    out = np.empty(ticks)
    for t in range(ticks):
        for i in range(2):  # the plant's conrod force with the piston still (v_c = 0)
            y[i][L.Y_F_ROD] = K_ROD * (x_c[i] - p[i][L.P_X_ANCHOR])
            y[i][L.Y_F_STRAIN] = y[i][L.Y_F_ROD]
        couple_tick(g, h, js, DT, p[0], y[0], p[1], y[1])
        out[t] = js[J_TP]
        assert y[0][L.Y_F_STRAIN] == pytest.approx(y[0][L.Y_F_ROD] / js[J_CA1])
        assert y[1][L.Y_F_STRAIN] == pytest.approx(y[1][L.Y_F_ROD] / js[J_CA2])
    return out


@pytest.mark.parametrize("theta0_deg", [0.0, 40.0])
def test_thigh_swings_at_the_linearised_frequency(theta0_deg):
    theta0 = math.radians(theta0_deg)
    thigh = ThighParams()
    kin = UJointKinematics(hip_geometry())
    kin.inverse(theta0, 0.0)
    gp = kin.G[:, 0]
    stiff = K_ROD * float(gp @ gp) + thigh.mass_kg * 9.80665 * thigh.com_m * math.cos(theta0)
    f_lin = math.sqrt(stiff / thigh.inertia()) / (2 * math.pi)
    ticks = int(4.0 / f_lin / DT)
    swing = _held_pistons_swing(theta0, math.radians(0.05), ticks)
    # Equilibrium: gravity sags the thigh a little off theta0; swing about the mean.
    s = swing - swing.mean()
    up = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    f_sim = (len(up) - 1) / ((up[-1] - up[0]) * DT)
    assert f_sim == pytest.approx(f_lin, rel=0.01)


def test_the_leg_below_swings_with_the_thigh():
    """With the servo-on leg (rigid below the thigh), the held-piston swing is at
    sqrt((k G^T G + (m c)_total g) / I_total), the leg's share from Table 6.1's masses."""
    leg = LegBelow()
    thigh = ThighParams(leg=leg)
    kin = UJointKinematics(hip_geometry())
    kin.inverse(0.0, 0.0)
    gp = kin.G[:, 0]
    mc = thigh.mass_kg * thigh.com_m + leg.shank_kg * (leg.knee_m + leg.shank_com_m) \
        + leg.foot_kg * (leg.knee_m + leg.ankle_m + leg.foot_com_m)
    assert thigh.as_array()[H_MGC] == pytest.approx(mc * 9.80665, rel=1e-12)
    stiff = K_ROD * float(gp @ gp) + mc * 9.80665
    f_lin = math.sqrt(stiff / thigh.inertia()) / (2 * math.pi)
    swing = _held_pistons_swing(0.0, math.radians(0.05), int(4.0 / f_lin / DT), leg)
    s = swing - swing.mean()
    up = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    f_sim = (len(up) - 1) / ((up[-1] - up[0]) * DT)
    assert f_sim == pytest.approx(f_lin, rel=0.01)
    assert thigh.inertia() > 10 * ThighParams().inertia()  # the leg dominates the load


def test_without_the_leg_the_load_is_the_old_arithmetic():
    t = ThighParams()
    h = t.as_array()
    assert h[H_I_PITCH] == t.mass_kg * (t.com_m ** 2 + t.gyration_m ** 2)
    assert h[H_MGC] == t.mass_kg * GRAVITY * t.com_m
