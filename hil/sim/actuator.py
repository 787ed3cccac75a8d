"""One actuator wired: plant -> sensor chips -> driver board -> LVDS link [-> MCU].

The one wiring the harness reuses: :class:`FpgaStack` is everything below the MCU (plant,
sensor chips, driver board, LVDS link and the MCU side's link memory ``mcu_link``);
:class:`ActuatorStack` adds the MCU and a 1 kHz PC command on the scheduler; the fieldbus
boxes (:mod:`hil.fieldbus.boxes`) and the replay build on the same pieces.

Plant + driver board + LVDS link + the MCU side's link memory, stepped together.

:class:`FpgaStack` looks like a :class:`plant.model.Plant` to the scheduler (``advance``,
``y``, ``tick``, ``tick_ns``), so tasks at lower rates (an MCU model, a scenario's
reference generator) run between its compiled stretches and talk to the board only through
``stack.mcu_link`` (the MCU-side memories), as the real MCU does.

Per tick t (plant integrated to t): sensor chips digitise the plant outputs -> downstream
link words of the tick reach the board -> the board's control tick -> upstream words ->
the compare counts (or gates off) drive the inverter over [t, t+1]. The inverter is the
plant's average model: duty = count / top; sampling at the carrier's centre sees the
average current, which is what the average model gives.

``bit_level=True`` runs the same per tick in Python with the sensor links and the LVDS
words as real bits (:mod:`plant.sensors.harness`, :mod:`firmware_model.fpga.masters`,
:class:`firmware_model.lvds.link.BitLevelLink`); it is ~100x slower and gives identical words.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from firmware_model.fpga import lanes as fpl
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import DriverBoard, LinkMemory
from firmware_model.fpga.tick import control_tick
from firmware_model.lvds import link as LK
from firmware_model.mcu.mcu import Mcu
from hil.sim.scheduler import Record, Scheduler
from plant import kernel
from plant import lanes as lanes_mod
from plant import layout as L
from plant.config import Config
from plant.model import Plant
from plant.sensors.chips import chip_params
from plant.sensors.harness import digitise

#: Columns of a driver-board trace row (:func:`advance_stack` ``trace``): what the board
#: took in (raw sensor words; its downstream memory, link-watchdog count and CRC-error
#: count as the LVDS receive endpoint left them this tick) and gave out (its upstream
#: memory, PWM on, the three compare counts), one row per tick.
TRACE_RAW = 0
TRACE_DOWN = TRACE_RAW + B.N_RAW
TRACE_LINK = TRACE_DOWN + B.DOWN_WORDS   # F_SINCE_VALID, F_ERR_LINK_CRC
TRACE_UP = TRACE_LINK + 2
TRACE_ON = TRACE_UP + B.UP_WORDS
TRACE_DUTY = TRACE_ON + 1
TRACE_WORDS = TRACE_DUTY + 3           # the link's word logs of the tick: down, then up
TRACE_WIDTH = TRACE_WORDS + 2 * LK.WORDS_W


@njit(cache=True, inline="always")
def _trace_cols(tr, j, raw, down, link_since, link_crc, up, on, d_a, d_b, d_c):
    for i in range(raw.shape[0]):
        tr[j, TRACE_RAW + i] = raw[i]
    for i in range(down.shape[0]):
        tr[j, TRACE_DOWN + i] = down[i]
    tr[j, TRACE_LINK] = link_since
    tr[j, TRACE_LINK + 1] = link_crc
    for i in range(up.shape[0]):
        tr[j, TRACE_UP + i] = up[i]
    tr[j, TRACE_ON] = on
    tr[j, TRACE_DUTY] = d_a
    tr[j, TRACE_DUTY + 1] = d_b
    tr[j, TRACE_DUTY + 2] = d_c


@njit(cache=True)
def _trace_row(tr, j, raw, down, link_since, link_crc, up, on, st):
    _trace_cols(tr, j, raw, down, link_since, link_crc, up, on, st[B.F_DUTY_A],
                st[B.F_DUTY_B], st[B.F_DUTY_C])


@njit(cache=True, _nrt=False)
def trace_row_lanes(tr, j, fb, lane, up):
    """:func:`_trace_row` of the board in lane ``lane`` of the board lanes ``fb``
    (:mod:`firmware_model.fpga.lanes`, after its :func:`~firmware_model.fpga.lanes.
    board_tick`): the raw words, downstream memory, counts and compare values from the
    lanes, the upstream words from the board's row ``up``."""
    for i in range(B.N_RAW):
        tr[j, TRACE_RAW + i] = fpl.lane(fb, fpl.RO, i, lane)
    for i in range(B.DOWN_WORDS):
        tr[j, TRACE_DOWN + i] = fpl.lane(fb, fpl.DO, i, lane)
    tr[j, TRACE_LINK] = fpl.lane(fb, fpl.XO, fpl.X_SINCE, lane)
    tr[j, TRACE_LINK + 1] = fpl.lane(fb, fpl.XO, fpl.X_CRC, lane)
    for i in range(up.shape[0]):
        tr[j, TRACE_UP + i] = up[i]
    tr[j, TRACE_ON] = fpl.lane(fb, fpl.SO, B.F_PWM_ON, lane)
    for i in range(3):
        tr[j, TRACE_DUTY + i] = fpl.lane(fb, fpl.SO, B.F_DUTY_A + i, lane)


