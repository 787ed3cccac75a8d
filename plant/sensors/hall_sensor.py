"""The motor's hall sensors: the code of the electrical angle's 60-degree sector
(:data:`protocols.hall.SEQUENCE`), as three logic levels on the board's inputs."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.sensors.chips import K_HALL_OFFSET, K_POLE_PAIRS
from protocols import hall

HALL_SEQUENCE = np.asarray(hall.SEQUENCE, dtype=np.int64)


@njit(cache=True)
def hall_code(theta_m, k):
    x = (k[K_POLE_PAIRS] * theta_m - k[K_HALL_OFFSET]) / (math.pi / 3.0)
    return HALL_SEQUENCE[int(math.floor(x)) % 6]


def hall_levels(code: int) -> tuple[int, int, int]:
    """(Ha, Hb, Hc) logic levels of a hall code."""
    return (code >> 2) & 1, (code >> 1) & 1, code & 1
