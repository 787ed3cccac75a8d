"""Box models: what sits behind one EtherCAT slave (an MCU board and its driver boards).

* :class:`StackBox`: the real thing in simulation: the MCU board model over one value-level
  stack (plant + driver board + LVDS link) per actuator slot, at their real rates on the
  scheduler.
* :class:`EchoBox`: a cheap behavioural stand-in for bus-level work on the full robot
  (47 actuators): :class:`plant.echo_actuator.EchoActuators` (each actuator follows its
  command through a first-order lag and keeps the MCU's command watchdog, so timeouts and
  status words behave as the firmware's).

Both take the box's output record bytes once per fieldbus cycle (:meth:`apply`), give the
input record bytes (:meth:`inputs`) and advance by whole ticks (:meth:`advance`).
"""

from __future__ import annotations

import struct

import numpy as np

from firmware_model.mcu.board import McuBoard
from hil.fieldbus import pdo
from hil.fieldbus.topology import Box
from hil.sim.interfaces import BoardStack
from hil.sim.scheduler import Scheduler
from plant.config import Config, ConfigError
from plant.echo_actuator import EchoActuators


def _out_dtype(box: Box) -> np.dtype:
    fields = []
    for k, s in enumerate(box.slots):
        if s.sizes[0]:
            fields.append((f"s{k}", pdo.record_dtype(pdo.SLOT_FIELDS[s.kind][0])))
    return np.dtype(fields) if fields else np.dtype([])


def _in_dtype(box: Box) -> np.dtype:
    return np.dtype([(f"s{k}", pdo.record_dtype(pdo.SLOT_FIELDS[s.kind][1]))
                     for k, s in enumerate(box.slots)])


_I2_LO, _I2_HI = int(np.iinfo(np.int16).min), int(np.iinfo(np.int16).max)
_I4_LO, _I4_HI = pdo.I4_BOUNDS
_counts = pdo.saturated_counts


class _BoxBase:
    """Decoding of the box's outputs and packing of its inputs."""

    def __init__(self, box: Box, cfg: Config) -> None:
        self.box = box
        self.tick_s = cfg.get("sim.tick_ns") * 1e-9
        self.out_dtype = _out_dtype(box)
        self.in_dtype = _in_dtype(box)
        # The per-cycle path packs and unpacks with precompiled structs into one buffer:
        # numpy structured-record field access costs ~1 us a field.
        self._in_buf = bytearray(self.in_dtype.itemsize)
        self._in_off = {k: self.in_dtype.fields[f"s{k}"][1] for k in box.actuators}
        self._out_off = {k: self.out_dtype.fields[f"s{k}"][1] for k in box.actuators}
        self.tick = 0
        #: Per actuator slot: last decoded (mode, value SI, flags, kp_position, kp_force).
        self.act = box.actuators
        self.cycle_ticks = 20

    def decode(self, data: bytes) -> list[tuple[str, float, int, float, float]]:
        out = []
        for k in self.act:
            mode_code, flags, command, kpos, kpf = _OUT.unpack_from(data, self._out_off[k])
            mode = pdo.MODE_NAMES.get(mode_code, "off")
            lsb = pdo.POSITION_CMD_LSB if mode == "position" else pdo.FORCE_CMD_LSB
            out.append((mode, command * lsb, flags, kpos * 10.0, kpf * 1e-3))
        return out

    def inputs(self) -> bytes:
        """The box's input record as it stands now."""
        return bytes(self._in_buf)

    def _pack_actuator(self, k: int, x: float, v: float, f_pres: float, f_strain: float,
                       f_fil: float, iq: float, temp: float, status: int, err_down: int,
                       err_up: int) -> None:
        lo, hi = _I2_LO, _I2_HI
        _IN.pack_into(self._in_buf, self._in_off[k],
                      _counts(x, 1e-9, _I4_LO, _I4_HI), _counts(v, 1e-5, lo, hi),
                      _counts(f_pres, 0.1, lo, hi), _counts(f_strain, 0.1, lo, hi),
                      _counts(f_fil, 0.1, lo, hi), _counts(iq, 1e-3, lo, hi),
                      _counts(temp, 0.01, lo, hi), status & 0xFFFF, min(err_down, 0xFFFF),
                      min(err_up, 0xFFFF))


