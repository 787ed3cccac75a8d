"""The hip joint through the whole stack: the PC's joint loop at 1 kHz on the fieldbus
master -> process image -> the hip box (MCU at 5 kHz, two driver boards at 20 kHz, two
EHA plants coupled by the thigh) -> and back, in lockstep (:class:`hil.fieldbus.system.
BusSystem`, in-process transport).

:func:`run_joint` drives the joint with a reference theta_ref(t) and records, per cycle,
what the PC commanded and measured. The PC reads the inputs of the previous cycle, as the
real master does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from firmware_model.pc.joint_loop import JointController, JointGains, reference_acceleration
from hil.fieldbus.system import BusSystem
from hil.fieldbus.topology import load_topology
from plant.config import Config
from plant.hip.thigh import ThighParams

#: Cycles at the start with zero force commands, while the first inputs arrive.
START_CYCLES = 5
#: theta_ref(t_s) -> (theta_p, theta_r), rad.
Reference = Callable[[float], tuple[float, float]]


@dataclass
class JointRecord:
    """Per PC cycle (1 kHz): time, reference, measured angle, commanded and measured torque."""

    t: np.ndarray           # s
    theta_ref: np.ndarray   # (n, 2) rad
    theta: np.ndarray       # (n, 2) rad, from the pistons (forward kinematics)
    tau_cmd: np.ndarray     # (n, 2) Nm
    tau: np.ndarray         # (n, 2) Nm, from the rods' gauges (Eq. 6.4-6.6)
    theta_true: np.ndarray  # (n, 2) rad, the thigh's angle in the plant (truth)


def hip_config(cfg: Config, reinforced: bool, rod_damping_ns_per_m: float | None = None,
               rod_stiffness_n_per_m: float | None = None) -> Config:
    """The configuration for the hip's cylinders: their rod path's stiffness is
    ``rod_stiffness_n_per_m`` for the reinforced structure (divided by
    ``load.beam_reinforcement_ratio`` without it) or, when None, the testbed beam's
    (thesis 5.4; calibrated on F6), reinforced or not; its damping the configuration's
    unless given."""
    ratio = cfg.get("load.beam_reinforcement_ratio")
    if rod_stiffness_n_per_m is not None:
        k = rod_stiffness_n_per_m if reinforced else rod_stiffness_n_per_m / ratio
    else:
        k = cfg.get("load.beam_axial_stiffness_n_per_m")
        if reinforced:
            k *= ratio
    over = {"load.kind": "conrod", "load.conrod_stiffness_n_per_m": k, "mcu.impl": "python"}
    if rod_damping_ns_per_m is not None:
        over["load.conrod_damping_ns_per_m"] = rod_damping_ns_per_m
    return cfg.with_overrides(over,
                              "hip " + ("reinforced" if reinforced else "unreinforced"))


def run_joint(cfg: Config, seconds: float, reference: Reference,
              gains: JointGains | None = None, reinforced: bool = True,
              progress: Callable[[int, int], None] | None = None,
              rod_damping_ns_per_m: float | None = None,
              thigh: ThighParams | None = None, feed_forward: bool = False,
              rod_stiffness_n_per_m: float | None = None) -> JointRecord:
    """Run the joint stack for ``seconds`` under the position loop (``thigh``: the load's
    parameters, the box's default if None). ``feed_forward``: the PC adds the inverse
    dynamics of its planned reference, I_hat theta_ref_ddot, with the acceleration by
    central differences of the reference it generates (it plans one cycle ahead)."""
    cfg = hip_config(cfg, reinforced, rod_damping_ns_per_m, rod_stiffness_n_per_m)
    topo = load_topology("hip_one_box")
    cycles = int(round(seconds / 1e-3))
    rec = JointRecord(np.arange(cycles) * 1e-3, *(np.zeros((cycles, 2)) for _ in range(5)))
    with BusSystem(topo, cfg, "inproc", model="hip") as bus:
        box = bus.chain.boxes[0]
        if thigh is not None:
            box.thigh, box.h[:] = thigh, thigh.as_array()
        ctl = JointController(box.geometry, gains)

        def pc(cycle: int, master) -> None:  # noqa: ANN001 (hil.fieldbus.master.Master)
            a, b = master.actuator_inputs(0), master.actuator_inputs(1)
            ctl.measure((a["x_piston"], b["x_piston"]), (a["f_strain"], b["f_strain"]))
            t = cycle * 1e-3
            ff = (0.0, 0.0)
            if feed_forward:
                ff = ctl.gravity.feed_forward(reference_acceleration(reference, t, 1e-3))
            f = ctl.command(reference(t), ff)
            if cycle < START_CYCLES:  # no inputs yet: the boards boot, no force
                f = np.zeros(2)
            for j in range(2):
                master.set_actuator(j, "force", float(f[j]))
            rec.theta_ref[cycle] = ctl.theta_ref
            rec.theta[cycle] = ctl.theta
            rec.tau_cmd[cycle] = ctl.tau_cmd
            rec.tau[cycle] = ctl.tau
            rec.theta_true[cycle] = box.joint[:2]
            if progress and cycle % 250 == 0:
                progress(cycle, cycles)

        bus.run(cycles, pc)
    return rec
