"""Geometry of a two-DoF universal joint driven by two linear EHAs (thesis 6.2.1, Fig. 6.2).

The universal joint sits at the origin: pitch about y, roll about x (theta = [theta_p,
theta_r]). Each connecting rod (length l) joins a spherical joint p_i to the slider
z_i = [z_i0x, z_i0y, z_iz] that runs on a linear guide parallel to z; the piston drives
the slider. Coordinates are those of the link that carries the guides.

Two arrangements (``guides_on_child``):

* guides on the parent link, as Fig. 6.2 draws it: p_i = R_y(theta_p) R_x(theta_r) p_i0
  (Eq. 6.1). The roll arm of this form is p_i0y cos(theta_p): it vanishes at theta_p =
  90 deg, so a joint with pitch beyond ~80 deg cannot be built this way;
* guides on the child link, as on Hydra's hip, whose cylinders are on the thigh (Fig. 6.5):
  seen from the thigh, the intermediate link turns by the inverse rotation,
  p_i = R_x(-theta_r) R_y(-theta_p) p_i0, the same Eq. 6.1 with the links' roles swapped.
  The roll arm is then -p_iy whatever the pitch: no singular point over -13..+105 deg.

The thesis gives torques and ranges, not dimensions. :func:`ujoint_geometry` derives them
(docs/hip.md, "Geometry"):

* roll arm: the rods sit at y = +/-d. At theta = 0 each cylinder's roll moment arm is d, so
  the roll torque with 2 x 1500 N gives d (hip: 135 Nm -> 45 mm);
* pitch arm: p_i is at distance r from the pitch axis in the xz plane. Its moment arm is
  r cos(theta_p - theta_m), largest at theta_m, where p_i is level with the axis. The pitch
  torque with 2 x 1500 N is read as that peak (hip: 80 Nm -> r = 26.7 mm) and theta_m is
  the middle of the pitch range (hip: 46 deg), which keeps the arm >= r cos 59 deg =
  13.7 mm and the pitch stroke at 2 r sin 59 deg = 46 mm, within the cylinder's 50 mm;
* guides at x = r, y = +/-d: under p_i at theta = (theta_m, 0), where the rods stand
  vertical and the pistons are at mid-stroke;
* rod length l = 120 mm: an assumption (Fig. 6.5's proportions); it sets the rod tilt
  alpha (cos alpha >= 0.95 over the range) and so the difference of Eq. 6.5 from a lever.

Not every corner of the range box fits the 50 mm stroke (roll adds +/- d sin 22.5 deg =
17 mm of opposite stroke): the thesis's ranges are read as per axis.

Compiled code takes a geometry packed into float64[N_GEOM] at the G_* indices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Indices of the packed geometry (float64 array) the compiled kernels take.
(G_P10X, G_P10Y, G_P10Z, G_P20X, G_P20Y, G_P20Z,
 G_Z10X, G_Z10Y, G_Z20X, G_Z20Y, G_L, G_ZMID1, G_ZMID2, G_ON_CHILD) = range(14)
N_GEOM = 14


@dataclass(frozen=True)
class UJointGeometry:
    """Mechanical constants of one universal joint (m, rad)."""

    p0: tuple[tuple[float, float, float], tuple[float, float, float]]  # p_i0
    guide_xy: tuple[tuple[float, float], tuple[float, float]]          # (z_i0x, z_i0y)
    rod_length_m: float                                                # l
    #: Slider height z_iz at the piston's mid-stroke (x_piston = z_iz - z_mid_i).
    z_mid_m: tuple[float, float]
    pitch_range_rad: tuple[float, float]
    roll_range_rad: tuple[float, float]
    guides_on_child: bool

    def as_array(self) -> np.ndarray:
        """The geometry packed at the G_* indices."""
        g = np.zeros(N_GEOM)
        g[G_P10X:G_P10Z + 1] = self.p0[0]
        g[G_P20X:G_P20Z + 1] = self.p0[1]
        g[G_Z10X], g[G_Z10Y] = self.guide_xy[0]
        g[G_Z20X], g[G_Z20Y] = self.guide_xy[1]
        g[G_L] = self.rod_length_m
        g[G_ZMID1], g[G_ZMID2] = self.z_mid_m
        g[G_ON_CHILD] = 1.0 if self.guides_on_child else 0.0
        return g


#: Thesis 6.2.2 / Table 6.1: the hip's pitch and roll ranges and torques at 1500 N.
HIP_PITCH_RANGE_DEG = (-13.0, 105.0)
HIP_ROLL_RANGE_DEG = (-22.5, 22.5)
HIP_PITCH_TORQUE_NM = 80.0
HIP_ROLL_TORQUE_NM = 135.0
CYLINDER_FORCE_N = 1500.0
#: Assumption (no figure in the thesis): the connecting rod's length.
ROD_LENGTH_M = 0.120


def ujoint_geometry(pitch_torque_nm: float, roll_torque_nm: float,
                    pitch_range_deg: tuple[float, float],
                    roll_range_deg: tuple[float, float], guides_on_child: bool,
                    rod_length_m: float = ROD_LENGTH_M) -> UJointGeometry:
    """A joint's dimensions from its torques at 1500 N per cylinder and its ranges."""
    d = roll_torque_nm / (2.0 * CYLINDER_FORCE_N)
    r = pitch_torque_nm / (2.0 * CYLINDER_FORCE_N)
    lo, hi = (math.radians(a) for a in pitch_range_deg)
    tm = 0.5 * (lo + hi)
    c, s = math.cos(tm), math.sin(tm)
    if guides_on_child:
        # p at theta_m is R_y(-theta_m) p0 = (r, +/-d, 0)  =>  p0 = R_y(theta_m) (r, y, 0).
        p0 = ((c * r, d, -s * r), (c * r, -d, -s * r))
    else:
        # p at theta_m is R_y(theta_m) p0 = (r, +/-d, 0)  =>  p0 = R_y(-theta_m) (r, y, 0).
        p0 = ((c * r, d, s * r), (c * r, -d, s * r))
    guide = ((r, d), (r, -d))
    roll = tuple(math.radians(a) for a in roll_range_deg)
    return UJointGeometry(p0, guide, rod_length_m, (-rod_length_m, -rod_length_m),
                          (lo, hi), roll, guides_on_child)


def hip_geometry(rod_length_m: float = ROD_LENGTH_M) -> UJointGeometry:
    """Hydra's hip pitch/roll joint (cylinders on the thigh)."""
    return ujoint_geometry(HIP_PITCH_TORQUE_NM, HIP_ROLL_TORQUE_NM, HIP_PITCH_RANGE_DEG,
                           HIP_ROLL_RANGE_DEG, True, rod_length_m)


def waist_geometry(rod_length_m: float = ROD_LENGTH_M) -> UJointGeometry:
    """Hydra's waist (thesis 6.2.2: 94 / 147 Nm, -20..+60 / +/-22.5 deg), guides on the
    parent as Fig. 6.2 draws them (its cylinders' tilt is not modelled)."""
    return ujoint_geometry(94.0, 147.0, (-20.0, 60.0), (-22.5, 22.5), False, rod_length_m)
