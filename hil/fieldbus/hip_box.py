"""The hip box: one MCU board over the two EHAs of Hydra's hip universal joint, whose
pistons drive the thigh (:mod:`plant.hip.thigh`) through their connecting rods.

Like :class:`~hil.fieldbus.boxes.StackBox` (MCU at its period, value-level stacks between),
but the two stacks advance tick by tick together in one compiled loop, with the joint
coupled after every tick (:func:`advance_hip`), so the rods' forces and the thigh's motion
are exchanged at the plant's 20 kHz.

The joint is configured by :data:`HIP_OPTIONS` set on the configuration's ``load`` table
(``load.kind`` must be ``conrod``; the stiffness is the rod path's, thesis 5.4).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_model.lvds import link as LK
from firmware_model.pc.geometry import hip_geometry
from hil.fieldbus.boxes import StackBox
from hil.fieldbus.topology import Box
from hil.sim.actuator import advance_stack
from plant.config import Config, ConfigError
from plant.hip.thigh import (
    N_J,
    ThighParams,
    couple_tick,
    place_anchors,
    place_pistons,
    set_pose,
)


@njit(cache=True)
def advance_hip(n_ticks, dt, g, h, js,
                x1, p1, u1, y1, rec1, tick1, rng1, work1, k1, raw1, c1, st1, dn1, up1,
                md1, mu1, lk1, tr1,
                x2, p2, u2, y2, rec2, tick2, rng2, work2, k2, raw2, c2, st2, dn2, up2,
                md2, mu2, lk2, tr2):
    """``n_ticks`` ticks of both stacks, the joint coupled after each."""
    for j in range(n_ticks):
        advance_stack(1, x1, p1, u1, y1, rec1, 0, 1, tick1 + j, rng1, work1, k1, raw1, c1,
                      st1, dn1, up1, md1, mu1, lk1, tr1)
        advance_stack(1, x2, p2, u2, y2, rec2, 0, 1, tick2 + j, rng2, work2, k2, raw2, c2,
                      st2, dn2, up2, md2, mu2, lk2, tr2)
        couple_tick(g, h, js, dt, p1, y1, p2, y2)


class HipBox(StackBox):
    """A box of two actuator slots: the hip's two cylinders, coupled by the thigh."""

    def __init__(self, box: Box, cfg: Config, thigh: ThighParams | None = None,
                 theta0: tuple[float, float] = (0.0, 0.0)) -> None:
        if len(box.actuators) != 2:
            raise ConfigError(f"box {box.id}: the hip box model needs exactly two actuator "
                              f"slots, not {len(box.actuators)}")
        if cfg.get("load.kind") != "conrod":
            cfg = cfg.with_overrides({"load.kind": "conrod"}, "hip box")
        super().__init__(box, cfg)
        self.geometry = hip_geometry()
        self.g = self.geometry.as_array()
        self.thigh = thigh or ThighParams()
        self.h = self.thigh.as_array()
        self.joint = np.zeros(N_J)
        self.dt = self.tick_s
        self.set_pose(*theta0)

    def set_pose(self, theta_p: float, theta_r: float) -> None:
        """Put the joint (at rest) and both pistons at the pose, rods unloaded."""
        if not set_pose(self.g, self.joint, theta_p, theta_r, 0.0, 0.0):
            raise ValueError(f"hip pose ({math.degrees(theta_p):.1f}, "
                             f"{math.degrees(theta_r):.1f}) deg is outside the workspace")
        place_pistons(self.joint, self.stacks[0].plant.x, self.stacks[1].plant.x)
        place_anchors(self.joint, self.stacks[0].plant.params, self.stacks[1].plant.params)

    def _advance_stacks(self, n_ticks: int) -> None:
        a, b = self.stacks
        args = []
        for s in (a, b):
            pl, bd = s.plant, s.board
            args += [pl.x, pl.params, pl.u, pl.y, s._no_rec, pl.tick, pl.rng, pl._work,
                     s.chips, s.raw, bd.params, bd.state, bd.down, bd.up, s.mcu_link.down,
                     s.mcu_link.up, s.link, s._no_trace]
        advance_hip(n_ticks, self.dt, self.g, self.h, self.joint, *args)
        for s in (a, b):
            s.plant.tick += n_ticks
            s.mcu_link.up_crc_errors = int(s.link[LK.LK_MASTER_CRC])