@njit(cache=True, inline="always")
def _drive(on, d_a, d_b, d_c, inv_top, u, x):
    if on != 0:
        u[L.IN_MODE] = L.DriveMode.DUTY.value
        u[L.IN_DA] = d_a * inv_top
        u[L.IN_DB] = d_b * inv_top
        u[L.IN_DC] = d_c * inv_top
    else:
        if int(u[L.IN_MODE]) != L.DriveMode.OFF:
            u[L.IN_MODE] = L.DriveMode.OFF.value
            kernel.gates_off(x)


@njit(cache=True, inline="always")
def drive_plant(on, st, inv_top, u, x):
    """The inverter's gates as the board's tick left them (``on``: PWM running) into the
    plant's inputs: duties = compare counts / top, or gates off (currents zero at once)."""
    _drive(on, st[B.F_DUTY_A], st[B.F_DUTY_B], st[B.F_DUTY_C], inv_top, u, x)


@njit(cache=True, inline="always")
def _pix(at, k, j):
    """Row ``k`` of lane ``j`` of the block at ``at`` in the plant lanes (unsigned)."""
    return np.uint64(at + k * lanes_mod.LW + j)


_DUTY = float(L.DriveMode.DUTY.value)
_OFF = float(L.DriveMode.OFF.value)
_OFF_MODE = np.int64(L.DriveMode.OFF.value)


