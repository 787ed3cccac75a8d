"""The firmware interface: the C header an engineer compiles against (eha_hil.h) says what
the harness provides (hil/sim/image/memory_map.py) and what the board's registers are
(firmware_model/fpga/layout.py, firmware_model/mcu/dpram.py)."""

from __future__ import annotations

import re

from firmware_model.fpga import layout as B
from firmware_model.mcu import dpram
from hil.sim.image import build
from hil.sim.image import memory_map as M
from hil.sim.image.law import RX, TX


def _defines() -> dict[str, int]:
    text = (build.TEMPLATE_DIR / "eha_hil.h").read_text()
    return {m[1]: int(m[2], 0) for m in
            re.finditer(r"#define (EHA_\w+) (0x[0-9A-Fa-f]+|\d+)u?\b", text)}


def test_header_addresses_are_the_harness_map():
    d = _defines()
    assert d["EHA_FLASH_BASE"] == M.FLASH_BASE
    assert d["EHA_CAL_BASE"] == M.CAL_BASE
    assert d["EHA_CCM_BASE"] == M.CCM_BASE
    assert d["EHA_SRAM_BASE"] == M.SRAM_BASE
    assert d["EHA_DPRAM_BASE"] == M.DPRAM_BASE
    assert d["EHA_LINK_COUNTERS"] == M.LINK_COUNTERS
    assert d["EHA_RX_BASE"] == M.RX_BASE
    assert d["EHA_TX_BASE"] == M.TX_BASE
    assert d["EHA_CAL_MAGIC"] == M.CAL_MAGIC
    assert d["EHA_TIM2_VECTOR"] == M.TIM2_VECTOR
    assert d["EHA_BOARD_STRIDE"] == dpram.BOARD_STRIDE
    assert d["EHA_DOWN_OFFSET"] == dpram.DOWN_OFFSET
    assert d["EHA_UP_OFFSET"] == dpram.UP_OFFSET
    assert d["EHA_N_ANALOG"] == B.N_ANALOG


def test_header_registers_are_the_board_s():
    d = _defines()
    for name in ("CONTROL", "MODE", "IQ_REF", "VQ_FF", "ANGLE_OFFSET", "SEQUENCE"):
        assert d[f"EHA_D_{name}"] == getattr(B, f"D_{name}"), name
    for name in ("STATUS", "SPEED", "PISTON_LO", "PISTON_HI", "IQ", "ERR_LINK_CRC"):
        assert d[f"EHA_U_{name}"] == getattr(B, f"U_{name}"), name
    assert d["EHA_CTRL_ENABLE"] == B.CTRL_ENABLE
    assert d["EHA_CTRL_CLEAR_FAULT"] == B.CTRL_CLEAR_FAULT


def test_dpram_rules_follow_the_dpram_map():
    rules = M.dpram_rules()
    for addr in range(dpram.DPRAM_WORDS):
        _, block, _ = dpram.decode(addr)
        want = {"down": M.READ | M.WRITE, "up": M.READ, "reserved": 0}[block]
        assert rules[2 * addr] == rules[2 * addr + 1] == want, hex(addr)
    assert not rules[2 * dpram.DPRAM_WORDS:M.LINK_COUNTERS - M.DPRAM_BASE].any()
    assert M.LINK_COUNTERS_BYTES == 4 * dpram.MAX_BOARDS


def test_process_data_records_fit_their_windows():
    assert RX.itemsize == M.RX_BYTES
    assert TX.itemsize <= M.TX_BYTES
