"""The two sensor paths into the driver board give identical raw words and board outputs.

Value level: :func:`plant.sensors.harness.digitise` (compiled). Bit level: the chips' wires
(:class:`plant.sensors.harness.SensorLines`) read by the FPGA's masters
(:class:`firmware_model.fpga.masters.BitLevelMasters`). Faults injected on the wires must
show up as rejected reads that the board counts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.fpga.masters import BitLevelMasters
from firmware_model.fpga.params import board_params, calibrated_offset, down_defaults
from firmware_model.fpga.tick import control_tick
from plant import layout as L
from plant.config import load_config
from plant.model import Plant
from plant.sensors.chips import chip_params
from plant.sensors.harness import SensorLines, digitise
from plant.sensors.motor_encoder import abi_count, ssi_count
from plant.sensors.piston_encoder import biss_count
from plant.sensors.strain_gauge import strain_clamped, strain_code, strain_conversions
from protocols.ad7195 import AD7195Device
from protocols.ssi import SsiFormat

TWO_PI = 2.0 * math.pi


@pytest.fixture(scope="module")
def cfg():
    """Default preset with a free piston, so the motor turns under an open-loop current."""
    return load_config(None, ["load.kind=free"])


class Board:
    """One compiled driver board, enabled in current mode with a live link."""

    def __init__(self, cfg) -> None:
        self.c = board_params(cfg)
        self.st = np.zeros(B.N_STATE, dtype=np.int64)
        self.up = np.zeros(B.UP_WORDS, dtype=np.int64)
        self.down = down_defaults(cfg)
        self.down[B.D_CONTROL] = B.CTRL_ENABLE
        self.down[B.D_MODE] = B.BoardMode.CURRENT
        self.down[B.D_IQ_REF] = 5000  # mA
        self.down[B.D_ANGLE_OFFSET] = calibrated_offset(cfg)

    def tick(self, raw: np.ndarray) -> None:
        self.st[B.F_SINCE_VALID] = 0  # a downstream word arrived this tick: link alive
        control_tick(self.c, self.st, self.down, self.up, raw)


def synthetic_y(theta: float = 0.0, x: float = 0.0, force: float = 0.0, p: float = 2e6,
                temp: float = 40.0, ia: float = 0.0, ib: float = 0.0) -> np.ndarray:
    """Plant outputs with the sensor rows set (rad, m, N, Pa, degC, A)."""
    y = np.zeros(L.N_OUTPUTS)
    y[L.Y_THETA_M] = theta
    y[L.Y_X_PISTON] = x
    y[L.Y_F_STRAIN] = force
    for j, row in enumerate((L.Y_P_ACC, L.Y_P_PUMP_A, L.Y_P_PUMP_B, L.Y_P_CYL_A,
                             L.Y_P_CYL_B)):
        y[row] = p * (1.0 + 0.1 * j)
    y[L.Y_TEMP] = temp
    y[L.Y_IA] = ia
    y[L.Y_IB] = ib
    return y


def new_conversion_ticks(k: np.ndarray, n: int) -> list[int]:
    """Ticks < n at which an AD7195 conversion completes."""
    return [t for t in range(n) if strain_conversions(t, k) != strain_conversions(t - 1, k)]


def diff(a: np.ndarray, b: np.ndarray) -> list[tuple[str, int, int]]:
    return [(B.RAW_NAMES[i], int(a[i]), int(b[i])) for i in np.nonzero(a != b)[0]]


def test_plant_run_identical_raw_words_and_board_outputs(cfg):
    """A free-piston run, motor driven open loop both ways: every raw word, duty count and
    upstream word is identical for the two paths on every tick."""
    plant = Plant(cfg)
    k = chip_params(cfg)
    lines, masters = SensorLines(cfg), BitLevelMasters(cfg)
    raw_v = np.zeros(B.N_RAW, dtype=np.int64)
    raw_b = np.zeros(B.N_RAW, dtype=np.int64)
    board_v, board_b = Board(cfg), Board(cfg)
    n_ticks = 3000
    ssi = np.zeros(n_ticks, dtype=np.int64)
    abi = np.zeros(n_ticks, dtype=np.int64)
    strain_new = enabled = 0
    for t in range(n_ticks):
        digitise(plant.y, k, t, raw_v)
        lines.update(plant.y, t)
        masters.read(lines, t, raw_b)
        assert np.array_equal(raw_v, raw_b), (t, diff(raw_v, raw_b))
        board_v.tick(raw_v)
        board_b.tick(raw_b)
        assert np.array_equal(board_v.st[B.F_DUTY_A:B.F_DUTY_C + 1],
                              board_b.st[B.F_DUTY_A:B.F_DUTY_C + 1]), t
        assert np.array_equal(board_v.up, board_b.up), t
        ssi[t] = raw_b[B.R_SSI]
        abi[t] = abi_count(plant.y[L.Y_THETA_M], k)
        strain_new += raw_b[B.R_STRAIN_NEW]
        enabled += board_b.st[B.F_STATE] == B.STATE_ENABLED
        plant.set_current(-12.0 * math.sin(TWO_PI * t / 1500))  # A, down then back up
        plant.advance(1)
    # The run covered what the paths could disagree on.
    assert strain_new > 600  # 4.8 kS/s at 20 kHz: every fourth or fifth tick
    assert np.any(np.diff(ssi) > 1000) and np.any(np.diff(ssi) < -1000)  # 0 <-> 2047 wraps
    assert abi.min() < -1000 and abi[-1] > abi.min()  # negative counts, both directions
    assert np.abs(np.diff(abi)).max() >= 3  # several counts within one tick
    assert enabled == n_ticks  # the boards ran their current loops throughout
    assert board_b.up[B.U_ERR_SSI] == board_b.up[B.U_ERR_BISS] == 0
    assert board_b.up[B.U_ERR_STRAIN] == 0
    assert masters.abi_illegal == 0


def test_edge_values_identical(cfg):
    """Count boundaries, negative angles and positions, saturated ADCs and a strain force
    beyond the bridge range (clamped, ERR set, read rejected on both paths)."""
    k = chip_params(cfg)
    lines, masters = SensorLines(cfg), BitLevelMasters(cfg)
    raw_v = np.zeros(B.N_RAW, dtype=np.int64)
    raw_b = np.zeros(B.N_RAW, dtype=np.int64)
    step = TWO_PI / 2048
    half_stroke = 0.05
    cases = [
        synthetic_y(theta=n * step, x=n * 5e-9, force=f, p=p, temp=tc, ia=i, ib=-i)
        for n, f, p, tc, i in [
            (0, 0.0, 0.0, 20.0, 0.0),
            (-1, -2999.9, -1e5, -60.0, 39.99),
            (-97, 3000.5, 8e6, 300.0, 45.0),      # force beyond +FS: clamped
            (1950, -3500.0, 7e6, 25.0, -45.0),    # force beyond -FS: clamped
            (1951, 2999.99, 3.5e6, 0.0, -40.0),
            (5000, 0.0001, 1.0, 100.0, 0.0049),
        ]
    ]
    cases += [synthetic_y(theta=-7.3, x=-half_stroke), synthetic_y(theta=9.1, x=half_stroke)]
    conv = new_conversion_ticks(k, 200)
    seen_rejected = 0
    for i, t in enumerate(conv[: 2 * len(cases)]):
        y = cases[i % len(cases)]
        for tt in (t, t + 1):  # the tick of a conversion and one without
            digitise(y, k, tt, raw_v)
            lines.update(y, tt)
            masters.read(lines, tt, raw_b)
            assert np.array_equal(raw_v, raw_b), (tt, diff(raw_v, raw_b))
        seen_rejected += raw_b[B.R_STRAIN_OK] == 0
    assert seen_rejected == 4


def test_set_force_gives_the_value_level_code(cfg):
    """The device's own force conversion agrees with the value level's code and clamping."""
    k = chip_params(cfg)
    dev = AD7195Device(full_scale_n=cfg.get("sensors.strain_full_scale_n"))
    rng = np.random.default_rng(7)
    forces = np.concatenate((rng.uniform(-3100.0, 3100.0, 2000),
                             [-3000.0, 3000.0, 0.0, -3000.0001, 2999.9999]))
    for f in forces:
        code = dev.set_force(float(f))
        assert code == strain_code(f, k)
        assert bool(dev.status & 0x40) == strain_clamped(f, k)


def test_abi_counter_follows_several_counts_per_tick(cfg):
    """Jumps of several counts per tick either way, through zero and the 16-bit wrap."""
    k = chip_params(cfg)
    n_abi = cfg.get("sensors.abi_counts_per_rev")
    lines, masters = SensorLines(cfg), BitLevelMasters(cfg)
    raw_v = np.zeros(B.N_RAW, dtype=np.int64)
    raw_b = np.zeros(B.N_RAW, dtype=np.int64)
    counts = [0, 5, 12, 4, -3, -10, -4, 3, 65530, 65537, 65541, 65533, 65529]
    for t, c in enumerate(counts):
        y = synthetic_y(theta=(c + 0.5) * TWO_PI / n_abi)
        digitise(y, k, t, raw_v)
        lines.update(y, t)
        masters.read(lines, t, raw_b)
        assert raw_b[B.R_ABI] == c & 0xFFFF
        assert raw_b[B.R_ABI] == raw_v[B.R_ABI]
    assert masters.abi_illegal == 0


def run(lines, masters, board, y, t, raw):
    lines.update(y, t)
    masters.read(lines, t, raw)
    board.tick(raw)


def test_ssi_faults_rejected_and_counted(cfg):
    k = chip_params(cfg)
    lines, masters, board = SensorLines(cfg), BitLevelMasters(cfg), Board(cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    run(lines, masters, board, synthetic_y(theta=1.0), 0, raw)
    held = ssi_count(1.0, k)
    assert raw[B.R_SSI_OK] == 1 and raw[B.R_SSI] == held
    for t, level in ((1, 0), (2, 1)):  # line stuck low, then stuck high
        lines.ssi_stuck = level
        run(lines, masters, board, synthetic_y(theta=2.0), t, raw)
        assert raw[B.R_SSI_OK] == 0 and raw[B.R_SSI] == held
        assert board.up[B.U_SSI] == held
    lines.ssi_stuck = None
    run(lines, masters, board, synthetic_y(theta=2.0), 3, raw)
    assert raw[B.R_SSI_OK] == 1 and raw[B.R_SSI] == ssi_count(2.0, k)
    assert board.up[B.U_ERR_SSI] == 2
    assert board.up[B.U_STATUS] & B.ST_ENCODER_ERROR == 0

    # The default RMB30 frame has no parity: a flipped bit passes as a wrong angle.
    lines.ssi_flip_mask = 1 << 10
    run(lines, masters, board, synthetic_y(theta=2.0), 4, raw)
    assert raw[B.R_SSI_OK] == 1 and raw[B.R_SSI] == ssi_count(2.0, k) ^ (1 << 10)


def test_ssi_bit_flip_caught_by_parity(cfg):
    k = chip_params(cfg)
    fmt = SsiFormat(position_bits=cfg.get("sensors.ssi_bits"), parity="even")
    lines, masters = SensorLines(cfg, ssi_fmt=fmt), BitLevelMasters(cfg, ssi_fmt=fmt)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    lines.update(synthetic_y(theta=1.0), 0)
    masters.read(lines, 0, raw)
    assert raw[B.R_SSI_OK] == 1 and raw[B.R_SSI] == ssi_count(1.0, k)
    lines.ssi_flip_mask = 1 << 3
    lines.update(synthetic_y(theta=-1.0), 1)
    masters.read(lines, 1, raw)
    assert raw[B.R_SSI_OK] == 0 and raw[B.R_SSI] == ssi_count(1.0, k)
    assert masters.ssi_errors == 1


def test_biss_crc_and_error_bit_rejected_and_counted(cfg):
    k = chip_params(cfg)
    lines, masters, board = SensorLines(cfg), BitLevelMasters(cfg), Board(cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    run(lines, masters, board, synthetic_y(x=1e-3), 0, raw)
    held = biss_count(1e-3, k)
    assert raw[B.R_BISS_OK] == 1 and raw[B.R_BISS] == held
    lines.corrupt_biss_crc()
    run(lines, masters, board, synthetic_y(x=2e-3), 1, raw)
    assert raw[B.R_BISS_OK] == 0 and raw[B.R_BISS] == held
    lines.biss_flip_mask = 1 << 20  # a position bit: caught by the CRC as well
    run(lines, masters, board, synthetic_y(x=2e-3), 2, raw)
    assert raw[B.R_BISS_OK] == 0 and raw[B.R_BISS] == held
    lines.biss_error_frames = 2
    for t in (3, 4):
        run(lines, masters, board, synthetic_y(x=2e-3), t, raw)
        assert raw[B.R_BISS_OK] == 0 and raw[B.R_BISS] == held
        assert board.up[B.U_STATUS] & B.ST_ENCODER_ERROR
    run(lines, masters, board, synthetic_y(x=2e-3), 5, raw)
    assert raw[B.R_BISS_OK] == 1 and raw[B.R_BISS] == biss_count(2e-3, k)
    assert board.up[B.U_ERR_BISS] == 4 == masters.biss_errors
    assert board.up[B.U_PISTON_LO] | board.up[B.U_PISTON_HI] << 16 == biss_count(2e-3, k)


@pytest.mark.parametrize("mask", [0x40, 0x80, 0x100, 0x01])  # ERR, /RDY, data bit, channel
def test_ad7195_failed_read_rejected_and_counted(cfg, mask):
    k = chip_params(cfg)
    lines, masters, board = SensorLines(cfg), BitLevelMasters(cfg), Board(cfg)
    raw = np.zeros(B.N_RAW, dtype=np.int64)
    conv = new_conversion_ticks(k, 40)
    t_good, t_bad, t_after = conv[1], conv[2], conv[3]
    for t in range(t_after + 1):
        if t == t_bad:
            lines.strain_flip_mask = mask
        run(lines, masters, board, synthetic_y(force=100.0 if t < t_bad else 200.0), t, raw)
        if t == t_good:
            good = strain_code(100.0, k)
            assert (raw[B.R_STRAIN_NEW], raw[B.R_STRAIN_OK], raw[B.R_STRAIN]) == (1, 1, good)
        elif t == t_bad:
            assert (raw[B.R_STRAIN_NEW], raw[B.R_STRAIN_OK], raw[B.R_STRAIN]) == (1, 0, good)
            assert board.up[B.U_STATUS] & B.ST_STRAIN_ERROR
            assert board.up[B.U_STRAIN_LO] == good & 0xFFFF
        elif t_bad < t < t_after:
            # between conversions the bit still says how the latest read went
            assert board.up[B.U_STATUS] & B.ST_STRAIN_ERROR
        elif t == t_after:
            assert (raw[B.R_STRAIN_NEW], raw[B.R_STRAIN_OK]) == (1, 1)
            assert raw[B.R_STRAIN] == strain_code(200.0, k)
            assert not board.up[B.U_STATUS] & B.ST_STRAIN_ERROR
        elif t_good <= t < t_bad:
            assert not board.up[B.U_STATUS] & B.ST_STRAIN_ERROR
    assert board.up[B.U_ERR_STRAIN] == 1 == masters.strain_errors
