"""Box models: what sits behind one EtherCAT slave (an MCU board and its driver boards).

* :class:`StackBox`: the real thing in simulation: the MCU model over one value-level stack
  (plant + driver board + LVDS link) per actuator slot, at their real rates.
* :class:`EchoBox`: a cheap behavioural stand-in for bus-level work on the full robot
  (47 actuators): each actuator follows its command through a first-order lag and keeps the
  MCU's command watchdog, so timeouts and status words behave as the firmware's.

Both take the box's output record bytes once per fieldbus cycle (:meth:`apply`), give the
input record bytes (:meth:`inputs`) and advance by whole ticks (:meth:`advance`).
"""

from __future__ import annotations

import math
import struct

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.mcu.mcu import BOARD_ENABLED, CMD_TIMEOUT, SAFE_OFF, Mcu
from hil.fieldbus import pdo
from hil.fieldbus.topology import Box
from plant.config import Config

F32 = np.float32


def _out_dtype(box: Box) -> np.dtype:
    fields = []
    for k, s in enumerate(box.slots):
        if s.sizes[0]:
            fields.append((f"s{k}", pdo.record_dtype(pdo.SLOT_FIELDS[s.kind][0])))
    return np.dtype(fields) if fields else np.dtype([])


def _in_dtype(box: Box) -> np.dtype:
    return np.dtype([(f"s{k}", pdo.record_dtype(pdo.SLOT_FIELDS[s.kind][1]))
                     for k, s in enumerate(box.slots)])


def _sat(value: float, lsb: float, dtype: str) -> int:
    return pdo.to_counts(float(value), lsb, dtype)


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
        _IN.pack_into(self._in_buf, self._in_off[k],
                      _sat(x, 1e-9, "i4"), _sat(v, 1e-5, "i2"), _sat(f_pres, 0.1, "i2"),
                      _sat(f_strain, 0.1, "i2"), _sat(f_fil, 0.1, "i2"), _sat(iq, 1e-3, "i2"),
                      _sat(temp, 0.01, "i2"), status & 0xFFFF, min(err_down, 0xFFFF),
                      min(err_up, 0xFFFF))


#: Struct layouts equal to the pdo declarations (checked at import below).
_OUT = struct.Struct("<" + "".join({"u1": "B", "u2": "H", "i2": "h", "i4": "i"}[f.dtype]
                                   for f in pdo.ACTUATOR_OUT))
_IN = struct.Struct("<" + "".join({"u1": "B", "u2": "H", "i2": "h", "i4": "i"}[f.dtype]
                                  for f in pdo.ACTUATOR_IN))
assert _OUT.size == pdo.ACTUATOR_OUT_DTYPE.itemsize and _IN.size == pdo.ACTUATOR_IN_DTYPE.itemsize
assert [f.name for f in pdo.ACTUATOR_IN][:3] == ["x_piston", "v_piston", "f_pressure"]


class StackBox(_BoxBase):
    """MCU model + one value-level FPGA stack per actuator slot."""

    def __init__(self, box: Box, cfg: Config) -> None:
        super().__init__(box, cfg)
        from hil.actuator import FpgaStack

        self.stacks = [FpgaStack(cfg) for _ in self.act]
        self.mcu = Mcu(cfg, [s.mcu_link for s in self.stacks]) if self.stacks else None
        self.period = cfg.get("mcu.period_ticks")
        self._flags = [0] * len(self.act)
        self._x_prev = [0.0] * len(self.act)
        self._defaults = [(c.k_pos, c.kp) for c in self.mcu.ctrl] if self.mcu else []
        self._fill()

    def apply(self, data: bytes) -> None:
        """Outputs of this cycle: commands, enable edges, gains."""
        if self.mcu is None:
            return
        for i, (mode, value, flags, kpos, kpf) in enumerate(self.decode(data)):
            rising = flags & ~self._flags[i]
            if rising & pdo.FLAG_CLEAR_FAULT:
                self.stacks[i].mcu_link.write("control", B.CTRL_CLEAR_FAULT)
            if rising & pdo.FLAG_ENABLE:
                self.mcu.enable(i, self.stacks[i].board.calibrated_offset)
            elif self._flags[i] & pdo.FLAG_ENABLE and not flags & pdo.FLAG_ENABLE:
                self.stacks[i].mcu_link.write("control", 0)
            self._flags[i] = flags
            ctrl = self.mcu.ctrl[i]
            ctrl.k_pos = F32(kpos) if kpos > 0 else self._defaults[i][0]
            ctrl.kp = F32(kpf) if kpf > 0 else self._defaults[i][1]
            self.mcu.command(i, mode, value, self.tick)

    def advance(self, ticks: int) -> None:
        """Run the MCU every period and the stacks between, for ``ticks`` ticks."""
        end = self.tick + ticks
        while self.tick < end:
            if self.mcu is not None:
                self.mcu.step(self.tick)
            for s in self.stacks:
                s.advance(self.period)
            self.tick += self.period
        self._fill(ticks)

    def _fill(self, ticks: int = 0) -> None:
        if self.mcu is None:
            return
        for i, k in enumerate(self.act):
            m, c = self.mcu.meas[i], self.mcu.ctrl[i]
            x = float(m.x_piston)
            v = (x - self._x_prev[i]) / (ticks * self.tick_s) if ticks else 0.0
            self._x_prev[i] = x
            # The error counts as the MCU read them at its last step (what it reports).
            err_down, err_up = self.mcu.link_error_counts(i)
            self._pack_actuator(k, x, v, float(m.f_pres), float(c.cos_alpha * m.f_strain_raw),
                                float(c.f_fil), float(m.iq), float(m.temperature_c),
                                self.mcu.status[i], err_down, err_up)


