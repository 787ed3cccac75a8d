"""The arrays of many actuators' stacks as named bundles, one row per actuator: what the
robot engine's compiled kernel (:func:`hil.sim.robot.advance_robot`) takes instead of a
long list of positional arrays. numba passes a :class:`typing.NamedTuple` of arrays as a
tuple: a field read is a static index, resolved when the kernel is compiled."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class PlantRows(NamedTuple):
    """The plants' arrays, one row per actuator (:class:`plant.model.Plant`)."""
    x: np.ndarray       #: state
    params: np.ndarray  #: parameters
    u: np.ndarray       #: inputs (drive mode, duties)
    y: np.ndarray       #: outputs
    rng: np.ndarray     #: noise generators' states
    work: np.ndarray    #: the integrator's scratch


class SensorRows(NamedTuple):
    """The sensor chips' parameters and the raw words they gave the board this tick."""
    chips: np.ndarray
    raw: np.ndarray


class BoardRows(NamedTuple):
    """The driver boards (:class:`firmware_model.fpga.driver_board.DriverBoard`)."""
    params: np.ndarray
    state: np.ndarray
    down: np.ndarray  #: downstream memory (what the MCU sent)
    up: np.ndarray    #: upstream memory (what the board sends)


class LinkRows(NamedTuple):
    """The LVDS links: the MCU side's memories and the link's own state."""
    mcu_down: np.ndarray
    mcu_up: np.ndarray
    state: np.ndarray


class StackRows(NamedTuple):
    """Every array one actuator's stack below the MCU works on (:func:`advance_stack`), one
    row per actuator. A tuple of arrays to numba: the kernel reads the fields by name at
    no cost once compiled."""
    plant: PlantRows
    sensors: SensorRows
    board: BoardRows
    link: LinkRows


class McuRows(NamedTuple):
    """The MCU programs' records, one row per actuator."""
    ptrs: np.ndarray   #: addresses of its state, input and output record
    in16: np.ndarray   #: input records as 16-bit words
    in32: np.ndarray   #: input records as 32-bit words
    out16: np.ndarray  #: output records as 16-bit words
    err: np.ndarray    #: link error counts the program read at its last step


class TapRows(NamedTuple):
    """What the robot engine's kernel copies out for a frame log, per actuator and MCU step
    (row ``r = row[0] + n`` for the call's ``n``-th MCU period): ``up[i, r]`` the 32
    upstream words the MCU program read at the step and, last, the link's upstream
    CRC-error count it read with them as a u32 in two words, low half first (uint16,
    (actuators, rows, 34): the frame log's ``eha-hil/mcu-up``); ``down[i, r]`` the
    16 downstream words it wrote (uint16, (actuators, rows, 16)); ``trace[i, r * period:
    (r + 1) * period]`` the driver board's trace of the period's ticks
    (:data:`hil.sim.actuator.TRACE_WIDTH` int64 columns). Rows 0 (``up.shape[1] == 0``):
    nothing is copied; ``trace`` with no rows: no trace."""
    up: np.ndarray
    down: np.ndarray
    trace: np.ndarray
    row: np.ndarray  #: (1,) int64: the row of the call's first MCU step


class ImageRows(NamedTuple):
    """What the robot engine's compiled :func:`~hil.sim.robot.give_inputs` copies out for
    a frame log at the end of each fieldbus cycle, into row ``at[0]`` (then moved on; no
    copy once it reaches the rows' end): ``out`` the output image the cycle's compute took
    (uint8, (cycles, output bytes)), ``got`` which actuators' boxes had sent theirs (bool,
    (cycles, actuators)), ``inp`` the input image it gave back (uint8, (cycles, input
    bytes)), ``t_out``/``t_in`` the ticks of the take and of the end (int64, (cycles,)).
    The tap's ``row`` (:class:`TapRows`) moves on by the cycle's MCU steps with it. Rows 0:
    nothing is copied."""
    out: np.ndarray
    got: np.ndarray
    inp: np.ndarray
    t_out: np.ndarray
    t_in: np.ndarray
    at: np.ndarray  #: (1,) int64: the row the next cycle's images go to


class LinkSensorLanes(NamedTuple):
    """One compute thread's lane buffers (:func:`hil.sim.robot.advance_robot_lanes`): the
    LVDS links' counters and word logs of the batch it holds
    (:func:`firmware_model.lvds.lanes.link_lane_buffer`) and its sensor chips' parameters
    and codes (:func:`plant.sensors.lanes.sensor_lane_buffer`), and its MCU programs' states
    (:meth:`hil.sim.mcu_builds.HostLaw.lane_buffer`: the C law's ``mcu_lanes``)."""
    link: np.ndarray
    chips: np.ndarray
    mcu: np.ndarray


#: Where each field of :class:`StackRows` lives on an :class:`~hil.sim.actuator.FpgaStack`:
#: (object path, attribute), in the bundles' field order.
SOURCES = (
    (PlantRows, (("plant", "x"), ("plant", "params"), ("plant", "u"), ("plant", "y"),
                 ("plant", "rng"), ("plant", "_work"))),
    (SensorRows, (("", "chips"), ("", "raw"))),
    (BoardRows, (("board", "params"), ("board", "state"), ("board", "down"),
                 ("board", "up"))),
    (LinkRows, (("mcu_link", "down"), ("mcu_link", "up"), ("", "link"))),
)


__all__ = ["SOURCES", "BoardRows", "LinkRows", "LinkSensorLanes", "McuRows", "PlantRows",
           "SensorRows", "StackRows", "TapRows", "ImageRows"]
