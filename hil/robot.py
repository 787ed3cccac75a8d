"""The whole robot in one engine: every actuator's stack below the MCU (plant, sensor chips,
driver board, LVDS link) and its MCU program advanced together, batched over actuators.

The per-actuator path (:class:`~hil.fieldbus.boxes.StackBox`) steps each box's Python MCU
model and calls each actuator's compiled stack every MCU period: 47 actuators cost ~10 Python
calls each per MCU period. Here one fieldbus cycle (20 ticks) is five rounds of

* one C call for the MCU program of every actuator (the MCU law's host build,
  ``firmware_model/mcu/c/``, ``mcu_law_step_many``; built with ``-ffp-contract=off`` and
  checked bit for bit against the Python model, docs/mcu.md), then
* one compiled call that copies each program's downstream words into its LVDS memory,
  advances every stack by one MCU period (``prange`` over actuators: the workers share
  the actuators, each actuator's arithmetic is the same whichever worker runs it), and
  copies the upstream words back into the programs' input records,

and the process data of all boxes is decoded and packed with whole-array operations. The
arrays of every :class:`~hil.actuator.FpgaStack` are rebound to rows of the engine's arrays,
so faults and tools that hold a stack see the same memory. A stack with a sensor fault
(:class:`~hil.fieldbus.faults.FaultyStack` overriding plant outputs tick by tick) is left
out of the compiled call and advanced by its own wrapper between the same two copies.

Same results as the per-actuator path, bit for bit (``tests/hil/test_robot.py``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from firmware_model.fpga import layout as B
from firmware_model.lvds import link as LK
from firmware_model.mcu.c_abi import (
    IN_CLEAR_FAULT,
    IN_COMMAND,
    IN_DISABLE,
    IN_ENABLE,
    IN_GAINS,
    INPUT,
    OUTPUT,
    config_record,
)
from hil.actuator import advance_stack
from hil.fieldbus import pdo
from plant import layout as L
from plant.config import Config, ConfigError

#: Offsets of the input record's fields, in 16-bit words (the kernel writes through a view).
_IN_U16 = INPUT.itemsize // 2
_IN_UP = INPUT.fields["up"][1] // 2
_IN_CRC = INPUT.fields["up_crc_errors"][1] // 4
_OUT_U16 = OUTPUT.itemsize // 2
_OUT_DOWN = OUTPUT.fields["down"][1] // 2
_T_ANALOG = [a.name for a in B.ANALOG_INPUTS].index("temperature")


@njit(cache=True, parallel=True)
def advance_robot(n_ticks, tick0, batched, no_rec, no_trace, x, p, u, y, rng, work, k, raw,
                  c, st, down, up, mdown, mup, lk, out16, in16, in32):
    """``n_ticks`` ticks of every stack ``i`` with ``batched[i]``: the program's downstream
    words (``out16`` rows) into its LVDS memory first, its upstream words and the link's
    CRC count into the program's input record (``in16``/``in32`` rows) after. ``no_rec``
    and ``no_trace``: empty record and trace arrays (nothing recorded here)."""
    for i in prange(x.shape[0]):
        if not batched[i]:
            continue
        for w in range(mdown.shape[1]):
            mdown[i, w] = out16[i, _OUT_DOWN + w]
        advance_stack(n_ticks, x[i], p[i], u[i], y[i], no_rec, 0, 1, tick0, rng[i], work[i],
                      k[i], raw[i], c[i], st[i], down[i], up[i], mdown[i], mup[i], lk[i],
                      no_trace)
        for w in range(mup.shape[1]):
            in16[i, _IN_UP + w] = mup[i, w] & 0xFFFF
        in32[i, _IN_CRC] = lk[i, LK.LK_MASTER_CRC]


#: (object path, attribute) of every array the stack's compiled tick works on, in the order
#: of :func:`advance_robot`'s arguments from ``x`` to ``lk``.
_ARRAYS = (("plant", "x"), ("plant", "params"), ("plant", "u"), ("plant", "y"),
           ("plant", "rng"), ("plant", "_work"), ("", "chips"), ("", "raw"),
           ("board", "params"), ("board", "state"), ("board", "down"), ("board", "up"),
           ("mcu_link", "down"), ("mcu_link", "up"), ("", "link"))


def _counts(value: np.ndarray, lsb: float, dtype: str) -> np.ndarray:
    """:func:`hil.fieldbus.pdo.to_counts` over an array (same float64 steps)."""
    info = np.iinfo(np.dtype(dtype))
    c = value / lsb
    c = np.where(c >= 0, np.trunc(c + 0.5), -np.trunc(-c + 0.5))
    return np.clip(c, info.min, info.max).astype(np.int64)


class RobotEngine:
    """All StackBoxes of a chain advanced as one; ``workers`` threads share the actuators
    (``None``: numba's default, one per core)."""

    def __init__(self, boxes: list, cfg: Config, workers: int | None = None) -> None:
        from hil.verify.mcu_builds import BuildError, HostLaw, build_host

        self.all_boxes = boxes
        self.boxes = [b for b in boxes if getattr(b, "board", None) is not None]
        if workers is not None and not 1 <= workers <= numba.config.NUMBA_NUM_THREADS:
            raise ConfigError(f"workers = {workers}: expected 1..{numba.config.NUMBA_NUM_THREADS}")
        self.workers = workers
        self.period = cfg.get("mcu.period_ticks")
        self.tick_s = cfg.get("sim.tick_ns") * 1e-9
        #: (box, slot index in the box) of each actuator, in chain order.
        self.slots = [(b, i) for b in self.boxes for i in range(len(b.stacks))]
        n = self.n = len(self.slots)
        try:
            self.law = HostLaw(build_host())
        except BuildError as exc:
            raise ConfigError(f"the robot engine runs the MCU law's C build: {exc}") from None
        self._bind_arrays()
        config = config_record(cfg)
        size = self.law.state_size
        self.states = np.zeros(n * size, dtype=np.uint8)
        for j in range(n):
            self.law.init_at(self.states.ctypes.data + j * size, config)
        self.inp = np.zeros(n, dtype=INPUT)
        self.out = np.zeros(n, dtype=OUTPUT)
        self.in16 = self.inp.view(np.uint16).reshape(n, _IN_U16)
        self.in32 = self.inp.view(np.uint32).reshape(n, _IN_U16 // 2)
        self.out16 = self.out.view(np.uint16).reshape(n, _OUT_U16)
        self.out["down"] = self.out_down_init = config["down_init"]
        self.inp["angle_offset"] = [b.stacks[i].board.calibrated_offset for b, i in self.slots]
        self.cos_alpha = np.float32(config["cos_alpha"])
        self._refresh_inputs(np.ones(n, dtype=bool))
        # Process data as the boxes last decoded it (edges are taken against these).
        self.enabled = np.zeros(n, dtype=bool)
        self.clear = np.zeros(n, dtype=bool)
        self.x_prev = np.zeros(n)
        self.tick = self.boxes[0].tick if self.boxes else 0
        # Where each actuator's records sit in its box's process data.
        self._out_at = [[b._out_off[b.act[i]] for i in range(len(b.stacks))] for b in self.boxes]
        self._in_at = [[b._in_off[b.act[i]] for i in range(len(b.stacks))] for b in self.boxes]
        self._first = np.cumsum([0] + [len(b.stacks) for b in self.boxes])
        out_w, in_w = pdo.ACTUATOR_OUT_DTYPE.itemsize, pdo.ACTUATOR_IN_DTYPE.itemsize
        self._out_idx = [np.add.outer(np.array(at, dtype=np.intp), np.arange(out_w))
                         for at in self._out_at]
        self._in_idx = [np.add.outer(np.array(at, dtype=np.intp), np.arange(in_w))
                        for at in self._in_at]
        self._out_rows = np.zeros((n, out_w), dtype=np.uint8)
        self._no_rec = np.zeros((0, L.N_OUTPUTS))
        self._no_trace = np.zeros((0, 1), dtype=np.int64)
        self.err_down = np.zeros(n, dtype=np.int64)
        self.err_up = np.zeros(n, dtype=np.int64)
        for b in self.all_boxes:
            b.pending = None
            b.engine = self

    # --- set-up --------------------------------------------------------------------------
    def _bind_arrays(self) -> None:
        """Stack the stacks' arrays and rebind every stack to its row."""
        self.arrays = []
        stacks = [self._inner(b.stacks[i]) for b, i in self.slots]
        for owner, name in _ARRAYS:
            parts = [getattr(s, owner) if owner else s for s in stacks]
            whole = np.ascontiguousarray(np.stack([getattr(o, name) for o in parts]))
            for j, o in enumerate(parts):
                setattr(o, name, whole[j])
            self.arrays.append(whole)

    @staticmethod
    def _inner(stack: object) -> object:
        return getattr(stack, "stack", stack)  # a FaultyStack holds the FpgaStack

    def _refresh_inputs(self, which: np.ndarray) -> None:
        """Upstream words and CRC counts of the stacks ``which`` into the input records."""
        mup, lk = self.arrays[13], self.arrays[14]
        self.inp["up"][which] = mup[which] & 0xFFFF
        self.inp["up_crc_errors"][which] = lk[which, LK.LK_MASTER_CRC]

    # --- one fieldbus cycle ----------------------------------------------------------------
    def advance(self, ticks: int) -> None:
        """``ticks`` ticks (whole MCU periods) of every actuator; then every box's inputs."""
        if ticks % self.period:
            raise ValueError(f"the robot engine advances whole MCU periods ({self.period} "
                             f"ticks), not {ticks}")
        if self.workers is not None:
            numba.set_num_threads(self.workers)
        self._take_outputs()
        external = [j for j, (b, i) in enumerate(self.slots)
                    if getattr(b.stacks[i], "sensors", None)]
        batched = np.ones(self.n, dtype=bool)
        batched[external] = False
        for b, i in self.slots:  # LVDS faults switch at cycle boundaries (FaultyStack)
            s = b.stacks[i]
            if hasattr(s, "_switch_lvds") and not s.sensors:
                s._switch_lvds(self.tick // ticks)
        a = self.arrays
        for t in range(self.tick, self.tick + ticks, self.period):
            self.inp["tick"] = t
            self.law.step_many(self.states, self.inp, self.out)
            self.inp["flags"] = 0
            if t + self.period >= self.tick + ticks:
                # The link error counts as the programs read them at their last step.
                self.err_down[:] = self.in16[:, _IN_UP + B.U_ERR_LINK_CRC]
                self.err_up[:] = self.in32[:, _IN_CRC]
            advance_robot(self.period, t, batched, self._no_rec, self._no_trace, *a,
                          self.out16, self.in16, self.in32)
            for j in external:
                b, i = self.slots[j]
                self.arrays[12][j] = self.out["down"][j]
                b.stacks[i].advance(self.period)
            if external:
                self._refresh_inputs(~batched)
        for j, (b, i) in enumerate(self.slots):
            if batched[j]:
                self._inner(b.stacks[i]).plant.tick += ticks
        self.tick += ticks
        for b in self.all_boxes:
            b.tick = self.tick
        self._give_inputs(ticks)

    def _take_outputs(self) -> None:
        """The process data the boxes received since the last cycle, as program inputs
        (what :meth:`McuBoard.apply` does with it, for every actuator at once)."""
        rows = self._out_rows
        got = np.zeros(self.n, dtype=bool)
        for n_box, b in enumerate(self.boxes):
            if b.pending is None:
                continue
            lo, hi = self._first[n_box], self._first[n_box + 1]
            rows[lo:hi] = np.frombuffer(b.pending, dtype=np.uint8)[self._out_idx[n_box]]
            got[lo:hi] = True
            b.pending = None
        if not got.any():
            self.inp["flags"] = 0
            return
        r = rows.view(pdo.ACTUATOR_OUT_DTYPE)[:, 0]
        mode = r["mode"].astype(np.uint32)
        known = np.isin(mode, list(pdo.MODE_NAMES))
        mode[~known] = pdo.MODE_CODES["off"]
        lsb = np.where(mode == pdo.MODE_CODES["position"], pdo.POSITION_CMD_LSB,
                       pdo.FORCE_CMD_LSB)
        enable = (r["flags"] & pdo.FLAG_ENABLE) != 0
        clear = (r["flags"] & pdo.FLAG_CLEAR_FAULT) != 0
        rising = enable & ~self.enabled
        flags = np.full(self.n, IN_COMMAND | IN_GAINS, dtype=np.uint32)
        flags[clear & ~self.clear] |= IN_CLEAR_FAULT
        flags[rising] |= IN_ENABLE
        flags[~rising & self.enabled & ~enable] |= IN_DISABLE
        flags[~got] = 0
        self.enabled = np.where(got, enable, self.enabled)
        self.clear = np.where(got, clear, self.clear)
        inp = self.inp
        inp["flags"] = flags
        inp["mode"] = np.where(got, mode, inp["mode"])
        inp["value"] = np.where(got, r["command"].astype(np.int64) * lsb, inp["value"])
        inp["kp_position"] = np.where(got, r["kp_position"].astype(np.int64) * 10.0,
                                      inp["kp_position"])
        inp["kp_force"] = np.where(got, r["kp_force"].astype(np.int64) * 1e-3, inp["kp_force"])

    def _give_inputs(self, ticks: int) -> None:
        """Every box's input record from the programs' last outputs (as McuBoard.report)."""
        o = self.out
        x = o["x_piston"].astype(np.float64)
        v = (x - self.x_prev) / (ticks * self.tick_s) if ticks else np.zeros(self.n)
        self.x_prev = x
        rec = np.zeros(self.n, dtype=pdo.ACTUATOR_IN_DTYPE)
        rec["x_piston"] = _counts(x, 1e-9, "i4")
        rec["v_piston"] = _counts(v, 1e-5, "i2")
        rec["f_pressure"] = _counts(o["f_pres"].astype(np.float64), 0.1, "i2")
        rec["f_strain"] = _counts((self.cos_alpha * o["f_strain_raw"]).astype(np.float64),
                                  0.1, "i2")
        rec["f_filtered"] = _counts(o["f_fil"].astype(np.float64), 0.1, "i2")
        rec["iq"] = _counts(o["iq"].astype(np.float64), 1e-3, "i2")
        rec["temperature"] = _counts(o["m_analog"][:, _T_ANALOG].astype(np.float64), 0.01,
                                     "i2")
        rec["status"] = o["status"] & 0xFFFF
        rec["err_link_down"] = np.minimum(self.err_down, 0xFFFF)
        rec["err_link_up"] = np.minimum(self.err_up, 0xFFFF)
        raw = rec.view(np.uint8).reshape(self.n, -1)
        for n_box, b in enumerate(self.boxes):
            buf = np.frombuffer(b._in_buf, dtype=np.uint8)
            buf[self._in_idx[n_box]] = raw[self._first[n_box]:self._first[n_box + 1]]


def plant_records(engine: RobotEngine) -> np.ndarray:
    """The plant outputs of every actuator now, (actuators, outputs), chain order."""
    return engine.arrays[3].copy()


__all__ = ["RobotEngine", "advance_robot", "plant_records", "L"]