@njit(**lanes_mod.LANES, inline="always")
def drive_lanes(fb, pb, rows):
    """:func:`drive_plant` for every lane of the batch ``rows`` (its ``LW`` entries, the
    free lanes too): from the board lanes ``fb`` (:mod:`firmware_model.fpga.lanes`, after
    their :func:`~firmware_model.fpga.lanes.board_tick`) into the plant lanes ``pb``
    (:mod:`plant.lanes`: inputs, and the currents of a plant whose gates go off), its
    branches as selects, no actuator row. The trip count is ``rows``' length, not the
    constant ``LW``: a loop this small with a known count is unrolled before the loop
    vectoriser sees it, and the unrolled moves between two buffers stay scalar (nothing
    tells the compiler they do not overlap); this way it is one vector loop behind a
    run-time overlap check."""
    for j in range(rows.shape[0]):
        on = fpl.lane(fb, fpl.SO, B.F_PWM_ON, j) != 0
        inv_top = 1.0 / fpl.lane(fb, fpl.PO, B.C_PWM_TOP, j)
        mode = pb[_pix(lanes_mod.UO, L.IN_MODE, j)]
        off = (not on) & (np.int64(mode) != _OFF_MODE)
        pb[_pix(lanes_mod.UO, L.IN_MODE, j)] = _DUTY if on else (_OFF if off else mode)
        d_a = fpl.lane(fb, fpl.SO, B.F_DUTY_A, j) * inv_top
        d_b = fpl.lane(fb, fpl.SO, B.F_DUTY_B, j) * inv_top
        d_c = fpl.lane(fb, fpl.SO, B.F_DUTY_C, j) * inv_top
        pb[_pix(lanes_mod.UO, L.IN_DA, j)] = d_a if on else pb[_pix(lanes_mod.UO, L.IN_DA, j)]
        pb[_pix(lanes_mod.UO, L.IN_DB, j)] = d_b if on else pb[_pix(lanes_mod.UO, L.IN_DB, j)]
        pb[_pix(lanes_mod.UO, L.IN_DC, j)] = d_c if on else pb[_pix(lanes_mod.UO, L.IN_DC, j)]
        pb[_pix(lanes_mod.X, L.S_ID, j)] = 0.0 if off else pb[_pix(lanes_mod.X, L.S_ID, j)]
        pb[_pix(lanes_mod.X, L.S_IQ, j)] = 0.0 if off else pb[_pix(lanes_mod.X, L.S_IQ, j)]


@njit(cache=True)
def advance_stack(n_ticks, x, p, u, y, rec, row0, every, tick0, rng, work,
                  k, raw, c, st, down, up, mdown, mup, lk, trace):
    """``n_ticks`` ticks of the whole stack at value level; returns the next record row.
    With a ``trace`` of ``n_ticks`` rows, the board's inputs and outputs of every tick are
    written into it (columns ``TRACE_*``)."""
    row = row0
    tracing = trace.shape[0] >= n_ticks
    n_rows = rec.shape[0]
    n_out = y.shape[0]
    inv_top = 1.0 / c[B.C_PWM_TOP]
    for j in range(n_ticks):
        t = tick0 + j
        digitise(y, k, t, raw)
        LK.sweep_down(lk, mdown, st, down)
        since, crc = st[B.F_SINCE_VALID], st[B.F_ERR_LINK_CRC]
        on = control_tick(c, st, down, up, raw)
        if tracing:
            _trace_row(trace, j, raw, down, since, crc, up, on, st)
        LK.sweep_up(lk, up, mup)
        if tracing:
            for i in range(2 * LK.WORDS_W):
                trace[j, TRACE_WORDS + i] = lk[LK.LK_DOWN_WORDLOG + i]
        drive_plant(on, st, inv_top, u, x)
        kernel.rk4_tick(x, p, u, work)
        kernel.outputs(x, p, u, rng, y)
        if n_rows > 0 and (t + 1) % every == 0 and row < n_rows:
            for i in range(n_out):
                rec[row, i] = y[i]
            row += 1
    return row