class EchoBox(_BoxBase):
    """Behavioural actuators: force follows the command with ``TAU_FORCE_S``, the piston a
    position command with ``TAU_POSITION_S``; the MCU's command watchdog is kept."""

    TAU_FORCE_S = 0.005
    TAU_POSITION_S = 0.02
    N_PER_A = 2150.0 / 18.0

    def __init__(self, box: Box, cfg: Config) -> None:
        super().__init__(box, cfg)
        n = len(self.act)
        self.timeout = round(cfg.get("mcu.command_timeout_s") / self.tick_s)
        self.off = self.timeout + round(cfg.get("mcu.safe_off_delay_s") / self.tick_s)
        self.temp = cfg.get("effects.oil_temperature.initial_c")
        self.cmd = [("off", 0.0)] * n
        self.enabled = [False] * n
        self.last = [0] * n
        self.f = [0.0] * n
        self.x = [0.0] * n
        self.v = [0.0] * n
        self.status = [0] * n
        self._fill()

    def apply(self, data: bytes) -> None:
        for i, (mode, value, flags, _kpos, _kpf) in enumerate(self.decode(data)):
            self.cmd[i] = (mode, value)
            self.enabled[i] = bool(flags & pdo.FLAG_ENABLE)
            self.last[i] = self.tick

    def advance(self, ticks: int) -> None:
        dt = ticks * self.tick_s
        af = 1.0 - math.exp(-dt / self.TAU_FORCE_S)
        ax = 1.0 - math.exp(-dt / self.TAU_POSITION_S)
        self.tick += ticks
        for i in range(len(self.act)):
            mode, value = self.cmd[i]
            age = self.tick - self.last[i]
            status = BOARD_ENABLED if self.enabled[i] else 0
            if age > self.timeout and mode != "off":
                status |= CMD_TIMEOUT
                mode, value = "force", 0.0
                if age > self.off:
                    status = (status | SAFE_OFF) & ~BOARD_ENABLED
            if not status & BOARD_ENABLED:
                mode = "off"
            x0 = self.x[i]
            if mode == "force":
                self.f[i] += af * (value - self.f[i])
            elif mode == "position":
                self.x[i] += ax * (value - self.x[i])
                self.f[i] += af * (1e4 * (value - self.x[i]) - self.f[i])
            else:
                self.f[i] += af * (0.0 - self.f[i])
            self.v[i] = (self.x[i] - x0) / dt
            self.status[i] = status
        self._fill()

    def _fill(self) -> None:
        for i, k in enumerate(self.act):
            f = self.f[i]
            self._pack_actuator(k, self.x[i], self.v[i], f, f, f, f / self.N_PER_A, self.temp,
                                self.status[i], 0, 0)


BOX_MODELS = {"stack": StackBox, "echo": EchoBox}


def make_box(model: str, box: Box, cfg: Config) -> _BoxBase:
    """A box model by name ("stack" or "echo")."""
    try:
        cls = BOX_MODELS[model]
    except KeyError:
        raise ValueError(f"unknown box model {model!r}; choose from "
                         f"{', '.join(BOX_MODELS)}") from None
    return cls(box, cfg)
