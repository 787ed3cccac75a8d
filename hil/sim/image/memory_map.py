"""The firmware interface's memory map, as the harness provides it (the C side is
``firmware_model/mcu/image/template/eha_hil.h``; a test reads that header and compares).

Unicorn maps whole 4 KiB pages; inside the FSMC pages a per-byte rule table (read,
write) enforces the dual-port RAM's blocks and the process-data windows, checked by the C
access hook on every external-bus access."""

from __future__ import annotations

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.mcu import dpram

PAGE = 0x1000
FLASH_BASE, FLASH_SIZE = 0x0800_0000, 1 << 20
CAL_BASE = 0x080E_0000
CCM_BASE, CCM_SIZE = 0x1000_0000, 64 << 10
SRAM_BASE, SRAM_SIZE = 0x2000_0000, 128 << 10
TIM_BASE = 0x4000_0000          # TIM2..TIM5 registers: accepted, no effect
RCC_PAGE = 0x4002_3000          # CRC, RCC, flash interface: accepted, no effect
SCS_BASE = 0xE000_E000          # CPACR, NVIC, SysTick: accepted, no effect
DPRAM_BASE = 0x6000_0000        # FSMC bank 1, NE1
LINK_COUNTERS = 0x6000_0400
LINK_COUNTERS_BYTES = 20        # one 32-bit count per board, boards 0..4 (dpram.MAX_BOARDS)
RX_BASE = 0x6400_0000           # FSMC bank 1, NE2: the fieldbus controller's process data
TX_BASE = 0x6400_0100
RX_BYTES, TX_BYTES = 0x20, 0x100
RETURN_ADDRESS = 0x1FFF_0000    # system memory: where the harness's cycle call returns to
TIM2_VECTOR = 44
CAL_MAGIC = 0x4C41_4345         # "ECAL"
CAL_VERSION = 1
STEP_SYMBOL = "eha_hil_step"

READ, WRITE = 1, 2

#: (name, base, size, Unicorn permissions as "rwx") of every region an image may touch.
REGIONS = (
    ("flash", FLASH_BASE, FLASH_SIZE, "rx"),
    ("CCM RAM", CCM_BASE, CCM_SIZE, "rw"),
    ("SRAM", SRAM_BASE, SRAM_SIZE, "rwx"),
    ("TIM2..TIM5", TIM_BASE, PAGE, "rw"),
    ("CRC/RCC/flash interface", RCC_PAGE, PAGE, "rw"),
    ("DPRAM (FSMC NE1)", DPRAM_BASE, PAGE, "rw"),
    ("process data (FSMC NE2)", RX_BASE, PAGE, "rw"),
    ("system control space", SCS_BASE, PAGE, "rw"),
    ("harness return", RETURN_ADDRESS, PAGE, "rx"),
)


def dpram_rules() -> np.ndarray:
    """Per byte of the DPRAM page: READ/WRITE bits (downstream blocks read/write, upstream
    read only, gaps nothing; the MCU board FPGA's CRC counters read only)."""
    rules = np.zeros(PAGE, dtype=np.uint8)
    for addr in range(dpram.DPRAM_WORDS):
        _, block, _ = dpram.decode(addr)
        rules[2 * addr:2 * addr + 2] = {"down": READ | WRITE, "up": READ}.get(block, 0)
    off = LINK_COUNTERS - DPRAM_BASE
    rules[off:off + LINK_COUNTERS_BYTES] = READ
    return rules


def pd_rules() -> np.ndarray:
    """Per byte of the process-data page: the RX window read only, TX read/write."""
    rules = np.zeros(PAGE, dtype=np.uint8)
    rules[:RX_BYTES] = READ
    off = TX_BASE - RX_BASE
    rules[off:off + TX_BYTES] = READ | WRITE
    return rules


def region_of(address: int) -> str | None:
    """The name of the region holding ``address`` (None: unmapped)."""
    for name, base, size, _ in REGIONS:
        if base <= address < base + size:
            return name
    return None


def describe(address: int) -> str:
    """Where ``address`` is, in the firmware interface's words."""
    if DPRAM_BASE <= address < DPRAM_BASE + PAGE:
        off = address - DPRAM_BASE
        if off < 2 * dpram.DPRAM_WORDS:
            k, block, word = dpram.decode(off // 2)
            names = {"down": [n for _, n, *_ in B.DOWN_REGISTERS],
                     "up": [n for _, n, *_ in B.UP_REGISTERS]}.get(block, [])
            reg = f" ({names[word]})" if word < len(names) else ""
            return f"DPRAM board {k} {block} word 0x{word:02X}{reg}"
        return "DPRAM page outside the map"
    if RX_BASE <= address < RX_BASE + PAGE:
        return "process data page outside the RX/TX windows"
    return region_of(address) or "unmapped"