class FpgaStack:
    """One actuator below the MCU: plant, sensor chips, driver board, LVDS link."""

    def __init__(self, cfg: Config, bit_level: bool = False, substeps: int | None = None
                 ) -> None:
        self.config = cfg
        self.plant = Plant(cfg, substeps)
        self.plant.set_gates_off()
        self.board = DriverBoard(cfg)
        #: The current loop's Verilated RTL in place of the board's own (``fpga.impl``).
        self.rtl = None
        if cfg.get("fpga.impl") == "rtl":
            from hil.sim.verilator import load

            self.rtl = self.board.rtl = load(cfg, self.board.params)
        self.mcu_link = LinkMemory(cfg)
        self.link = LK.link_state(cfg)
        self.chips = chip_params(cfg)
        self.raw = np.zeros(B.N_RAW, dtype=np.int64)
        self.tick_ns = self.plant.tick_ns
        self.tick_s = self.plant.tick_s
        self.bit_level = bit_level
        self._no_rec = np.zeros((0, L.N_OUTPUTS))
        self._no_trace = np.zeros((0, TRACE_WIDTH), dtype=np.int64)
        self._bits = None
        if bit_level:
            from firmware_model.fpga.masters import BitLevelMasters
            from plant.sensors.harness import SensorLines

            self._bits = (SensorLines(cfg), BitLevelMasters(cfg), LK.BitLevelLink())

    # --- Plant-like interface for the scheduler ---------------------------------------------
    @property
    def y(self) -> np.ndarray:
        return self.plant.y

    @property
    def tick(self) -> int:
        return self.plant.tick

    @property
    def time_s(self) -> float:
        return self.plant.time_s

    def advance(self, n_ticks: int, rec: np.ndarray | None = None, row0: int = 0,
                every: int = 1, trace: np.ndarray | None = None) -> int:
        """Advance the stack ``n_ticks`` ticks; record plant outputs like Plant.advance.

        ``trace``: an int64 array of (n_ticks, TRACE_WIDTH) that receives the driver board's
        inputs and outputs of every tick (value-level path only), for FPGA replay."""
        if trace is not None and self._bits is not None:
            raise ValueError("trace: only the value-level path records board traces")
        rows = self._no_rec if rec is None else rec
        pl = self.plant
        bd = self.board
        if self._bits is None:
            row = advance_stack(n_ticks, pl.x, pl.params, pl.u, pl.y, rows, row0, every,
                                pl.tick, pl.rng, pl._work, self.chips, self.raw,
                                bd.params, bd.state, bd.down, bd.up, self.mcu_link.down,
                                self.mcu_link.up, self.link,
                                self._no_trace if trace is None else trace)
            pl.tick += n_ticks
        else:
            row = self._advance_bits(n_ticks, rows, row0, every)
        self.mcu_link.up_crc_errors = int(self.link[LK.LK_MASTER_CRC])
        return row

    def _advance_bits(self, n_ticks: int, rows: np.ndarray, row0: int, every: int) -> int:
        lines, masters, link = self._bits
        pl = self.plant
        bd = self.board
        inv_top = 1.0 / bd.pwm_top
        row = row0
        for _ in range(n_ticks):
            t = pl.tick
            lines.update(pl.y, t)
            masters.read(lines, t, self.raw)
            link.sweep_down(self.link, self.mcu_link.down, bd.state, bd.down)
            on = bd.tick(self.raw)
            link.sweep_up(self.link, bd.up, self.mcu_link.up)
            if on:
                a, b, c = bd.duty_counts()
                pl.set_duty(a * inv_top, b * inv_top, c * inv_top)
            else:
                pl.set_gates_off()
            row = pl.advance(1, rows, row, every)
        return row

    # --- fault injection on the link --------------------------------------------------------
    def link_fault(self, direction: str = "down", stopped: bool | None = None,
                   corrupt_every: int | None = None, drop_every: int | None = None,
                   dup_every: int | None = None, delay_ticks: int | None = None) -> None:
        """Fault one direction of the link (None leaves a setting as it is): ``stopped``;
        every N-th word corrupted (1 = all, 0 = none); and, value level only, every N-th
        word dropped or sent twice, and a latency of ``delay_ticks`` (docs/fpga.md)."""
        if direction not in ("down", "up"):
            raise ValueError(f"link direction {direction!r}: expected 'down' or 'up'")
        down = direction == "down"
        i_stop, i_every = ((LK.LK_DOWN_STOPPED, LK.LK_DOWN_CORRUPT) if down
                           else (LK.LK_UP_STOPPED, LK.LK_UP_CORRUPT))
        if stopped is not None:
            self.link[i_stop] = int(stopped)
        extra = {"corrupt_every": (corrupt_every, i_every),
                 "drop_every": (drop_every, LK.LK_DOWN_DROP if down else LK.LK_UP_DROP),
                 "dup_every": (dup_every, LK.LK_DOWN_DUP if down else LK.LK_UP_DUP),
                 "delay_ticks": (delay_ticks, LK.LK_DOWN_DELAY if down else LK.LK_UP_DELAY)}
        for name, (value, index) in extra.items():
            if value is None:
                continue
            if value < 0:
                raise ValueError(f"{name} must be >= 0")
            if name == "delay_ticks" and value >= LK.HIST_TICKS:
                raise ValueError(f"delay_ticks must be < {LK.HIST_TICKS}")
            if name != "corrupt_every" and value and self._bits is not None:
                raise ValueError(f"{name}: the bit-level link models stop and corruption only")
            self.link[index] = value

    # --- the boot sequence the PC and MCU perform ---------------------------------------------
    def boot(self, mode: int = B.BoardMode.CURRENT, settle_ticks: int = 40) -> None:
        """Send the calibrated angle offset, select ``mode``, enable, and run until the board
        reports ENABLED; RuntimeError (with the status bits) if it refuses."""
        self.mcu_link.write("angle_offset", self.board.calibrated_offset)
        self.mcu_link.write("mode", mode)
        self.mcu_link.write("control", B.CTRL_ENABLE)
        self.advance(settle_ticks)
        if "ENABLED" not in self.mcu_link.status():
            raise RuntimeError(f"driver board did not enable: {sorted(self.mcu_link.status())}")