#: Struct layouts equal to the pdo declarations (checked at import below).
_OUT = struct.Struct("<" + "".join({"u1": "B", "u2": "H", "i2": "h", "i4": "i"}[f.dtype]
                                   for f in pdo.ACTUATOR_OUT))
_IN = struct.Struct("<" + "".join({"u1": "B", "u2": "H", "i2": "h", "i4": "i"}[f.dtype]
                                  for f in pdo.ACTUATOR_IN))
assert _OUT.size == pdo.ACTUATOR_OUT_DTYPE.itemsize and _IN.size == pdo.ACTUATOR_IN_DTYPE.itemsize
assert [f.name for f in pdo.ACTUATOR_IN][:3] == ["x_piston", "v_piston", "f_pressure"]


class _Stacks:
    """The box's value-level stacks as one plant-like block for the scheduler (every stack
    advanced over the same ticks; ``box.stacks`` may be wrapped in place, e.g. by faults)."""

    def __init__(self, box: StackBox, tick_ns: int) -> None:
        self.box = box
        self.tick_ns = tick_ns
        self.tick = 0

    def advance(self, n_ticks: int, rec: np.ndarray | None = None, row0: int = 0,
                every: int = 1) -> int:
        self.box._advance_stacks(n_ticks)
        self.tick += n_ticks
        return row0


class McuBox(_BoxBase):
    """A box's MCU board (:class:`~firmware_model.mcu.board.McuBoard`) over the given LVDS
    link memories: the process data in and out. :class:`StackBox` puts driver boards and
    plants behind the links; the replay (:mod:`hil.replay.replay`) feeds them from a log."""

    def __init__(self, box: Box, cfg: Config, links: list, offsets: list[int]) -> None:
        super().__init__(box, cfg)
        if cfg.get("mcu.impl") != "python":
            raise ConfigError(f"mcu.impl = {cfg.get('mcu.impl')!r} runs in the "
                              "single-actuator stack only; the fieldbus boxes run the Python "
                              "MCU (mcu.impl = 'python')")
        self.board = McuBoard(cfg, links, offsets) if links else None
        self.mcu = self.board.mcu if self.board else None
        self.period = cfg.get("mcu.period_ticks")

    def apply(self, data: bytes) -> None:
        """Outputs of this cycle: commands, enable edges, gains."""
        if self.board is None:
            return
        for i, (mode, value, flags, kpos, kpf) in enumerate(self.decode(data)):
            self.board.apply(i, mode, value, bool(flags & pdo.FLAG_ENABLE),
                             bool(flags & pdo.FLAG_CLEAR_FAULT), kpos, kpf, self.tick)

    def _fill(self, ticks: int = 0) -> None:
        if self.board is None:
            return
        for i, k in enumerate(self.act):
            r = self.board.report(i, ticks)
            self._pack_actuator(k, r.x_piston, r.v_piston, r.f_pressure, r.f_strain,
                                r.f_filtered, r.iq, r.temperature_c, r.status,
                                r.link_errors_down, r.link_errors_up)


