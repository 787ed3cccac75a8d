"""Oil temperature, viscosity and the energy books.

``C dT/dt = P_loss - G (T - T_amb)`` (``effects.oil_temperature``); d_s, d_p, d_c scale with
``mu(T)/mu_ref = exp(-c (T - T_ref))``. The connecting rod's temperature (which drives the
strain gauge's drift) follows the ambient with a time constant. The energy states
integrate the power in (electrical at the terminals, or the ideal pump force's power), the
power dissipated (oil heat, load dampers, copper) and the external force's work, so that
E_in + E_ext = E_diss + E_stored closes.
"""

from __future__ import annotations

from numba import njit

from plant.blocks.lanemath import exp_r
from plant.layout import (
    IN_T_AMB,
    P_COOL_G,
    P_HEAT_CAP,
    P_NUMERICS,
    P_ROD_TAU,
    P_T_REF,
    P_TEMP_ON,
    P_VISC_COEFF,
    S_EDISS,
    S_EEXT,
    S_EIN,
    S_TOIL,
    S_TROD,
    DriveMode,
)


@njit(cache=True, inline="always")
def viscosity_ratio(p, t_oil):
    """mu(T)/mu(T_ref): 1 when the oil-temperature effect is off."""
    if p[P_TEMP_ON] > 0.5:
        return exp_r(-p[P_VISC_COEFF] * (t_oil - p[P_T_REF]), p[P_NUMERICS])
    return 1.0


@njit(cache=True, inline="always")
def energy_and_heat(x, p, u, dx, mode, heat_oil, tau_p, vp, p_elec, p_copper, loss_load,
                    p_ext):
    """Write the energy states' and the two temperatures' derivatives."""
    if mode == DriveMode.DUTY:
        dx[S_EIN] = p_elec
    else:
        dx[S_EIN] = tau_p * vp
    dx[S_EDISS] = heat_oil + loss_load + p_copper
    dx[S_EEXT] = p_ext
    t_amb = u[IN_T_AMB]
    if p[P_TEMP_ON] > 0.5:
        dx[S_TOIL] = (heat_oil - p[P_COOL_G] * (x[S_TOIL] - t_amb)) / p[P_HEAT_CAP]
    else:
        dx[S_TOIL] = 0.0
    dx[S_TROD] = (t_amb - x[S_TROD]) / p[P_ROD_TAU]
