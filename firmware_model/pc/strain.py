"""Cylinder force from the strain gauge on the connecting rod (thesis 6.2.1, Eq. 6.5-6.6).

The rod is not coaxial with the piston: it leans by alpha_i from the guide, so the gauge
force f_i^strain (along the rod) holds the guide's constraint force besides the piston's.
Along the guide only f_i = cos(alpha_i) f_i^strain acts, with cos(alpha_i) =
(p_iz - z_iz) / l, from the solved pose (:mod:`firmware_model.pc.kinematics`).
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def piston_force(cos_alpha: float, f_strain: float) -> float:
    """f_i = cos(alpha_i) f_i^strain (Eq. 6.5), N."""
    return cos_alpha * f_strain


@njit(cache=True)
def rod_force(cos_alpha: float, f_piston: float) -> float:
    """The gauge force along the rod that carries the piston force f_i, N (inverse of 6.5)."""
    return f_piston / cos_alpha