class StackBox(McuBox):
    """The MCU board over one value-level stack (:class:`~hil.sim.actuator.FpgaStack`) per
    actuator slot, on the scheduler: the MCU every ``mcu.period_ticks``, the stacks
    between."""

    def __init__(self, box: Box, cfg: Config) -> None:
        from hil.sim.actuator import FpgaStack

        if cfg.get("fpga.impl") != "python":
            raise ConfigError("fpga.impl = 'rtl' runs in the single-actuator stack only; the "
                              "fieldbus boxes run the board's own loop (fpga.impl = 'python')")
        self.stacks: list[BoardStack] = [FpgaStack(cfg) for _ in box.actuators]
        super().__init__(box, cfg, [s.mcu_link for s in self.stacks],
                         [s.board.calibrated_offset for s in self.stacks])
        #: The whole-robot engine that advances this box with all others (hil.sim.robot);
        #: None on the per-actuator path.
        self.engine = None
        self._group = _Stacks(self, cfg.get("sim.tick_ns"))
        self.sched = Scheduler(self._group, record_every=0)
        if self.board is not None:
            self.sched.every(self.period, self._mcu_step, "mcu")
        self._fill()

    def apply(self, data: bytes) -> None:
        """Outputs of this cycle (kept for the engine to decode with every box's, if any)."""
        if self.engine is not None:
            self.engine.applied(self, data)
            return
        super().apply(data)

    def advance(self, ticks: int) -> None:
        """``ticks`` ticks on the scheduler (the MCU at its period, the stacks between)."""
        if self.engine is not None:
            raise RuntimeError("this box is advanced by its robot engine, with every box")
        self._group.tick = self.tick
        self.sched.run(ticks)
        self.tick = self._group.tick
        self._fill(ticks)

    def _mcu_step(self, tick: int) -> None:
        self.board.step(tick)

    def _advance_stacks(self, n_ticks: int) -> None:
        for s in self.stacks:
            s.advance(n_ticks)


class EchoBox(_BoxBase):
    """Behavioural actuators (:class:`plant.echo_actuator.EchoActuators`: a first-order lag
    each, the MCU's command watchdog kept) behind the box's process data."""

    def __init__(self, box: Box, cfg: Config) -> None:
        super().__init__(box, cfg)
        self.model = EchoActuators(len(self.act), cfg)
        self.temp = cfg.get("effects.oil_temperature.initial_c")
        #: Per actuator: the (x, v, f, status) last packed (an actuator at rest is not
        #: packed again: its bytes would be the same).
        self._packed: list[tuple | None] = [None] * len(self.act)
        self._fill()

    def apply(self, data: bytes) -> None:
        for i, (mode, value, flags, _kpos, _kpf) in enumerate(self.decode(data)):
            self.model.command(i, mode, value, bool(flags & pdo.FLAG_ENABLE))

    def advance(self, ticks: int) -> None:
        self.model.advance(ticks)
        self.tick = self.model.tick
        self._fill()

    def _fill(self) -> None:
        m = self.model
        for i, k in enumerate(self.act):
            f = m.f[i]
            now = (m.x[i], m.v[i], f, m.status[i])
            if now == self._packed[i]:
                continue
            self._packed[i] = now
            self._pack_actuator(k, m.x[i], m.v[i], f, f, f, m.iq(i), self.temp, m.status[i],
                                0, 0)


#: "robot": the stack boxes advanced together by one compiled engine (:mod:`hil.sim.robot`).
BOX_MODELS = {"stack": StackBox, "robot": StackBox, "echo": EchoBox}


def box_engine(model: str, boxes: list, cfg: Config, overlap: bool = True) -> object | None:
    """The engine that advances all ``boxes`` as one for ``model`` "robot", else None;
    ``overlap``: a cycle's compute may start as soon as every box has its outputs (not for
    a chain paced by the wall clock, where a box may take new outputs twice a cycle)."""
    if model != "robot" or not any(getattr(b, "board", None) for b in boxes):
        return None  # (no actuator at all: nothing to batch)
    from hil.sim.robot import RobotEngine

    return RobotEngine(boxes, cfg, overlap=overlap)


def make_box(model: str, box: Box, cfg: Config) -> _BoxBase:
    """A box model by name ("stack", "robot", "echo" or "hip")."""
    if model == "hip":  # the hip's two coupled stacks (built on StackBox, so imported here)
        from hil.fieldbus.hip_box import HipBox

        return HipBox(box, cfg)
    try:
        cls = BOX_MODELS[model]
    except KeyError:
        raise ValueError(f"unknown box model {model!r}; choose from "
                         f"{', '.join([*BOX_MODELS, 'hip'])}") from None
    return cls(box, cfg)