PC_PERIOD_TICKS = 20  # 1 kHz

#: command(t_s) -> (mode, value): "force" N, "position" m, or "off".
CommandFn = Callable[[float], tuple[str, float]]


class ActuatorStack:
    """Plant, driver board, link and MCU for one actuator."""

    def __init__(self, cfg: Config, command: CommandFn, record_every: int = 4) -> None:
        self.config = cfg
        self.fpga = FpgaStack(cfg)
        if cfg.get("mcu.impl") == "c":  # the C law built for the host (docs/mcu.md)
            from hil.sim.mcu_c import CMcu

            self.mcu = CMcu(cfg, [self.fpga.mcu_link])
        elif cfg.get("mcu.impl") == "image":  # a firmware ELF on the emulator (docs/mcu.md)
            from hil.sim.image.stack import ImageMcu

            self.mcu = ImageMcu(cfg, [self.fpga.mcu_link])
        else:
            self.mcu = Mcu(cfg, [self.fpga.mcu_link])
        self.command = command
        self.tick_s = self.fpga.tick_s
        self.sched = Scheduler(self.fpga, record_every=record_every)
        period = self.mcu.period
        self.sched.every(PC_PERIOD_TICKS, self._pc, "pc")
        self.sched.every(period, self.mcu.step, "mcu")
        ctrl = self.mcu.ctrl[0]
        self.sched.probe("tau_ref", lambda: float(self.mcu.tau_ref[0]), period)
        self.sched.probe("f_pres", lambda: float(self.mcu.meas[0].f_pres), period)
        self.sched.probe("f_strain", lambda: float(ctrl.strain_force(self.mcu.meas[0])),
                         period)
        self.sched.probe("f_fil", lambda: float(ctrl.f_fil), period)
        self.sched.probe("iq_ref", lambda: float(self.mcu.iq_ref[0]), period)
        self.sched.probe("x_meas", lambda: float(self.mcu.meas[0].x_piston), period)
        self.mcu.command(0, *command(0.0), tick=0)
        self.mcu.enable(0, self.fpga.board.calibrated_offset)

    def _pc(self, tick: int) -> None:
        self.mcu.command(0, *self.command(tick * self.tick_s), tick=tick)

    def run(self, seconds: float, progress: bool = False, label: str = "stack") -> Record:
        """Run for ``seconds`` of simulated time; the record holds plant outputs and probes."""
        return self.sched.run(self.sched.ticks(seconds), progress, label)


def probe_times(rec: Record, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(t in s, values) of a probe."""
    return rec.probe(name)


__all__ = ["ActuatorStack", "FpgaStack", "advance_stack", "probe_times"]
